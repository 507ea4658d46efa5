//! Phong specular reflection with a certified node bound.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::shader::{NodeEstimate, Shader, colour_or_clamped, try_colour};
use crate::tree::Node;

/// Below this value `cos^e` is computed together with its scale factor in
/// log space, so that a lobe value that would underflow `f64` on its own but
/// is multiplied by a large intensity is not flushed to zero. `1e-280` leaves
/// 28 decades above the smallest normal `f64`.
const LOBE_LOG_SPACE_BELOW: f64 = 1e-280;

/// Phong specular reflection: a light of intensity `I` at distance `d` in
/// direction `w` contributes `I * ks * max(0, r . w)^e / d^2`, with
/// `r = 2 (n . v) n - v` the mirror image of the view direction `v` about the
/// normal `n`.
///
/// Conventions: a light at `d = 0` contributes 0; `max(0, r.w)^e` is 0
/// whenever `r . w <= 0`, including for `e = 0` (so `e = 0` is the indicator
/// of the hemisphere around `r`). The model is applied as written for every
/// view: when `n . v < 0` (the eye below the surface) `r` points below the
/// tangent plane and lights there are reflected; a host shading two-sided
/// surfaces flips the normal towards the eye first. Lights below the tangent
/// plane are not culled by this term (the model has no `n . w` factor).
///
/// # Node bound
/// The paper's (slides "Specular Reflection"), valid whenever `D > R`: with
/// `alpha_c` the angle between `r` and the node's axis and `delta` the cone
/// half-angle,
///
/// ```text
/// I ks max(0, cos(alpha_c + delta))^e / (D + R)^2
///     <= exact <= I ks max(0, cos(max(0, alpha_c - delta)))^e / (D - R)^2
/// ```
///
/// with cosines from [`Cone::cos_range`] (sines and cosines, never `acos`,
/// whose error near 0 is raised to the `e`-th power). The estimate is the
/// virtual light `I ks max(0, cos alpha_c)^e / D^2`. The power is taken in log
/// space when it would underflow, so no bound is lost to a `cos^e` that
/// flushed to zero while `I/d^2` is large. Exponents `0 <= e <= 1e6`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phong {
    ks: DVec3,
    exponent: f64,
}

impl Phong {
    /// Largest supported exponent. Exponents above it are clamped by
    /// [`Phong::new`] and refused by [`Phong::try_new`]; `1e6` already makes
    /// a lobe narrower than 0.1 degree at half maximum.
    pub const MAX_EXPONENT: f64 = 1e6;

    /// Specular colour `ks` (each channel finite and `>= 0`) and exponent
    /// `e` in `[0, MAX_EXPONENT]`.
    ///
    /// Debug builds assert that the colour is valid and the exponent is not
    /// NaN or negative; release builds keep results finite by reading NaN or
    /// negative channels (and exponents) as 0 and infinite channels as
    /// `f32::MAX`. Exponents above [`MAX_EXPONENT`](Self::MAX_EXPONENT) are
    /// clamped in every build. [`Phong::try_new`] returns an error instead.
    #[must_use]
    pub fn new(ks: Vec3, exponent: f32) -> Self {
        let e = f64::from(exponent);
        debug_assert!(
            e >= 0.0,
            "Phong exponent must be >= 0, got {e} (use try_new for an error)"
        );
        Self {
            ks: colour_or_clamped(ks, "ks"),
            // `+ 0.0` also turns -0.0 into +0.0.
            exponent: if e.is_nan() {
                0.0
            } else {
                e.clamp(0.0, Self::MAX_EXPONENT) + 0.0
            },
        }
    }

    /// Like [`Phong::new`], but refuses bad parameters.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`] for a NaN, infinite or negative
    /// channel of `ks`, or an exponent outside `[0, MAX_EXPONENT]`.
    pub fn try_new(ks: Vec3, exponent: f32) -> Result<Self, ShadeError> {
        let ks = try_colour(ks, "ks must be finite and >= 0")?;
        let e = f64::from(exponent);
        if !(0.0..=Self::MAX_EXPONENT).contains(&e) {
            return Err(ShadeError::InvalidMaterial(
                "exponent must lie in [0, MAX_EXPONENT]",
            ));
        }
        // `+ 0.0` turns an exponent of -0.0 into +0.0.
        Ok(Self {
            ks,
            exponent: e + 0.0,
        })
    }

    /// The specular colour.
    #[must_use]
    pub fn ks(&self) -> DVec3 {
        self.ks
    }

    /// The exponent.
    #[must_use]
    pub fn exponent(&self) -> f64 {
        self.exponent
    }

    /// `scale * max(0, cos)^e` per channel, without losing a product that is
    /// representable to an underflowing power.
    #[inline]
    fn lobe(&self, scale: DVec3, cos: f64) -> DVec3 {
        if !(cos > 0.0) {
            return DVec3::ZERO;
        }
        if self.exponent == 0.0 {
            return scale;
        }
        let log_lobe = self.exponent * cos.ln();
        let lobe = log_lobe.exp();
        if lobe >= LOBE_LOG_SPACE_BELOW {
            return scale * lobe;
        }
        let f = |s: f64| {
            if s > 0.0 {
                (log_lobe + s.ln()).exp()
            } else {
                0.0
            }
        };
        DVec3::new(f(scale.x), f(scale.y), f(scale.z))
    }
}

impl Shader for Phong {
    /// The unit mirror direction `r`.
    type PerPoint = DVec3;

    #[inline]
    fn prepare(&self, surface: &Surface) -> DVec3 {
        let n = surface.normal;
        let v = surface.view;
        (2.0 * n.dot(v) * n - v).normalize_or_zero()
    }

    #[inline]
    fn eval(&self, r: &DVec3, surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        let delta = position - surface.point;
        let d2 = delta.length_squared();
        if d2 == 0.0 {
            return DVec3::ZERO;
        }
        let cos = r.dot(delta) / d2.sqrt();
        self.lobe(intensity * self.ks / d2, cos)
    }

    #[inline]
    fn bound(&self, r: &DVec3, _surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        let (cos_lo, cos_hi) = cone.cos_range(*r);
        if cos_hi <= 0.0 {
            return NodeEstimate::ZERO;
        }
        let inv_d = cone.inv_distance;
        let scale = node.intensity * self.ks * (inv_d * inv_d);
        NodeEstimate::new(
            self.lobe(scale, r.dot(cone.axis)),
            self.lobe(scale * cone.far_falloff(), cos_lo),
            self.lobe(scale * cone.near_falloff(), cos_hi),
        )
    }
}
