//! Phong specular reflection with a certified node bound.

use glam::{DVec3, Vec3};

use crate::ShadeError;
use crate::geometry::{Cone, Surface};
use crate::lambert::sanitize;
use crate::shader::{NodeBound, Shader};
use crate::tree::Node;

/// Largest supported Phong exponent. Exponents above it are clamped (and
/// [`Phong::try_new`] refuses them); `1e6` already makes a lobe narrower than
/// 0.1 degree at half maximum.
pub const MAX_EXPONENT: f64 = 1e6;

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
    /// Specular colour `ks` and exponent `e`. NaN or negative channels of
    /// `ks` become 0, infinite ones `f32::MAX`; a NaN or negative exponent
    /// becomes 0 and one above [`MAX_EXPONENT`] is clamped (see
    /// [`Phong::try_new`] for an error instead).
    pub fn new(ks: Vec3, exponent: f32) -> Self {
        let e = f64::from(exponent);
        Self {
            ks: sanitize(ks),
            exponent: if e.is_nan() || e < 0.0 {
                0.0
            } else {
                e.min(MAX_EXPONENT)
            },
        }
    }

    /// Like [`Phong::new`], but refuses bad parameters.
    ///
    /// # Errors
    /// [`ShadeError::InvalidMaterial`] for a NaN, infinite or negative
    /// channel of `ks`, or an exponent outside `[0, MAX_EXPONENT]`.
    pub fn try_new(ks: Vec3, exponent: f32) -> Result<Self, ShadeError> {
        if !ks.is_finite() || ks.min_element() < 0.0 {
            return Err(ShadeError::InvalidMaterial("ks must be finite and >= 0"));
        }
        if !(0.0..=MAX_EXPONENT).contains(&f64::from(exponent)) {
            return Err(ShadeError::InvalidMaterial(
                "exponent must lie in [0, MAX_EXPONENT]",
            ));
        }
        Ok(Self::new(ks, exponent))
    }

    /// The specular colour.
    pub fn ks(&self) -> DVec3 {
        self.ks
    }

    /// The exponent.
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
    type Frame = DVec3;

    #[inline]
    fn frame(&self, surface: &Surface) -> DVec3 {
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
    fn bound(&self, r: &DVec3, _surface: &Surface, node: &Node, cone: &Cone) -> NodeBound {
        let (cos_lo, cos_hi) = cone.cos_range(*r);
        if cos_hi <= 0.0 {
            return NodeBound::ZERO;
        }
        let inv_d = cone.inv_distance;
        let scale = node.intensity * self.ks * (inv_d * inv_d);
        NodeBound::new(
            self.lobe(scale, r.dot(cone.axis)),
            self.lobe(scale * cone.far_falloff(), cos_lo),
            self.lobe(scale * cone.near_falloff(), cos_hi),
        )
    }
}
