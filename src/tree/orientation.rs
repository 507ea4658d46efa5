//! What a tree of oriented emitters adds: each light's emission profile
//! (leaf order) and, per node, a cone bounding its members' axes and the
//! range of their profiles' parameters, from which a point's bound on every
//! member's profile value follows.

use core::f64::consts::{FRAC_PI_2, PI};

use glam::{DVec3, Vec3};

use super::layout::LightTree;
use crate::emission::{Kind, Profile, lobe, spot};
use crate::geometry::Cone;
use crate::numeric::round_up_f32;

/// Added to every angle the bound derives (radians): it covers the
/// rounding of the stored axes and of the angles' own computation, and the
/// rounding of a light's cosine in the model (at most about `3e-8` radians
/// where the cosine is near 1, far less elsewhere), so that the profiles'
/// values at the padded angles bound the values the model computes.
const ANGLE_SLACK: f64 = 1e-7;

/// The profiles of a tree's lights and the orientation cones of its nodes.
#[derive(Clone, Debug, Default)]
pub(crate) struct Orientation {
    /// Per light, leaf order.
    pub(crate) profiles: Vec<Profile>,
    /// Per node.
    pub(crate) cones: Vec<NodeCone>,
}

impl Orientation {
    /// Heap bytes held.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.profiles.capacity() * size_of::<Profile>()
            + self.cones.capacity() * size_of::<NodeCone>()
    }
}

/// Member kinds and sides present in a node, as bits.
const HAS_ISOTROPIC: u8 = 1;
const HAS_COSINE: u8 = 2;
const HAS_SPOT: u8 = 4;
const HAS_ONE_SIDED: u8 = 8;
const HAS_TWO_SIDED: u8 = 16;

/// A node's orientation bounds: every oriented member's axis (or its
/// opposite, for a two-sided member) lies within `spread` of `axis`, and
/// its profile's parameters within the stored ranges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct NodeCone {
    /// Unit, or zero where the members' axes have no useful mean (the
    /// spread is then `pi`).
    axis: Vec3,
    /// Largest angle (radians) between `axis` and a member's axis, rounded
    /// up and padded.
    spread: f32,
    /// Least and greatest cosine exponent of the node's cosine members.
    k: [f32; 2],
    /// Least and greatest `cos(outer_angle)` of its spot members.
    outer: [f32; 2],
    /// Least and greatest `cos(inner_angle)` of its spot members.
    inner: [f32; 2],
    kinds: u8,
}

/// A bound on every member's profile value at one point, and the value
/// the node's estimate takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Factor {
    pub(crate) lower: f64,
    pub(crate) estimate: f64,
    pub(crate) upper: f64,
}

impl Factor {
    /// Every member isotropic.
    pub(crate) const ONE: Self = Self {
        lower: 1.0,
        estimate: 1.0,
        upper: 1.0,
    };
}

/// The angle between unit vectors `a` and `b`, accurate everywhere.
#[inline]
fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

impl NodeCone {
    /// The cone of the lights with `profiles`.
    pub(crate) fn of(profiles: &[Profile]) -> Self {
        let mut kinds = 0u8;
        let (mut k, mut outer, mut inner) = (
            [f32::INFINITY, f32::NEG_INFINITY],
            [f32::INFINITY, f32::NEG_INFINITY],
            [f32::INFINITY, f32::NEG_INFINITY],
        );
        let widen = |r: &mut [f32; 2], v: f32| {
            r[0] = r[0].min(v);
            r[1] = r[1].max(v);
        };
        let mut sum = DVec3::ZERO;
        for p in profiles {
            match p.kind {
                Kind::Isotropic => {
                    kinds |= HAS_ISOTROPIC;
                    continue;
                }
                Kind::Cosine => {
                    kinds |= HAS_COSINE;
                    widen(&mut k, p.a);
                }
                Kind::Spot => {
                    kinds |= HAS_SPOT;
                    widen(&mut outer, p.a);
                    widen(&mut inner, p.b);
                }
            }
            kinds |= if p.two_sided {
                HAS_TWO_SIDED
            } else {
                HAS_ONE_SIDED
            };
            let m = p.axis.as_dvec3();
            // A two-sided member's axis may be taken either way: the one
            // nearer the others'.
            sum += if p.two_sided && m.dot(sum) < 0.0 {
                -m
            } else {
                m
            };
        }
        let length = sum.length();
        let axis = if length > 0.0 {
            (sum / length).as_vec3()
        } else {
            Vec3::ZERO
        };
        let w = axis.as_dvec3();
        let w_length = w.length();
        let spread = if w_length > 0.5 {
            let w = w / w_length;
            let mut widest = 0.0f64;
            for p in profiles.iter().filter(|p| p.kind != Kind::Isotropic) {
                let m = p.axis.as_dvec3();
                let m = m / m.length();
                let a = angle(w, m);
                widest = widest.max(if p.two_sided { a.min(PI - a) } else { a });
            }
            widest
        } else {
            PI
        };
        Self {
            axis: if spread < PI { axis } else { Vec3::ZERO },
            spread: round_up_f32((spread + ANGLE_SLACK).min(PI)),
            k,
            outer,
            inner,
            kinds,
        }
    }

    /// Whether every member is isotropic.
    #[inline]
    pub(crate) fn is_isotropic(&self) -> bool {
        self.kinds & !HAS_ISOTROPIC == 0
    }

    /// Bounds every member's profile value at the point from which the
    /// node's ball is seen under `cone`: each member's direction to the
    /// point lies within the cone's half-angle `delta` of the direction
    /// from the ball's centre, so its angle with its own axis lies within
    /// `spread + delta` of the angle `psi` between the node's axis and that
    /// direction; every profile is non-increasing in that angle, and in its
    /// exponent and cosines.
    #[inline]
    pub(crate) fn factor(&self, cone: &Cone) -> Factor {
        let delta = cone.sin_half_angle.clamp(0.0, 1.0).asin();
        self.factor_within(-cone.axis, delta)
    }

    /// [`factor`](Self::factor) for every direction from a member to a
    /// point within `delta` radians of the unit vector `towards` (`delta`
    /// of `pi` or more: any direction).
    #[inline]
    pub(crate) fn factor_within(&self, towards: DVec3, delta: f64) -> Factor {
        if self.is_isotropic() {
            return Factor::ONE;
        }
        let w = self.axis.as_dvec3();
        let (psi, reach) = if w == DVec3::ZERO || !(delta < PI) {
            (FRAC_PI_2, PI)
        } else {
            let w = w / w.length();
            (
                angle(w, towards),
                f64::from(self.spread) + delta + ANGLE_SLACK,
            )
        };
        let (least, most) = ((psi - reach).max(0.0), (psi + reach).min(PI));
        // The least and greatest angle any member's profile sees.
        let two = self.kinds & HAS_TWO_SIDED != 0;
        let one = self.kinds & HAS_ONE_SIDED != 0;
        let nearest = if two {
            least.min(PI - most)
        } else {
            least
        };
        let farthest_two = if least <= FRAC_PI_2 && FRAC_PI_2 <= most {
            FRAC_PI_2
        } else if most < FRAC_PI_2 {
            most
        } else {
            PI - least
        };
        let farthest = match (one, two) {
            (true, true) => most.max(farthest_two),
            (false, true) => farthest_two,
            _ => most,
        };
        let centre = if two && !one { psi.min(PI - psi) } else { psi };
        let (c_hi, c_lo, c_mid) = (nearest.cos(), farthest.cos(), centre.cos());
        let mut upper = 0.0f64;
        let mut lower = 1.0f64;
        let mut estimate: Option<f64> = None;
        let mut kinds = 0;
        if self.kinds & HAS_ISOTROPIC != 0 {
            upper = 1.0;
            kinds += 1;
            estimate = Some(1.0);
        }
        let mid = |r: [f32; 2]| 0.5 * (f64::from(r[0]) + f64::from(r[1]));
        if self.kinds & HAS_COSINE != 0 {
            let [k_min, k_max] = self.k.map(f64::from);
            upper = upper.max(lobe(c_hi, k_min, false));
            lower = lower.min(lobe(c_lo, k_max, false));
            kinds += 1;
            estimate = Some(lobe(c_mid, mid(self.k), false));
        }
        if self.kinds & HAS_SPOT != 0 {
            let ([co_min, co_max], [ci_min, ci_max]) =
                (self.outer.map(f64::from), self.inner.map(f64::from));
            upper = upper.max(spot(c_hi, co_min, ci_min));
            lower = lower.min(spot(c_lo, co_max, ci_max));
            kinds += 1;
            let (co, ci) = (mid(self.outer), mid(self.inner));
            estimate = Some(spot(c_mid, co, ci.max(co)));
        }
        let estimate = match estimate {
            Some(e) if kinds == 1 => e,
            _ => 0.5 * (lower + upper),
        };
        Factor {
            lower,
            estimate: estimate.clamp(lower, upper),
            upper,
        }
    }
}

impl LightTree {
    /// The emission profiles' bounds of node `index` seen under `cone`:
    /// [`Factor::ONE`] for a tree of isotropic lights.
    #[inline(always)]
    pub(crate) fn factor(&self, index: usize, cone: &Cone) -> Factor {
        match &self.orientation {
            None => Factor::ONE,
            Some(o) => o.cones[index].factor(cone),
        }
    }

    /// The emission profiles' bounds of node `index` over every point
    /// within `radius` of `centre` (a group of points): every direction
    /// from a member (within the node's radius of its centroid) to such a
    /// point lies within `asin((R + r) / D)` of the direction from the
    /// centroid to `centre`, `D` their distance; any direction where the
    /// balls meet. [`Factor::ONE`] for a tree of isotropic lights.
    #[inline]
    pub(crate) fn group_factor(&self, index: usize, centre: DVec3, radius: f64) -> Factor {
        let Some(o) = &self.orientation else {
            return Factor::ONE;
        };
        let node = &self.nodes[index];
        let offset = centre - node.centroid.as_dvec3();
        let distance = offset.length();
        // Rounded up relatively, so that the angle is not understated.
        let reach = (f64::from(node.radius) + radius) * (1.0 + 1e-12);
        let delta = if reach < distance && distance > 0.0 {
            (reach / distance).min(1.0).asin()
        } else {
            PI
        };
        o.cones[index].factor_within(offset / distance.max(f64::MIN_POSITIVE), delta)
    }

    /// The emission bounds of the light at `leaf_index` (leaf order) over
    /// every point within `radius` of `centre`, as
    /// [`group_factor`](Self::group_factor) bounds a node's.
    #[inline]
    pub(crate) fn light_group_factor(&self, leaf_index: usize, centre: DVec3, radius: f64) -> Factor {
        let Some(o) = &self.orientation else {
            return Factor::ONE;
        };
        let profile = o.profiles[leaf_index];
        if profile.kind == Kind::Isotropic {
            return Factor::ONE;
        }
        let offset = centre - self.lights[leaf_index].position.as_dvec3();
        let distance = offset.length();
        let reach = radius * (1.0 + 1e-12);
        let delta = if reach < distance && distance > 0.0 {
            (reach / distance).min(1.0).asin()
        } else {
            PI
        };
        NodeCone::of(&[profile]).factor_within(offset / distance.max(f64::MIN_POSITIVE), delta)
    }

    /// Whether some light of the tree has a profile other than isotropic.
    #[inline(always)]
    pub(crate) fn is_oriented(&self) -> bool {
        self.orientation.is_some()
    }

    /// The profile of the light at `leaf_index` (leaf order).
    #[inline(always)]
    pub(crate) fn profile(&self, leaf_index: usize) -> Profile {
        self.orientation
            .as_ref()
            .map_or(Profile::ISOTROPIC, |o| o.profiles[leaf_index])
    }

    /// Computes every node's cone from the lights' profiles (leaf order).
    pub(crate) fn fill_cones(&mut self) {
        let Some(o) = self.orientation.as_mut() else {
            return;
        };
        let profiles = &o.profiles;
        o.cones.clear();
        o.cones.extend(
            self.nodes
                .iter()
                .map(|n| NodeCone::of(&profiles[n.lights()])),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emission::Emission;

    fn profile(e: Emission) -> Profile {
        e.profile().unwrap()
    }

    #[test]
    fn a_node_aimed_away_is_dark_and_one_aimed_at_the_point_is_not() {
        let down = profile(Emission::spot(Vec3::NEG_Z, 0.3, 0.6));
        let cone = NodeCone::of(&[down, down]);
        // A node at height 10, radius 1: seen from straight below and from
        // far aside.
        let below = Cone::new(DVec3::ZERO, Vec3::new(0.0, 0.0, 10.0), 1.0).unwrap();
        let aside = Cone::new(DVec3::new(100.0, 0.0, 10.0), Vec3::new(0.0, 0.0, 10.0), 1.0)
            .unwrap();
        let f = cone.factor(&below);
        assert_eq!((f.lower, f.upper), (1.0, 1.0));
        assert_eq!(cone.factor(&aside).upper, 0.0);
    }

    #[test]
    fn the_factor_bounds_every_member_at_random_points() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) as f32
        };
        for round in 0..200 {
            let mut profiles = Vec::new();
            let mut positions = Vec::new();
            let base = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            for _ in 0..8 {
                let axis = base + 0.3 * Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                let e = match round % 4 {
                    0 => Emission::cosine(axis, 1.0),
                    1 => Emission::spot(axis, 0.2 * next(), 0.3 + next()),
                    2 => Emission::cosine(axis, 30.0 * next()).two_sided(),
                    _ => Emission::spot(axis, 0.1, 0.8).two_sided(),
                };
                profiles.push(profile(e));
                positions.push(Vec3::new(next(), next(), next()));
            }
            let centre = Vec3::splat(0.5);
            let cone = NodeCone::of(&profiles);
            for _ in 0..50 {
                let p = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 20.0;
                let Some(c) = Cone::new(p.as_dvec3(), centre, 0.87) else {
                    continue;
                };
                let f = cone.factor(&c);
                for (pr, x) in profiles.iter().zip(&positions) {
                    let v = pr.factor(*x, p.as_dvec3());
                    assert!(
                        f.lower <= v && v <= f.upper,
                        "{round}: {v} outside [{}, {}]",
                        f.lower,
                        f.upper
                    );
                }
            }
        }
    }
}
