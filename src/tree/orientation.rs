//! What a tree of oriented emitters adds: each light's emission profile
//! (leaf order) and, per node, a cone bounding its members' axes and the
//! range of their profiles' parameters, from which a point's bound on every
//! member's profile value follows.

use core::f64::consts::{FRAC_PI_2, PI};

use glam::{DVec3, Vec3};

use super::layout::LightTree;
use crate::emission::{Kind, Profile, lobe, spot};
use crate::geometry::{Aabb, Cone};

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
    /// Unit (in `f64`), or zero where the members' axes have no useful
    /// mean (the spread is then `pi`).
    axis: DVec3,
    /// Cosine and sine of the spread: the largest angle between `axis` and
    /// a member's axis, plus [`ANGLE_SLACK`]; at most a right angle (else
    /// `(-1, 0)` and a zero axis).
    spread: (f64, f64),
    /// Whether every oriented member has exactly the same axis (the
    /// spread is then [`ANGLE_SLACK`] alone).
    pub(crate) one_axis: bool,
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

/// A few ulps of a cosine or sine near 1: what the angle-sum formulas and
/// the square roots below may err by, moved outward.
const TRIG_SLACK: f64 = 8.0 * f64::EPSILON;

/// The relative rounding allowance of [`NodeCone::box_cosines`]'s
/// numerators (of their terms' magnitude) and distances: `2^-49`, sixteen
/// `f64` ulps, over the few roundings each takes.
const BOX_SLACK: f64 = 1.0 / (1u64 << 49) as f64;

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
        let mut first: Option<Vec3> = None;
        let mut one_axis = true;
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
            one_axis &= *first.get_or_insert(p.axis) == p.axis;
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
        let w = if one_axis && let Some(a) = first {
            a.as_dvec3().normalize_or_zero()
        } else if length > 0.0 {
            sum / length
        } else {
            DVec3::ZERO
        };
        let spread = if w != DVec3::ZERO {
            let mut widest = 0.0f64;
            if !one_axis {
                for p in profiles.iter().filter(|p| p.kind != Kind::Isotropic) {
                    let m = p.axis.as_dvec3();
                    let m = m / m.length();
                    let a = angle(w, m);
                    widest = widest.max(if p.two_sided { a.min(PI - a) } else { a });
                }
            }
            widest + ANGLE_SLACK
        } else {
            PI
        };
        // Spreads past a right angle bound nothing worth the trouble: the
        // node is then taken as aimed every way.
        let spread = if spread <= FRAC_PI_2 {
            (spread.cos(), spread.sin())
        } else {
            (-1.0, 0.0)
        };
        Self {
            axis: if spread.0 > -1.0 { w } else { DVec3::ZERO },
            spread,
            one_axis: one_axis && first.is_some(),
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

    /// Whether every member is a one-sided cosine lobe of exponent 1 (a
    /// diffuse virtual point light) about one same axis, which it returns
    /// (unit, pointing from the lights into the lit half-space).
    #[inline]
    pub(crate) fn diffuse_lobe(&self) -> Option<DVec3> {
        (self.kinds == HAS_COSINE | HAS_ONE_SIDED && self.one_axis && self.k == [1.0, 1.0])
            .then_some(self.axis)
    }

    /// Whether every member is one-sided and dark at every cosine up to
    /// `c` (the greatest its members see): each profile is 0 at `c` and
    /// so below it.
    #[inline(always)]
    fn dark_at(&self, c: f64) -> bool {
        self.kinds & (HAS_ISOTROPIC | HAS_TWO_SIDED) == 0
            && (self.kinds & HAS_COSINE == 0 || c <= 0.0)
            && (self.kinds & HAS_SPOT == 0 || c <= f64::from(self.outer[0]))
    }

    /// An estimate (not a bound) of the members' profile for a direction
    /// at cosine `cosine` to the node's mean axis: the value
    /// [`factor_within`](Self::factor_within) estimates for such a
    /// direction, which for a single kind of profile is that profile at the
    /// middle of the node's parameter ranges. 1 for isotropic members; for
    /// members whose axes have no mean, the estimate at a right angle.
    #[inline]
    pub(crate) fn estimate_at(&self, cosine: f64) -> f64 {
        if self.is_isotropic() {
            return 1.0;
        }
        let w = self.axis;
        let c = if cosine >= -1.0 { cosine.min(1.0) } else { 0.0 };
        let towards = if w == DVec3::ZERO {
            DVec3::X
        } else {
            c * w + (1.0 - c * c).max(0.0).sqrt() * w.any_orthonormal_vector()
        };
        self.factor_within(towards, 0.0, 1.0).estimate
    }

    /// The unit mean axis (zero where the members' axes have none), and
    /// whether every oriented member is two-sided.
    #[inline]
    pub(crate) fn mean_axis(&self) -> (DVec3, bool) {
        (
            self.axis,
            self.kinds & HAS_TWO_SIDED != 0 && self.kinds & HAS_ONE_SIDED == 0,
        )
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
        self.factor_within(-cone.axis, cone.sin_half_angle, cone.cos_half_angle)
    }

    /// The bound of [`factor_within`](Self::factor_within) for the
    /// directions `cone` (a unit vector and the sine and cosine of the
    /// angle about it), narrowed by the members' box `aabb` seen from
    /// every point within `reach` of `point` (0 for the point alone; see
    /// [`box_cosines`](Self::box_cosines)).
    #[inline]
    pub(crate) fn factor_boxed(
        &self,
        cone: (DVec3, f64, f64),
        aabb: &Aabb,
        point: DVec3,
        reach: f64,
    ) -> Factor {
        let (towards, sin, cos) = cone;
        let boxed = self.box_cosines(aabb, point, reach);
        self.factor_within_box(towards, sin, cos, boxed)
    }

    /// The range of `w . (q - x) / |q - x|` over every member position `x`
    /// in `aabb` and every point `q` within `reach` of `point`, `w` the
    /// node's mean axis, rounded outward; `None` where the axis has no
    /// mean or the box reaches a point (no direction is then excluded).
    ///
    /// The numerator lies within `w . point - [max, min] of w . x over the
    /// box` (the box's support in `w`'s direction), widened by `reach`
    /// (`|w| = 1`); the distance within `[d_min - reach, d_max + reach]`,
    /// `d_min` and `d_max` from the point to the box's nearest point and
    /// farthest corner. A numerator's bound of either sign is divided by
    /// the distance bound that makes the quotient largest (or least). A
    /// thin node (the lamps of a street at one height, virtual lights on a
    /// wall) is bounded this way far closer than by its ball: the support
    /// is exact along the thin direction. Rounding: the numerator's terms
    /// are at most `mag = sum |w_i| (|p_i| + max |x_i|) + reach` and its
    /// computation a few roundings of them, covered by `2^-49 mag`; the
    /// distances are within a few ulps, covered by a relative `2^-49`.
    #[inline]
    pub(crate) fn box_cosines(&self, aabb: &Aabb, point: DVec3, reach: f64) -> Option<(f64, f64)> {
        let w = self.axis;
        if w == DVec3::ZERO {
            return None;
        }
        let (lo, hi) = (aabb.min.as_dvec3(), aabb.max.as_dvec3());
        let (near, far) = (
            DVec3::select(w.cmpge(DVec3::ZERO), lo, hi),
            DVec3::select(w.cmpge(DVec3::ZERO), hi, lo),
        );
        let wp = w.dot(point);
        let mag = (w.abs() * (point.abs() + lo.abs().max(hi.abs()))).element_sum() + reach;
        let slack = mag * BOX_SLACK;
        let n_hi = wp - w.dot(near) + reach + slack;
        let n_lo = wp - w.dot(far) - reach - slack;
        let gap = (lo - point).max(point - hi).max(DVec3::ZERO);
        let d_min = gap.length() * (1.0 - BOX_SLACK) - reach;
        let d_max = (point - lo).abs().max((point - hi).abs()).length() * (1.0 + BOX_SLACK) + reach;
        if !(d_min > 0.0) || !d_max.is_finite() {
            return None;
        }
        let up = 1.0 + BOX_SLACK;
        let hi_c = if n_hi >= 0.0 {
            n_hi / d_min * up
        } else {
            n_hi / d_max / up
        };
        let lo_c = if n_lo >= 0.0 {
            n_lo / d_max / up
        } else {
            n_lo / d_min * up
        };
        Some((lo_c.max(-1.0), hi_c.min(1.0)))
    }

    /// [`factor`](Self::factor) for every direction from a member to a
    /// point within the angle `delta` (given by its sine and cosine, `delta
    /// <= pi / 2`) of the unit vector `towards`.
    ///
    /// In cosines throughout: with `sigma = spread + delta`, the angles lie
    /// in `[max(0, psi - sigma), min(pi, psi + sigma)]`, whose cosines the
    /// angle-sum formulas give from `cos psi = w . towards` and `sin psi =
    /// |w x towards|`; each is moved outward by four [`TRIG_SLACK`]s (the
    /// formulas' rounding, and the stored cosine and sine of the spread,
    /// are a few ulps), and the spread itself carries [`ANGLE_SLACK`], far
    /// more than the rounding of a light's cosine in the model.
    #[inline]
    pub(crate) fn factor_within(&self, towards: DVec3, sin_delta: f64, cos_delta: f64) -> Factor {
        self.factor_within_box(towards, sin_delta, cos_delta, None)
    }

    /// [`factor_within`](Self::factor_within), the range of the cosine
    /// between the mean axis and every direction also within `boxed` where
    /// given ([`box_cosines`](Self::box_cosines)): a member's angle to its
    /// own axis is then also within the spread of `[acos hi, acos lo]`, and
    /// the tighter of the two ranges holds.
    #[inline]
    pub(crate) fn factor_within_box(
        &self,
        towards: DVec3,
        sin_delta: f64,
        cos_delta: f64,
        boxed: Option<(f64, f64)>,
    ) -> Factor {
        if self.is_isotropic() {
            return Factor::ONE;
        }
        let w = self.axis;
        let (cos_s, sin_s) = self.spread;
        // sigma = spread + delta (both at most a right angle), as a cosine
        // and a sine.
        let cos_sigma = cos_s * cos_delta - sin_s * sin_delta;
        let sin_sigma = sin_s * cos_delta + cos_s * sin_delta;
        let (c_least, c_most, c_psi) = if w == DVec3::ZERO {
            (1.0, -1.0, 0.0)
        } else {
            let (cos_psi, sin_psi) = (w.dot(towards), w.cross(towards).length());
            let mut least = if cos_psi >= cos_sigma {
                // psi <= sigma: the axis itself is among the directions.
                1.0
            } else {
                (cos_psi * cos_sigma + sin_psi * sin_sigma + 4.0 * TRIG_SLACK).min(1.0)
            };
            // The same from the box: the least angle to the mean axis is at
            // least acos(hi), to a member's axis at least that less the
            // spread.
            let mut box_most = -1.0f64;
            if let Some((lo, hi)) = boxed {
                if hi < cos_s {
                    let sin_hi = (1.0 - hi * hi).max(0.0).sqrt();
                    least = least.min((hi * cos_s + sin_hi * sin_s + 4.0 * TRIG_SLACK).min(1.0));
                }
                let sin_lo = (1.0 - lo * lo).max(0.0).sqrt();
                // sin(acos(lo) + spread) <= 0: the angle may reach pi.
                if sin_lo * cos_s + lo * sin_s > TRIG_SLACK {
                    box_most = (lo * cos_s - sin_lo * sin_s - 4.0 * TRIG_SLACK).max(-1.0);
                }
            }
            if self.dark_at(least) {
                // Most nodes the cut bounds far from a spot's cone end here.
                return Factor {
                    lower: 0.0,
                    estimate: 0.0,
                    upper: 0.0,
                };
            }
            // sin(psi + sigma) <= 0: psi + sigma reaches pi.
            let most = if sin_psi * cos_sigma + cos_psi * sin_sigma <= TRIG_SLACK {
                -1.0
            } else {
                (cos_psi * cos_sigma - sin_psi * sin_sigma - 4.0 * TRIG_SLACK).max(-1.0)
            }
            .max(box_most);
            (least, most, cos_psi)
        };
        // The greatest and least cosine any member's profile sees.
        let two = self.kinds & HAS_TWO_SIDED != 0;
        let one = self.kinds & HAS_ONE_SIDED != 0;
        let c_hi = if two { c_least.max(-c_most) } else { c_least };
        let farthest_two = if c_least >= 0.0 && c_most <= 0.0 {
            0.0
        } else if c_most > 0.0 {
            c_most
        } else {
            -c_least
        };
        let c_lo = match (one, two) {
            (true, true) => c_most.min(farthest_two),
            (false, true) => farthest_two,
            _ => c_most,
        };
        let c_mid = if two && !one { c_psi.abs() } else { c_psi };
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

/// The unit direction of `offset` and the sine and cosine of the angle
/// under which a ball of radius `reach` about its end is seen from its
/// start (rounded outward); a right angle where the ball reaches the start
/// (every direction then possible within `pi / 2` of `offset`'s, which the
/// caller's spread widens; a zero offset gives no direction at all).
#[inline]
fn seen_within(offset: DVec3, reach: f64) -> (DVec3, f64, f64) {
    let distance = offset.length();
    let reach = reach * (1.0 + 4.0 * f64::EPSILON);
    if !(distance > reach) {
        return (DVec3::ZERO, 1.0, 0.0);
    }
    let sin = (reach / distance * (1.0 + 4.0 * f64::EPSILON)).min(1.0);
    let cos = ((1.0 - sin * sin).max(0.0).sqrt() - TRIG_SLACK).max(0.0);
    (offset / distance, sin, cos)
}

impl LightTree {
    /// The emission profiles' bounds of node `index` seen under `cone`
    /// (from its ball alone): [`Factor::ONE`] for a tree of isotropic
    /// lights.
    #[inline(always)]
    pub(crate) fn factor(&self, index: usize, cone: &Cone) -> Factor {
        match &self.orientation {
            None => Factor::ONE,
            Some(o) => o.cones[index].factor(cone),
        }
    }

    /// [`factor`](Self::factor) from the point `point` (the cone's apex),
    /// narrowed by the node's box ([`NodeCone::box_cosines`]).
    #[inline(always)]
    pub(crate) fn factor_at(&self, index: usize, point: DVec3, cone: &Cone) -> Factor {
        match &self.orientation {
            None => Factor::ONE,
            Some(o) => o.cones[index].factor_boxed(
                (-cone.axis, cone.sin_half_angle, cone.cos_half_angle),
                &self.nodes[index].aabb,
                point,
                0.0,
            ),
        }
    }

    /// Node `index`'s orientation cone, `None` for a tree of isotropic
    /// lights.
    #[inline]
    pub(crate) fn node_cone(&self, index: usize) -> Option<&NodeCone> {
        self.orientation.as_ref().map(|o| &o.cones[index])
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
        let seen = seen_within(offset, f64::from(node.radius) + radius);
        o.cones[index].factor_boxed(seen, &node.aabb, centre, radius)
    }

    /// The emission bounds of the light at `leaf_index` (leaf order) over
    /// every point within `radius` of `centre`, as
    /// [`group_factor`](Self::group_factor) bounds a node's.
    #[inline]
    pub(crate) fn light_group_factor(
        &self,
        leaf_index: usize,
        centre: DVec3,
        radius: f64,
    ) -> Factor {
        let Some(o) = &self.orientation else {
            return Factor::ONE;
        };
        let profile = o.profiles[leaf_index];
        if profile.kind == Kind::Isotropic {
            return Factor::ONE;
        }
        let offset = centre - self.lights[leaf_index].position.as_dvec3();
        let (towards, sin, cos) = seen_within(offset, radius);
        NodeCone::of(&[profile]).factor_within(towards, sin, cos)
    }

    /// The common axis of node `index`'s members where every one is a
    /// diffuse virtual point light about it (see
    /// [`NodeCone::diffuse_lobe`]).
    #[inline(always)]
    pub(crate) fn diffuse_lobe(&self, index: usize) -> Option<DVec3> {
        self.orientation.as_ref()?.cones[index].diffuse_lobe()
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
        let aside =
            Cone::new(DVec3::new(100.0, 0.0, 10.0), Vec3::new(0.0, 0.0, 10.0), 1.0).unwrap();
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

    /// Narrowed by the members' box, the factor still bounds every member's
    /// profile, from points and from every point of a ball about one: thin
    /// boxes (one flat along a random axis, as lamps at one height or
    /// lights on a wall) seen from far and near, members on the box's
    /// faces, every kind of profile; and it is tighter than the ball's
    /// alone for a thin node seen off its axis.
    #[test]
    fn the_boxed_factor_bounds_every_member_of_thin_nodes() {
        let mut seed = 11u64;
        let mut next = || crate::testing::uniform(&mut seed);
        let mut narrower = 0;
        for round in 0..400 {
            let base = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            // Thin along one axis (all members at one height for round % 3
            // == 0), or not.
            let scale = match round % 3 {
                0 => Vec3::new(4.0, 4.0, 0.0),
                1 => Vec3::new(4.0, 0.01, 4.0),
                _ => Vec3::splat(2.0),
            };
            let (mut profiles, mut positions) = (Vec::new(), Vec::new());
            for _ in 0..8 {
                let axis = base + 0.2 * Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                let e = match round % 5 {
                    0 => Emission::cosine(axis, 1.0),
                    1 => Emission::spot(axis, 0.2 * next(), 0.3 + next()),
                    2 => Emission::cosine(axis, 300.0 * next()).two_sided(),
                    3 => Emission::spot(axis, 0.02, 0.05 + 0.2 * next()),
                    _ => Emission::spot(axis, 0.1, 0.8).two_sided(),
                };
                profiles.push(profile(e));
                positions.push(Vec3::new(next(), next(), next()) * scale);
            }
            let aabb = positions.iter().fold(Aabb::EMPTY, |b, &x| b.union_point(x));
            let centre = 0.5 * (aabb.min + aabb.max);
            let radius = positions
                .iter()
                .map(|x| x.distance(centre))
                .fold(0.0f32, f32::max)
                * (1.0 + 1e-6);
            let cone = NodeCone::of(&profiles);
            for k in 0..60 {
                let far = if k % 2 == 0 { 3.0 } else { 40.0 };
                let p =
                    (centre + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * far).as_dvec3();
                let reach = if k % 3 == 0 {
                    0.0
                } else {
                    0.2 * f64::from(next())
                };
                let offset = p - centre.as_dvec3();
                let seen = seen_within(offset, f64::from(radius) + reach);
                let f = cone.factor_boxed(seen, &aabb, p, reach);
                let plain = cone.factor_within(seen.0, seen.1, seen.2);
                assert!(f.lower >= plain.lower && f.upper <= plain.upper);
                narrowed_count(&mut narrower, &f, &plain);
                // Members seen from the point and from points of the ball
                // about it.
                for j in 0..4 {
                    let dir = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5)
                        .normalize_or_zero()
                        .as_dvec3();
                    let q = if j == 0 {
                        p
                    } else {
                        p + dir * reach * f64::from(next())
                    };
                    for (pr, x) in profiles.iter().zip(&positions) {
                        let v = pr.factor(*x, q);
                        assert!(
                            f.lower <= v && v <= f.upper,
                            "{round}/{k}: {v} outside [{}, {}]",
                            f.lower,
                            f.upper
                        );
                    }
                }
            }
        }
        assert!(narrower > 1000, "the box narrowed only {narrower} factors");
    }

    fn narrowed_count(count: &mut u32, boxed: &Factor, plain: &Factor) {
        if boxed.upper < plain.upper || boxed.lower > plain.lower {
            *count += 1;
        }
    }
}
