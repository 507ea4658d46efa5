//! What a shading call returns.

use glam::DVec3;

#[cfg(doc)]
use super::Threshold;

/// Why the cut stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stop {
    /// The threshold was met: [`ShadeResult::error_bound`] satisfies it.
    ThresholdMet,
    /// The budget ran out first; the bound is still certified but may exceed
    /// the threshold (and is infinite if a node containing the shading point
    /// was left unrefined).
    Budget,
}

/// Radiance at a shading point with its certified error bound and its cost.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct ShadeResult {
    /// Estimated RGB radiance.
    pub radiance: DVec3,
    /// Certified bound on `|radiance - exact|` per channel, up to
    /// [`ROUNDING_ALLOWANCE`](Self::ROUNDING_ALLOWANCE) of the exact value
    /// (see [`certifies`](Self::certifies) and the crate docs).
    pub error_bound: DVec3,
    /// Node bounds computed.
    pub nodes_evaluated: u32,
    /// Single lights evaluated exactly.
    pub lights_evaluated: u32,
    /// Visibility classifications asked of the host.
    pub classify_queries: u32,
    /// Point-to-point visibility queries asked of the host (a standard ray
    /// tracer asks one per light).
    pub point_queries: u32,
    /// Why the cut stopped.
    pub stop: Stop,
}

/// Nothing shaded yet, to fill a results slice before a batch call
/// ([`Shading::shade_batch`](crate::Shading::shade_batch)): radiance 0 with
/// an infinite bound (it certifies nothing), no work, stopped by the budget.
impl Default for ShadeResult {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl ShadeResult {
    /// [`ShadeResult::default`].
    pub(crate) const EMPTY: Self = Self {
        radiance: DVec3::ZERO,
        error_bound: DVec3::INFINITY,
        nodes_evaluated: 0,
        lights_evaluated: 0,
        classify_queries: 0,
        point_queries: 0,
        stop: Stop::Budget,
    };

    /// Relative rounding allowance of the certified-bound contract:
    /// `|radiance - exact| <= error_bound + ROUNDING_ALLOWANCE * exact` per
    /// channel.
    ///
    /// What it covers: the relative rounding of single terms (whose signs are
    /// exact: a Lambert term is within `2^-40`, about `9e-13`, relative, a
    /// Phong term within about `4e-12` for every exponent; see
    /// [`Phong`](crate::Phong)), the plain `f64` sums of at most 16 visible
    /// lights' terms ([`Shader::sum_lights`](crate::shader::Shader::sum_lights),
    /// within `16 * 2^-53` relative, the terms being non-negative),
    /// relative rounding of node interval ends computed in `f64` (about
    /// `1e-12`), and the reference sum's own error (compensated, about
    /// `2^-52`). `1e-9` leaves a margin of over 200 over
    /// the largest of these.
    pub const ROUNDING_ALLOWANCE: f64 = 1e-9;

    /// `nodes_evaluated + lights_evaluated`: the work, in the units of
    /// [`Threshold::with_budget`].
    #[must_use]
    pub fn cost(&self) -> u32 {
        self.nodes_evaluated + self.lights_evaluated
    }

    /// Whether this result keeps the certified-bound contract against the
    /// `exact` value (e.g. from [`Shading::exact`](crate::Shading::exact)):
    /// per channel `|radiance - exact| <= error_bound + ROUNDING_ALLOWANCE *
    /// exact`.
    #[must_use]
    pub fn certifies(&self, exact: DVec3) -> bool {
        let slack = self.error_bound + Self::ROUNDING_ALLOWANCE * exact.abs();
        (self.radiance - exact).abs().cmple(slack).all()
    }
}
