//! Emission profiles: how a light's intensity varies with the direction it
//! is seen from (isotropic lights, cosine lobes such as virtual point
//! lights, glTF spot lights), what a light carries of one, and the exact
//! value the model multiplies a light's term by.

use core::f64::consts::FRAC_PI_2;

use glam::{DVec3, Vec3};

use crate::PointLight;
use crate::numeric::dot_of_difference;

/// How a light's intensity varies with direction: its *profile* `f(c)`,
/// where `c = m . (p - x) / |p - x|` is the cosine between the light's
/// axis `m` and the direction from the light (at `x`) to the shading point
/// `p`. The model multiplies each light's term by `f(c)` (crate docs, "The
/// model"): the light emits `I f(c)` towards `p`.
///
/// * [`Isotropic`](Self::Isotropic): `f = 1` (what [`PointLight`] alone
///   means);
/// * [`Cosine`](Self::Cosine): `f = c^k` for `c > 0`, else 0 (`k = 1`: a
///   diffuse virtual point light, as instant radiosity traces; larger `k`:
///   a glossy one; `k = 0`: a half-space);
/// * [`Spot`](Self::Spot): glTF's `KHR_lights_punctual` spot light, `f =
///   t^2` with `t = clamp((c - cos_outer) / (cos_inner - cos_outer), 0,
///   1)`; `f = 1` for `c >= cos_inner` and `0` for `c <= cos_outer` (so
///   equal angles give a hard edge).
///
/// A *two-sided* profile takes `|c|` in place of `c` (it emits along both
/// ends of its axis). Axes need not be unit length: the build normalises
/// them once (in `f64`, stored as `f32`), and the model uses the stored
/// axis, normalised again exactly as the exact reference does. A spot's
/// angles are stored as their cosines, computed once in `f64` and rounded
/// to `f32`; the model uses the stored cosines.
///
/// The sign of `m . (p - x)` is decided exactly from the `f32` axis,
/// point and position, so a point exactly in a lobe's plane gets exactly 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[non_exhaustive]
pub enum Emission {
    /// The same intensity in every direction.
    #[default]
    Isotropic,
    /// A cosine lobe `max(0, c)^exponent` about `axis`.
    Cosine {
        /// The lobe's axis (any non-zero finite length).
        axis: Vec3,
        /// The exponent `k`, from 0 to [`Emission::MAX_EXPONENT`].
        exponent: f32,
        /// Whether the lobe emits along both ends of its axis.
        two_sided: bool,
    },
    /// A glTF spot light about `axis`.
    Spot {
        /// The spot's axis, the direction it points (any non-zero finite
        /// length).
        axis: Vec3,
        /// Angle from the axis, in radians, out to which the spot is at
        /// full intensity (glTF's `innerConeAngle`), at least 0 and at
        /// most `outer_angle`.
        inner_angle: f32,
        /// Angle from the axis, in radians, past which the spot is dark
        /// (glTF's `outerConeAngle`), above 0 and at most `pi / 2`
        /// (`std::f32::consts::FRAC_PI_2`, which rounds up, is taken as
        /// `pi / 2`).
        outer_angle: f32,
        /// Whether the spot emits along both ends of its axis.
        two_sided: bool,
    },
}

impl Emission {
    /// The largest exponent of a [`Cosine`](Self::Cosine) lobe.
    pub const MAX_EXPONENT: f32 = 1e4;

    /// A one-sided cosine lobe `max(0, c)^exponent` about `axis`.
    #[must_use]
    pub const fn cosine(axis: Vec3, exponent: f32) -> Self {
        Self::Cosine {
            axis,
            exponent,
            two_sided: false,
        }
    }

    /// A one-sided glTF spot light about `axis`, at full intensity out to
    /// `inner_angle` and dark past `outer_angle` (radians).
    #[must_use]
    pub const fn spot(axis: Vec3, inner_angle: f32, outer_angle: f32) -> Self {
        Self::Spot {
            axis,
            inner_angle,
            outer_angle,
            two_sided: false,
        }
    }

    /// The same profile emitting along both ends of its axis (`|c|` for
    /// `c`); an isotropic profile is returned as it is.
    #[must_use]
    pub const fn two_sided(self) -> Self {
        match self {
            Self::Isotropic => Self::Isotropic,
            Self::Cosine { axis, exponent, .. } => Self::Cosine {
                axis,
                exponent,
                two_sided: true,
            },
            Self::Spot {
                axis,
                inner_angle,
                outer_angle,
                ..
            } => Self::Spot {
                axis,
                inner_angle,
                outer_angle,
                two_sided: true,
            },
        }
    }

    /// Whether the profile is [`Isotropic`](Self::Isotropic).
    #[must_use]
    pub const fn is_isotropic(&self) -> bool {
        matches!(self, Self::Isotropic)
    }

    /// The profile as the tree stores it, or why it is out of range.
    pub(crate) fn profile(&self) -> Result<Profile, &'static str> {
        let unit = |axis: Vec3| -> Result<Vec3, &'static str> {
            if !axis.is_finite() {
                return Err("axis is not finite");
            }
            let a = axis.as_dvec3();
            let length = a.length();
            if !(length > 0.0) || !length.is_finite() {
                return Err("axis has zero length");
            }
            let unit = (a / length).as_vec3();
            if unit == Vec3::ZERO {
                return Err("axis has zero length");
            }
            Ok(unit)
        };
        Ok(match *self {
            Self::Isotropic => Profile::ISOTROPIC,
            Self::Cosine {
                axis,
                exponent,
                two_sided,
            } => {
                if !(0.0..=Self::MAX_EXPONENT).contains(&exponent) {
                    return Err("cosine exponent must be in [0, 1e4]");
                }
                Profile {
                    axis: unit(axis)?,
                    a: exponent,
                    b: 0.0,
                    kind: Kind::Cosine,
                    two_sided,
                }
            }
            Self::Spot {
                axis,
                inner_angle,
                outer_angle,
                two_sided,
            } => {
                // `f32`'s `FRAC_PI_2` lies just above pi/2; it is taken as
                // pi/2.
                if !(outer_angle > 0.0 && outer_angle <= core::f32::consts::FRAC_PI_2) {
                    return Err("spot outer angle must be in (0, pi/2]");
                }
                if !(inner_angle >= 0.0) {
                    return Err("spot inner angle must be >= 0");
                }
                if inner_angle > outer_angle {
                    return Err("spot inner angle is wider than its outer angle");
                }
                Profile {
                    axis: unit(axis)?,
                    a: f64::from(outer_angle).min(FRAC_PI_2).cos() as f32,
                    b: f64::from(inner_angle).min(FRAC_PI_2).cos() as f32,
                    kind: Kind::Spot,
                    two_sided,
                }
            }
        })
    }

    /// The profile's value `f(c)` for a light at `light` seen from `point`
    /// (the model's factor, as [`Shading::exact_query`] multiplies the
    /// light's term by): 1 for an isotropic light; for a light exactly on
    /// the point, 1 (the shaders' terms are 0 there).
    ///
    /// An out-of-range profile (which the build refuses) gives 0.
    ///
    /// [`Shading::exact_query`]: crate::Shading::exact_query
    #[must_use]
    pub fn factor(&self, light: Vec3, point: Vec3) -> f64 {
        self.profile()
            .map_or(0.0, |p| p.factor(light, point.as_dvec3()))
    }
}

/// A light with an [`Emission`] profile: what
/// [`LightTree::build_emitters`](crate::LightTree::build_emitters) takes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Emitter {
    /// Position and intensity (the intensity along the profile's peak).
    pub light: PointLight,
    /// How the intensity varies with direction.
    pub emission: Emission,
}

impl Emitter {
    /// `light` emitting with `emission`.
    #[must_use]
    pub const fn new(light: PointLight, emission: Emission) -> Self {
        Self { light, emission }
    }
}

impl From<PointLight> for Emitter {
    fn from(light: PointLight) -> Self {
        Self::new(light, Emission::Isotropic)
    }
}

impl PointLight {
    /// This light with the emission profile `emission`.
    #[must_use]
    pub const fn with_emission(self, emission: Emission) -> Emitter {
        Emitter::new(self, emission)
    }
}

/// Which profile a stored light has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Kind {
    Isotropic,
    Cosine,
    Spot,
}

/// A validated profile as the tree stores it, one per light in leaf order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Profile {
    /// Unit axis (rounded to `f32`); zero for an isotropic light.
    pub(crate) axis: Vec3,
    /// Cosine: the exponent. Spot: `cos(outer_angle)`.
    pub(crate) a: f32,
    /// Spot: `cos(inner_angle)`.
    pub(crate) b: f32,
    pub(crate) kind: Kind,
    pub(crate) two_sided: bool,
}

impl Profile {
    pub(crate) const ISOTROPIC: Self = Self {
        axis: Vec3::ZERO,
        a: 0.0,
        b: 0.0,
        kind: Kind::Isotropic,
        two_sided: false,
    };

    /// The model's factor for a light at `light` seen from `point` (an
    /// `f32` value): see [`Emission`].
    #[inline(always)]
    pub(crate) fn factor(&self, light: Vec3, point: DVec3) -> f64 {
        if self.kind == Kind::Isotropic {
            return 1.0;
        }
        let m = self.axis.as_dvec3();
        let x = light.as_dvec3();
        let offset = point - x;
        let d2 = offset.length_squared();
        if d2 == 0.0 {
            return 1.0;
        }
        if !self.two_sided && self.kind == Kind::Spot && self.a >= 0.0 {
            // Dark for certain without the division or the roots: the
            // plain cosine, at most a few ulps off, is well below the
            // outer cosine (`a >= 0`), so the model's is not above it.
            let plain = m.dot(offset);
            let co = f64::from(self.a);
            let m2 = m.length_squared();
            if plain <= 0.0 && co > 0.0
                || plain > 0.0 && plain * plain < co * co * m2 * d2 * (1.0 - DARK_MARGIN)
            {
                return 0.0;
            }
        }
        // The sign exactly; the value to about 1e-16 relative.
        let along = dot_of_difference(m, point, x);
        let c = along / (self.length() * d2.sqrt());
        let c = if self.two_sided { c.abs() } else { c };
        self.of_cosine(c, along == 0.0)
    }

    /// The stored axis's length in `f64` (1 to within `f32` rounding).
    #[inline(always)]
    fn length(&self) -> f64 {
        self.axis.as_dvec3().length()
    }

    /// The profile at cosine `c` (`|c|` already taken for a two-sided
    /// profile); `zero` when `c` is exactly 0.
    #[inline]
    pub(crate) fn of_cosine(&self, c: f64, zero: bool) -> f64 {
        match self.kind {
            Kind::Isotropic => 1.0,
            Kind::Cosine => lobe(c, f64::from(self.a), zero),
            Kind::Spot => spot(c, f64::from(self.a), f64::from(self.b)),
        }
    }
}

/// How far below a spot's outer cosine, relatively and squared, a plain
/// `f64` cosine must be for [`Profile::factor`] to call the light dark
/// without computing the model's cosine: `1e-12`, where the two differ by
/// a few units of `2^-53`.
const DARK_MARGIN: f64 = 1e-12;

/// `c^k` for `c > 0`, else 0 (also for `k = 0`).
#[inline]
pub(crate) fn lobe(c: f64, k: f64, zero: bool) -> f64 {
    if zero || !(c > 0.0) {
        0.0
    } else if k == 1.0 {
        c.min(1.0)
    } else {
        c.min(1.0).powf(k)
    }
}

/// glTF's spot falloff at cosine `c`, outer and inner cosines `co <= ci`.
#[inline]
pub(crate) fn spot(c: f64, co: f64, ci: f64) -> f64 {
    if c >= ci {
        1.0
    } else if c <= co {
        0.0
    } else {
        let t = ((c - co) / (ci - co)).clamp(0.0, 1.0);
        t * t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_follow_their_formulas() {
        let down = Vec3::NEG_Z;
        let light = Vec3::new(0.0, 0.0, 10.0);
        let below = Vec3::ZERO;
        let aside = Vec3::new(10.0, 0.0, 10.0);
        let at_45 = Vec3::new(10.0, 0.0, 0.0);
        let lobe = Emission::cosine(down, 2.0);
        assert_eq!(lobe.factor(light, below), 1.0);
        assert_eq!(lobe.factor(light, aside), 0.0);
        assert!((lobe.factor(light, at_45) - 0.5).abs() < 1e-12);
        assert_eq!(lobe.factor(light, Vec3::new(0.0, 0.0, 20.0)), 0.0);
        assert_eq!(
            lobe.two_sided().factor(light, Vec3::new(0.0, 0.0, 20.0)),
            1.0
        );
        let spot = Emission::spot(down, 0.5, 1.0);
        assert_eq!(spot.factor(light, below), 1.0);
        assert_eq!(spot.factor(light, Vec3::new(20.0, 0.0, 0.0)), 0.0);
        // At 45 degrees: between the cones.
        let (co, ci) = (1f64.cos() as f32, 0.5f64.cos() as f32);
        let t = (core::f64::consts::FRAC_1_SQRT_2 - f64::from(co)) / f64::from(ci - co);
        assert!((spot.factor(light, at_45) - t * t).abs() < 1e-6);
        assert_eq!(Emission::Isotropic.factor(light, aside), 1.0);
    }

    #[test]
    fn out_of_range_profiles_are_refused() {
        let bad = [
            Emission::cosine(Vec3::ZERO, 1.0),
            Emission::cosine(Vec3::new(f32::NAN, 0.0, 1.0), 1.0),
            Emission::cosine(Vec3::Z, -1.0),
            Emission::cosine(Vec3::Z, 2e4),
            Emission::cosine(Vec3::Z, f32::NAN),
            Emission::spot(Vec3::Z, 0.6, 0.5),
            Emission::spot(Vec3::Z, 0.0, 0.0),
            Emission::spot(Vec3::Z, 0.0, 2.0),
            Emission::spot(Vec3::Z, -0.1, 0.5),
            Emission::spot(Vec3::Z, f32::NAN, 0.5),
        ];
        for e in bad {
            assert!(e.profile().is_err(), "{e:?}");
            assert_eq!(e.factor(Vec3::Z, Vec3::ZERO), 0.0);
        }
        assert!(Emission::spot(Vec3::Z, 0.5, 0.5).profile().is_ok());
        // f32's pi/2 (just above pi/2) is a right angle: glTF's widest spot.
        let right = core::f32::consts::FRAC_PI_2;
        for inner in [0.0, right] {
            let p = Emission::spot(Vec3::Z, inner, right).profile().unwrap();
            assert!(p.a >= 0.0 && p.a < 1e-7);
            let e = Emission::spot(Vec3::Z, inner, right);
            let above = e.factor(Vec3::ZERO, Vec3::new(1.0, 0.0, 1e-3));
            assert!(if inner > 0.0 {
                above == 1.0
            } else {
                above > 0.0 && above < 1e-5
            });
            assert_eq!(e.factor(Vec3::ZERO, Vec3::new(1.0, 0.0, -1e-3)), 0.0);
        }
        assert!(Emission::cosine(Vec3::splat(1e30), 1e4).profile().is_ok());
    }
}
