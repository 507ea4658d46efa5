//! The Lambert node bound alone against the exact sum over the node's
//! lights, on adversarial light sets, and the constants it relies on.
//!
//! Ranges (see the strategies): 1 to 300 lights per set, shaped as a ball,
//! a slab, a line, two split clusters, a spherical shell, street lamps, a
//! lopsided line or one point, along a random or a coordinate axis, of
//! extent `10^-2` to `10^2` about a centre up to `10^4` from the origin;
//! weights `10^u`, `u` uniform in `[-3, 3]`, times random colours (a
//! channel exactly 0 with probability 1/8). Shading points at
//! `D = R (1 + 10^t)` from a node's centroid, `t` in `[-5.5, 6]` (just
//! outside the ball to a million radii), in a random direction or along the
//! line to the node's farthest member, with facing, grazing (down to
//! exactly perpendicular), straddling, averted and random normals.

use glam::{DVec3, Vec3};
use proptest::prelude::*;

use crate::shader::{ChildrenOf, Cone, NodeEstimate, Seal, Shader, Surface};
use crate::{BoundKind, Combined, Lambert, LightTree, Phong, PointLight, ShadeResult};

/// The children of `parent` whose bits are set in `wanted`.
fn children(tree: &LightTree, parent: usize, wanted: u8) -> ChildrenOf<'_> {
    ChildrenOf {
        tree,
        parent,
        wanted,
    }
}

/// `default` cases per property, or `PROPTEST_CASES` where it is set.
pub(super) fn cases(default: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(default);
    ProptestConfig {
        cases,
        ..ProptestConfig::default()
    }
}

/// A unit vector, uniform on the sphere.
fn unit() -> impl Strategy<Value = DVec3> {
    (-1.0f64..=1.0, 0.0f64..std::f64::consts::TAU).prop_map(|(z, phi)| {
        let s = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(s * phi.cos(), s * phi.sin(), z)
    })
}

/// A colour with channels in `[0, 1]` (each exactly 0 with probability
/// 1/8) times `10^u`, `u` in `[-3, 3]`.
fn intensity() -> impl Strategy<Value = Vec3> {
    let channel = prop_oneof![1 => Just(0.0f32), 7 => 0.0f32..=1.0];
    (channel.clone(), channel.clone(), channel, -3.0f32..=3.0)
        .prop_map(|(r, g, b, e)| Vec3::new(r, g, b) * 10f32.powf(e))
}

/// Shapes of light sets, in units of the set's extent.
#[derive(Clone, Copy, Debug)]
enum Shape {
    Ball,
    Slab,
    Line,
    Split,
    Shell,
    Streets,
    /// Members on a line through the centroid, all far ones on one side and
    /// offset across it by `1e-4` (weights up to 1000 times larger near the
    /// centre balance them): the terms of every degree add up when seen
    /// along the line.
    Lopsided,
    /// Every member at one point.
    Coincident,
}

/// A member's offset from the set's centre, in units of its extent, from a
/// unit vector `a` and two uniform numbers `s`, `t` in `[0, 1]`.
fn place(shape: Shape, a: DVec3, s: f64, t: f64, axis: DVec3) -> DVec3 {
    match shape {
        Shape::Ball => a * s.cbrt(),
        Shape::Slab => {
            let flat = a - axis * a.dot(axis);
            flat * s.sqrt() + axis * (1e-3 * (t - 0.5))
        }
        Shape::Line => axis * (2.0 * s - 1.0) + a * 1e-4 * t,
        Shape::Split => {
            let side = if t < 0.5 { 1.0 } else { -1.0 };
            axis * side + a * 0.01 * s
        }
        Shape::Shell => a,
        Shape::Streets => {
            // Lamps along two perpendicular streets, at 6 +- 0.5 height
            // units of 1/100 of the extent.
            let along = 2.0 * s - 1.0;
            let (x, y) = if t < 0.5 {
                (along, 0.05 * (a.x.signum()))
            } else {
                (0.05 * a.y.signum(), along)
            };
            DVec3::new(x, y, 0.06 + 0.01 * a.z)
        }
        Shape::Lopsided => {
            if t < 0.25 {
                // Offset across the line by 1e-4 along one direction, the
                // next coordinate axis when the line is snapped to one.
                let across = DVec3::new(axis.z, axis.x, axis.y);
                let across = (across - axis * across.dot(axis)).normalize_or_zero();
                axis * (1.0 - 1e-3 * s) + across * 1e-4
            } else {
                -axis * (1e-3 + 0.2 * s * s) + a * 1e-6
            }
        }
        Shape::Coincident => DVec3::ZERO,
    }
}

fn light_set() -> impl Strategy<Value = Vec<PointLight>> {
    (
        prop::sample::select(vec![
            Shape::Ball,
            Shape::Slab,
            Shape::Line,
            Shape::Split,
            Shape::Shell,
            Shape::Streets,
            Shape::Lopsided,
            Shape::Coincident,
        ]),
        (unit(), 0.0f64..=4.0),
        (unit(), any::<bool>(), -2.0f64..=2.0),
        prop::collection::vec((unit(), 0.0f64..=1.0, 0.0f64..=1.0, intensity()), 1..=300),
    )
        .prop_map(
            |(shape, (centre_dir, centre_exp), (axis, snap, extent_exp), members)| {
                let centre =
                    centre_dir * 10f64.powf(centre_exp) * (centre_exp - 0.5).signum().max(0.0);
                let extent = 10f64.powf(extent_exp);
                // Half of the sets are aligned with a coordinate axis, so that
                // their boxes are as thin as they are.
                let axis = if snap {
                    let a = axis.abs();
                    let pick = if a.x >= a.y && a.x >= a.z {
                        DVec3::X
                    } else if a.y >= a.z {
                        DVec3::Y
                    } else {
                        DVec3::Z
                    };
                    pick * axis.dot(pick).signum()
                } else {
                    axis
                };
                members
                    .into_iter()
                    .map(|(a, s, t, i)| {
                        let x = centre + place(shape, a, s, t, axis) * extent;
                        PointLight::new(x.as_vec3(), i)
                    })
                    .collect()
            },
        )
}

/// How the normal is chosen relative to the axis `uh` from the point to the
/// node (`sigma = R / D`).
#[derive(Clone, Copy, Debug)]
enum Facing {
    /// Any direction.
    Random,
    /// Towards the node, tilted by up to 0.3 rad.
    Towards,
    /// Perpendicular to the axis, `n . uh` exactly 0 (one time in 20) or
    /// `+-10^u`, `u` in `[-17, -3]`.
    Grazing,
    /// The tangent plane cuts the node's ball: `n . uh = sigma * t`.
    Straddling,
    /// Away from the node.
    Averted,
}

/// One shading configuration for a node.
#[derive(Clone, Copy, Debug)]
struct View {
    node: prop::sample::Index,
    direction: DVec3,
    /// Whether the point lies (up to `10^aim`) on the line from the
    /// centroid through its farthest member, on that member's side (`> 0`) or
    /// the other, where pointwise bounds are tight; random otherwise.
    along: i8,
    aim: f64,
    distance_exp: f64,
    facing: Facing,
    other: DVec3,
    t: f64,
}

fn view() -> impl Strategy<Value = View> {
    (
        any::<prop::sample::Index>(),
        unit(),
        -1i8..=1,
        -9.0f64..=-1.0,
        -5.5f64..=6.0,
        prop::sample::select(vec![
            Facing::Random,
            Facing::Towards,
            Facing::Grazing,
            Facing::Straddling,
            Facing::Averted,
        ]),
        unit(),
        -1.0f64..=1.0,
    )
        .prop_map(
            |(node, direction, along, aim, distance_exp, facing, other, t)| View {
                node,
                direction,
                along,
                aim,
                distance_exp,
                facing,
                other,
                t,
            },
        )
}

/// The normal for `view` with unit axis `uh` and `sigma = R / D`.
fn normal(view: &View, uh: DVec3, sigma: f64) -> DVec3 {
    let perp = {
        let p = view.other - uh * view.other.dot(uh);
        if p.length_squared() > 1e-12 {
            p.normalize()
        } else {
            uh.any_orthonormal_vector()
        }
    };
    let n = match view.facing {
        Facing::Random => view.other,
        Facing::Towards => (uh + perp * (0.3 * view.t)).normalize(),
        // n . uh from 0 (exactly, when t = 0) through 1e-17 to 1e-3.
        Facing::Grazing => {
            let c = if view.t.abs() < 0.05 {
                0.0
            } else {
                view.t.signum() * 10f64.powf(-3.0 - 14.0 * (1.0 - view.t.abs()))
            };
            perp + uh * c
        }
        Facing::Straddling => {
            let c = sigma * view.t;
            uh * c + perp * (1.0 - c * c).max(0.0).sqrt()
        }
        Facing::Averted => -uh,
    };
    n.normalize()
}

/// Exact node sum in `f64`: `Shader::eval` over the node's lights.
fn exact(shader: &Lambert, surface: &Surface, tree: &LightTree, node: usize) -> DVec3 {
    tree.lights()[tree.nodes()[node].lights()]
        .iter()
        .map(|l| shader.eval(&(), surface, l.position.as_dvec3(), l.intensity.as_dvec3()))
        .sum()
}

/// The node, its cone and the shading surface (no view) of `view`; `None`
/// when the configuration has no cone (the point is too close to the ball)
/// or no valid normal.
fn place_view(tree: &LightTree, view: &View) -> Option<(usize, Cone, Surface)> {
    let index = view.node.index(tree.nodes().len());
    let node = &tree.nodes()[index];
    let c = node.centroid().as_dvec3();
    let r = f64::from(node.radius()).max(1e-3 * c.abs().max_element().max(1e-6));
    let d = r * (1.0 + 10f64.powf(view.distance_exp));
    let direction = if view.along == 0 {
        view.direction
    } else {
        let farthest = tree.lights()[node.lights()]
            .iter()
            .map(|l| l.position.as_dvec3() - c)
            .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
            .unwrap();
        let line = farthest.try_normalize().unwrap_or(view.direction);
        (line * f64::from(view.along) + view.direction * 10f64.powf(view.aim)).normalize()
    };
    let point = (c + direction * d).as_vec3();
    let cone = node.cone(point.as_dvec3())?;
    // The normal as a caller gives it (f32), so grazing normals are grazing
    // to f32 precision.
    let given = normal(view, cone.axis, cone.sin_half_angle).as_vec3();
    let surface = Surface::new(point, given, None).ok()?;
    Some((index, cone, surface))
}

/// Checks one node bound against the exact sum; returns false when the
/// configuration has no cone (the point is too close to the ball).
fn check(tree: &LightTree, view: &View, kind: BoundKind, kd: Vec3) -> Result<bool, TestCaseError> {
    let Some((index, cone, surface)) = place_view(tree, view) else {
        return Ok(false);
    };
    let node = &tree.nodes()[index];
    let shader = Lambert::new(kd).with_bound(kind);
    let bound = shader.bound(&(), &surface, node, &cone);
    let exact = exact(&shader, &surface, tree, index);
    // A coarse bound is only given by the series bound.
    if kind != BoundKind::Series {
        let mut out = [None; 8];
        prop_assert!(!shader.bound_children_coarse(
            Seal,
            &(),
            &surface,
            children(tree, 0, 1),
            &mut out
        ));
    }
    for k in 0..3 {
        let allowance = ShadeResult::ROUNDING_ALLOWANCE * exact[k];
        prop_assert!(
            bound.lower[k] <= exact[k] + allowance && exact[k] <= bound.upper[k] + allowance,
            "{kind:?} channel {k}: exact {:e} outside [{:e}, {:e}] (node {index} of {} lights, \
             D/R - 1 = {:e}, n.uh = {:e}, view {view:?})",
            exact[k],
            bound.lower[k],
            bound.upper[k],
            node.light_count(),
            cone.distance / cone.radius - 1.0,
            surface.normal.dot(cone.axis),
        );
        prop_assert!(
            bound.lower[k] <= bound.estimate[k] && bound.estimate[k] <= bound.upper[k],
            "{kind:?} channel {k}: estimate {:e} outside [{:e}, {:e}]",
            bound.estimate[k],
            bound.lower[k],
            bound.upper[k]
        );
        prop_assert!(bound.error()[k].is_finite(), "error not finite: {bound:?}");
    }
    if kind == BoundKind::Series {
        check_coarse(tree, index, &surface, &shader, &bound, exact)?;
    }
    Ok(true)
}

/// The parent of node `index` and the node's place among its children
/// (its lane in the parent's block); `None` for the root.
fn parent_and_lane(tree: &LightTree, index: usize) -> Option<(usize, usize)> {
    let parent = tree
        .nodes()
        .iter()
        .position(|n| n.children().contains(&index))?;
    Some((parent, index - tree.nodes()[parent].children().start))
}

/// The coarse bound of node `index` (through its parent's
/// `bound_children_coarse`, alone and among all its siblings) contains the
/// exact sum, and is at most `2^-11` of the node's `I kd / (D - R)^2` wider
/// than the `f64` bound at either end.
///
/// The widening grows with `D / (D - R)`, at most 64 in `f32` lanes (`R / D
/// < 1 - 2^-6`). There the box's height slack, `12 u (D + B)` with `B <= 3
/// R`, times `(D / (D - R))^3 / D^3`, comes to about `2^-12.4` of the
/// scale; `sigma`'s upward nudge moves `(D / (D - R))^2` by about
/// `2^-14`, and the point's rounding adds `2^-16.4`: about `2^-11.95` in
/// all. A run of 20,000 cases found `2^-11.997` (`D / R - 1 = 0.016`).
fn check_coarse(
    tree: &LightTree,
    index: usize,
    surface: &Surface,
    shader: &Lambert,
    f64_bound: &NodeEstimate,
    exact: DVec3,
) -> Result<(), TestCaseError> {
    let Some((parent, lane)) = parent_and_lane(tree, index) else {
        return Ok(());
    };
    let node = &tree.nodes()[index];
    let siblings = tree.nodes()[parent].children().len();
    for wanted in [1u8 << lane, ((1u16 << siblings) - 1) as u8] {
        let mut out = [Some(NodeEstimate::ZERO); 8];
        prop_assert!(shader.bound_children_coarse(
            Seal,
            &(),
            surface,
            children(tree, parent, wanted),
            &mut out
        ));
        let Some(bound) = out[lane] else {
            // No finite bound: exactly where the f64 bound has none.
            prop_assert!(false, "no coarse bound where the cone exists");
            continue;
        };
        let d = (node.centroid().as_dvec3() - surface.point).length();
        let near = (d - f64::from(node.radius())).max(0.0);
        let scale = node.intensity() * shader.kd() / (near * near);
        for k in 0..3 {
            let allowance = ShadeResult::ROUNDING_ALLOWANCE * exact[k];
            prop_assert!(
                bound.lower[k] <= exact[k] + allowance && exact[k] <= bound.upper[k] + allowance,
                "coarse channel {k}: exact {:e} outside [{:e}, {:e}] (node {index}, \
                 D/R - 1 = {:e}, f64 bound [{:e}, {:e}])",
                exact[k],
                bound.lower[k],
                bound.upper[k],
                d / f64::from(node.radius()) - 1.0,
                f64_bound.lower[k],
                f64_bound.upper[k],
            );
            prop_assert!(
                bound.lower[k] <= bound.estimate[k] && bound.estimate[k] <= bound.upper[k]
            );
            let slack = scale[k] / 2048.0;
            // The f64 bound's chord term for nodes straddling the tangent
            // plane has no coarse counterpart: there the coarse upper end
            // may lie above the f64 one by up to the depth term.
            let straddles = straddles_plane(node, surface);
            prop_assert!(
                (bound.upper[k] <= f64_bound.upper[k] + slack || straddles)
                    && bound.lower[k] >= f64_bound.lower[k] - slack,
                "coarse channel {k}: [{:e}, {:e}] much wider than [{:e}, {:e}] (scale {:e}, \
                 D/R - 1 = {:e})",
                bound.lower[k],
                bound.upper[k],
                f64_bound.lower[k],
                f64_bound.upper[k],
                scale[k],
                d / f64::from(node.radius()) - 1.0,
            );
        }
    }
    Ok(())
}

/// Whether some corner of the node's box lies below the tangent plane and
/// some above.
fn straddles_plane(node: &crate::tree::Node, surface: &Surface) -> bool {
    let (lo, hi) = (node.aabb().min.as_dvec3(), node.aabb().max.as_dvec3());
    let heights = (0..8).map(|i| {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        surface.normal.dot(corner - surface.point)
    });
    let (low, high) = heights.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    low < 0.0 && high > 0.0
}

proptest! {
    #![proptest_config(cases(64))]

    /// Every bound kind contains the exact node sum, per channel, and its
    /// estimate lies in its interval. A case none of whose views has a
    /// cone checks nothing and is drawn again.
    #[test]
    fn node_bound_contains_exact_sum(
        lights in light_set(),
        views in prop::collection::vec(view(), 1..=24),
        kd in (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        prop_assert_eq!(tree.validate(), Ok(()));
        let kd = Vec3::new(kd.0, kd.1, kd.2);
        let mut checked = 0;
        for v in &views {
            for kind in [BoundKind::Series, BoundKind::Taylor, BoundKind::Paper] {
                checked += usize::from(check(&tree, v, kind, kd)?);
            }
        }
        prop_assume!(checked > 0, "no view has a cone");
    }
}

/// The coarse bound of a sum of shaders whose second term has no coarse
/// bound of its own (Phong): Lambert's coarse interval plus Phong's `f64`
/// bound under the child's cone, child `index` bounded through its parent,
/// which holds the exact sum of both terms. Returns false when there is
/// nothing to check: no cone, the root (no parent), no valid view, or no
/// coarse bound.
fn check_combined_coarse(
    tree: &LightTree,
    view: &View,
    kd: Vec3,
    (ks, exponent): (Vec3, f32),
    eye: DVec3,
) -> Result<bool, TestCaseError> {
    let Some((index, cone, surface)) = place_view(tree, view) else {
        return Ok(false);
    };
    let Some((parent, lane)) = parent_and_lane(tree, index) else {
        return Ok(false);
    };
    let Ok(surface) = surface.with_view(eye.as_vec3()) else {
        return Ok(false);
    };
    let (lambert, phong) = (Lambert::new(kd), Phong::new(ks, exponent));
    let combined = Combined::new(lambert, phong);
    let at = combined.prepare(&surface);
    let mut out = [None; 8];
    prop_assert!(combined.bound_children_coarse(
        Seal,
        &at,
        &surface,
        children(tree, parent, 1 << lane),
        &mut out
    ));
    let mut diffuse = [None; 8];
    prop_assert!(lambert.bound_children_coarse(
        Seal,
        &(),
        &surface,
        children(tree, parent, 1 << lane),
        &mut diffuse
    ));
    let node = &tree.nodes()[index];
    let (a, bound) = match (diffuse[lane], out[lane]) {
        (None, None) => return Ok(false),
        (Some(a), Some(bound)) => (a, bound),
        (a, bound) => {
            prop_assert!(false, "Lambert's coarse bound {a:?}, the sum's {bound:?}");
            return Ok(false);
        }
    };
    let b = phong.bound(&at.1, &surface, node, &cone);
    prop_assert_eq!(bound.estimate, a.estimate + b.estimate);
    prop_assert_eq!(bound.lower, a.lower + b.lower);
    prop_assert_eq!(bound.upper, a.upper + b.upper);
    let exact: DVec3 = tree.lights()[node.lights()]
        .iter()
        .map(|l| combined.eval(&at, &surface, l.position.as_dvec3(), l.intensity.as_dvec3()))
        .sum();
    for k in 0..3 {
        let allowance = ShadeResult::ROUNDING_ALLOWANCE * exact[k];
        prop_assert!(
            bound.lower[k] <= exact[k] + allowance && exact[k] <= bound.upper[k] + allowance,
            "channel {k}: exact {:e} outside [{:e}, {:e}] (node {index}, e = {exponent})",
            exact[k],
            bound.lower[k],
            bound.upper[k],
        );
    }
    Ok(true)
}

proptest! {
    #![proptest_config(cases(64))]

    /// Lambert's coarse bound beside Phong's (which has none of its own)
    /// in a sum of shaders contains the exact sum of both terms, for
    /// exponents taken by repeated multiplication (integers up to 512) and
    /// in log space. A case with nothing to check (a tree of one node, or
    /// no view with a cone) is drawn again.
    #[test]
    fn combined_coarse_bound_contains_exact_sum(
        lights in light_set(),
        views in prop::collection::vec((view(), unit()), 1..=12),
        kd in (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0),
        ks in (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0),
        exponent in prop::sample::select(vec![0.0f32, 1.0, 2.0, 7.0, 100.0, 512.0, 37.5, 513.0, 1e4, 1e6]),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let kd = Vec3::new(kd.0, kd.1, kd.2);
        let ks = Vec3::new(ks.0, ks.1, ks.2);
        let mut checked = 0;
        for (v, eye) in &views {
            checked += usize::from(check_combined_coarse(&tree, v, kd, (ks, exponent), *eye)?);
        }
        prop_assume!(checked > 0, "nothing to check");
    }
}

/// Sonin's inequality `m(m+1) P_m^2 + (1 - x^2) P_m'^2 <= m(m+1)`, used by
/// the pointwise bound, on a grid (it is an identity-based theorem; this
/// guards the formulas in the documentation against a slip).
#[test]
fn sonin_inequality_on_a_grid() {
    for m in 1..=8 {
        let mm = (m * (m + 1)) as f64;
        for j in 0..=10_000 {
            let x = -1.0 + 2.0 * j as f64 / 10_000.0;
            let (p, dp) = (legendre(m, x), legendre_derivative(m, x));
            assert!(mm * p * p + (1.0 - x * x) * dp * dp <= mm * (1.0 + 1e-12));
        }
    }
}

/// The stored harmonic norms against their definition as a double sum over
/// the members, `sum_ij I_i I_j |y_i|^l |y_j|^l P_l(y^_i . y^_j)`.
#[test]
fn harmonic_norms_match_the_double_sum() {
    let mut lights = Vec::new();
    for k in 0..40 {
        let t = k as f32 * 0.37;
        let position = Vec3::new(
            t.sin() * 3.0,
            (1.7 * t).cos() * 2.0,
            (0.3 * t).sin() + 0.1 * t,
        );
        let colour = Vec3::new(1.0 + t.sin(), 0.5, (0.5 * t).cos().abs());
        lights.push(PointLight::new(position, colour * (1.0 + k as f32)));
    }
    let tree = LightTree::build(&lights).unwrap();
    tree.validate().unwrap();
    for node in tree.nodes().iter().filter(|n| n.light_count() > 1) {
        let c = node.centroid().as_dvec3();
        let r = f64::from(node.radius());
        let members = &tree.lights()[node.lights()];
        for (d, norms) in node.harmonic_norms().iter().enumerate() {
            let l = d + 3;
            for k in 0..3 {
                let mut sum = 0.0;
                for a in members {
                    for b in members {
                        let (ya, yb) = (a.position.as_dvec3() - c, b.position.as_dvec3() - c);
                        let (ra, rb) = (ya.length(), yb.length());
                        if ra == 0.0 || rb == 0.0 {
                            continue;
                        }
                        let cos = (ya.dot(yb) / (ra * rb)).clamp(-1.0, 1.0);
                        sum += f64::from(a.intensity[k])
                            * f64::from(b.intensity[k])
                            * (ra / r).powi(l as i32)
                            * (rb / r).powi(l as i32)
                            * legendre(l, cos);
                    }
                }
                let expected = sum.max(0.0).sqrt() / node.intensity()[k];
                let stored = f64::from(norms[k]);
                assert!(
                    stored >= expected * (1.0 - 1e-9) && stored <= expected * (1.0 + 1e-6) + 1e-9,
                    "degree {l} channel {k}: stored {stored}, double sum {expected}"
                );
            }
        }
    }
}

/// `P_m(x)` by the three-term recurrence.
fn legendre(m: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, x);
    if m == 0 {
        return 1.0;
    }
    for l in 2..=m {
        (p0, p1) = (
            p1,
            ((2 * l - 1) as f64 * x * p1 - (l - 1) as f64 * p0) / l as f64,
        );
    }
    p1
}

/// `P_m'(x)` from `P_m' = sum of (2j + 1) P_j` over `j = m-1, m-3, ...`.
fn legendre_derivative(m: usize, x: f64) -> f64 {
    (0..m)
        .rev()
        .step_by(2)
        .map(|j| (2 * j + 1) as f64 * legendre(j, x))
        .sum()
}

proptest! {
    #![proptest_config(cases(64))]

    /// A light pair on a line through the point, offset across it along the
    /// normal, at grazing incidence with both lights just above the tangent
    /// plane: every degree of the series is positive and near its bound
    /// through the box's reach across the axis (`hperp`), so this is where
    /// that bound and its tail are tight.
    #[test]
    fn node_bound_contains_exact_sum_along_a_grazing_pair(
        sigma in 0.05f64..=0.995,
        far_weight in 1e-3f32..=0.5,
        offset_exp in -4.0f64..=-1.0,
        lift in 1.0f64..=4.0,
        scale_exp in -2.0f64..=3.0,
    ) {
        let scale = 10f64.powf(scale_exp);
        let (f, h) = (f64::from(far_weight), 10f64.powf(offset_exp));
        // Far light at (1, 0, h), near one at -(f / (1 - f)) times that, so
        // the weighted centroid is the origin.
        let far = DVec3::new(1.0, 0.0, h) * scale;
        let near = -far * (f / (1.0 - f));
        let lights = [
            PointLight::new(far.as_vec3(), Vec3::splat(far_weight)),
            PointLight::new(near.as_vec3(), Vec3::splat(1.0 - far_weight)),
        ];
        let tree = LightTree::build(&lights).unwrap();
        let node = &tree.nodes()[0];
        let c = node.centroid().as_dvec3();
        let d = f64::from(node.radius()) / sigma;
        let point = (c + DVec3::X * d).as_vec3();
        let Some(cone) = node.cone(point.as_dvec3()) else {
            return Ok(());
        };
        // n . uh = lift * (the near light's height below the centroid) / D.
        let c0 = lift * (c.z - near.z).abs() / d;
        let normal = (DVec3::Z + cone.axis * c0).normalize();
        let Ok(surface) = Surface::new(point, normal.as_vec3(), None) else {
            return Ok(());
        };
        let shader = Lambert::new(Vec3::ONE);
        let bound = shader.bound(&(), &surface, node, &cone);
        let exact = exact(&shader, &surface, &tree, 0);
        for k in 0..3 {
            let allowance = ShadeResult::ROUNDING_ALLOWANCE * exact[k];
            prop_assert!(
                bound.lower[k] <= exact[k] + allowance && exact[k] <= bound.upper[k] + allowance,
                "exact {:e} outside [{:e}, {:e}]", exact[k], bound.lower[k], bound.upper[k]
            );
        }
        // The same pair as one child of a root (a third light far behind
        // the point, leaves of two lights), bounded coarsely.
        let mut three = lights.to_vec();
        three.push(PointLight::new((point.as_dvec3() * 2.0 - c * 1e3).as_vec3(), Vec3::ONE));
        let tree = LightTree::builder().max_leaf_lights(2).build(&three).unwrap();
        if let Some(pair) = tree.nodes().iter().position(|n| {
            n.light_count() == 2 && tree.lights()[n.lights()].iter().all(|l| l.position != three[2].position)
        }) && pair != 0
        {
            let node = &tree.nodes()[pair];
            if let Some(cone) = node.cone(surface.point) {
                let bound = shader.bound(&(), &surface, node, &cone);
                let sum = self::exact(&shader, &surface, &tree, pair);
                check_coarse(&tree, pair, &surface, &shader, &bound, sum)?;
            }
        }
    }
}
