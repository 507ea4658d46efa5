//! The GGX microfacet shader: its terms against an independent `f64`
//! evaluation of the textbook formulas, and the certified-bound contract
//! against the exact sum (`Shading::exact_query`), alone and beside
//! Lambert, for roughness log-uniform over the whole range, coloured
//! `F0`, grazing views and lights; stiff named cases.

use crate::common::*;
use glam::{DVec3, Vec3};
use manylights::shader::Shader;
use manylights::{
    Combined, Ggx, Lambert, LightTree, PointLight, Query, ShadeError, ShadeResult, Shading, Stop,
    Threshold, Unoccluded,
};
use proptest::prelude::*;

/// The model, summed in `f64` from the textbook formulas (`D` from `n.h`,
/// `Lambda` from `tan^2`): a reference written independently of the
/// crate's forms.
fn reference(lights: &[PointLight], p: Vec3, n: Vec3, v: Vec3, f0: Vec3, alpha: f32) -> DVec3 {
    let (p, n, v) = (
        p.as_dvec3(),
        n.as_dvec3().normalize(),
        v.as_dvec3().normalize(),
    );
    let (a, f0) = (f64::from(alpha), f0.as_dvec3());
    let nv = n.dot(v);
    if nv <= 0.0 {
        return DVec3::ZERO;
    }
    let lambda = |c: f64| ((1.0 + a * a * (1.0 - c * c) / (c * c)).sqrt() - 1.0) / 2.0;
    let mut sum = DVec3::ZERO;
    for light in lights {
        let d = light.position.as_dvec3() - p;
        let d2 = d.length_squared();
        if d2 == 0.0 {
            continue;
        }
        let l = d / d2.sqrt();
        let nl = n.dot(l);
        if nl <= 0.0 {
            continue;
        }
        let h = (l + v).normalize();
        let nh = n.dot(h);
        let t = nh * nh * (a * a - 1.0) + 1.0;
        let distribution = a * a / (std::f64::consts::PI * t * t);
        let g2 = 1.0 / (1.0 + lambda(nl) + lambda(nv));
        let fresnel = f0 + (DVec3::ONE - f0) * (1.0 - v.dot(h)).powi(5);
        let brdf = fresnel * (distribution * g2 / (4.0 * nl * nv));
        sum += light.intensity.as_dvec3() * brdf * nl / d2;
    }
    sum
}

/// Roughness log-uniform over `[1e-3, 1]`.
fn roughness() -> impl Strategy<Value = f32> {
    (-3.0f64..=0.0).prop_map(|u| (10f64.powf(u) as f32).clamp(1e-3, 1.0))
}

/// A coloured `F0`, channels in `[0, 1]`.
fn colour() -> impl Strategy<Value = Vec3> {
    (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0).prop_map(|(r, g, b)| Vec3::new(r, g, b))
}

/// A view for normal `n`: anywhere on the sphere, or grazing (`n.v` of
/// either sign and magnitude `10^-7` to `10^-1`, before `f32` rounding).
fn view_for(n: Vec3) -> impl Strategy<Value = Vec3> {
    prop_oneof![
        2 => direction(),
        1 => (direction(), -7.0f32..=-1.0, any::<bool>()).prop_map(move |(w, u, up)| {
            let n = n.normalize();
            let tangent = (w - n * w.dot(n)).try_normalize().unwrap_or(n.any_orthonormal_vector());
            tangent + n * 10f32.powf(u) * if up { 1.0 } else { -1.0 }
        }),
    ]
}

/// A normal and a view for it.
fn normal_and_view() -> impl Strategy<Value = (Vec3, Vec3)> {
    direction().prop_flat_map(|n| (Just(n), view_for(n)))
}

/// Lights of [`lights`], a share of them moved to within `10^-6` to 1 of
/// the horizontal plane through `p` (above or below): grazing lights for a
/// point of normal `+z`.
fn grazing_lights(p: Vec3) -> impl Strategy<Value = Vec<PointLight>> {
    (lights(1500), any::<u64>()).prop_map(move |(lights, seed)| {
        let mut state = seed | 1;
        lights
            .into_iter()
            .map(|l| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                if state % 3 == 0 {
                    return l;
                }
                let u = (state >> 11) as f32 / (1u64 << 53) as f32;
                let sign = if state & 2 == 0 { 1.0 } else { -1.0 };
                let z = p.z + sign * 10f32.powf(-6.0 + 6.0 * u);
                PointLight::new(Vec3::new(l.position.x, l.position.y, z), l.intensity)
            })
            .collect()
    })
}

fn query(p: Vec3, n: Vec3, v: Vec3) -> Query<manylights::query::WithView> {
    Query::new(p, n).unwrap().with_view(v).unwrap()
}

/// The contract, the threshold, the exact limit at threshold 0 and the
/// root alone at an infinite threshold, at one point.
fn check_point<S: Shader>(
    shading: &mut Shading<'_, S>,
    q: &Query<manylights::query::WithView>,
    t: Threshold,
) -> Result<ShadeResult, TestCaseError> {
    let exact = shading.exact_query(q, Unoccluded);
    let r = shading.shade_query(q, t, Unoccluded).unwrap();
    check_bound(&r, exact)?;
    check_threshold(&r, &t)?;

    let zero = shading
        .shade_query(q, Threshold::zero(), Unoccluded)
        .unwrap();
    prop_assert_eq!(zero.stop, Stop::ThresholdMet);
    for k in 0..3 {
        prop_assert!(
            (zero.radiance[k] - exact[k]).abs()
                <= 2.0 * ShadeResult::ROUNDING_ALLOWANCE * exact[k] + 1e-300,
            "threshold 0 is not exact: {} vs {}",
            zero.radiance,
            exact
        );
    }
    let inf = shading
        .shade_query(q, Threshold::absolute(f64::INFINITY), Unoccluded)
        .unwrap();
    check_bound(&inf, exact)?;
    Ok(r)
}

/// Relative agreement of the crate's exact sum with [`reference`], where
/// the reference itself is accurate: `1e-7` of the larger channel (the
/// textbook `D` loses digits to `1 - (n.h)^2` near the lobe's axis, and
/// `Lambda` to `tan^2` near grazing).
fn agrees(ours: DVec3, theirs: DVec3) -> bool {
    let scale = ours.max_element().max(theirs.max_element());
    (ours - theirs).abs().max_element() <= 1e-7 * scale + 1e-300
}

proptest! {
    #![proptest_config(cases(64))]

    /// Each term against the textbook formulas, summed.
    #[test]
    fn terms_match_the_textbook_model(
        light_set in lights(300),
        p in vec_in(12.0),
        n in direction(),
        v in direction(),
        f0 in colour(),
        alpha in roughness(),
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let shading = tree.shading(Ggx::new(f0, alpha));
        let ours = shading.exact_query(&query(p, n, v), Unoccluded);
        let theirs = reference(&light_set, p, n, v, f0, alpha);
        prop_assert!(agrees(ours, theirs), "{ours} vs {theirs}");
    }

    #[test]
    fn ggx_bound_holds(
        light_set in lights(2000),
        p in vec_in(12.0),
        (n, v) in normal_and_view(),
        f0 in colour(),
        alpha in roughness(),
        t in threshold(),
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let mut shading = tree.shading(Ggx::new(f0, alpha));
        check_point(&mut shading, &query(p, n, v), t)?;
    }

    #[test]
    fn ggx_beside_lambert_bound_holds(
        light_set in lights(2000),
        p in vec_in(12.0),
        (n, v) in normal_and_view(),
        kd in colour(),
        f0 in colour(),
        alpha in roughness(),
        t in threshold(),
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let mut shading = tree.shading(Combined::new(Lambert::new(kd), Ggx::new(f0, alpha)));
        check_point(&mut shading, &query(p, n, v), t)?;
    }

    /// Lights grazing the tangent plane (normal `+z`), views grazing too.
    #[test]
    fn ggx_bound_holds_for_grazing_lights(
        (p, light_set) in vec_in(8.0).prop_flat_map(|p| (Just(p), grazing_lights(p))),
        v in view_for(Vec3::Z),
        f0 in colour(),
        alpha in roughness(),
        t in threshold(),
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let mut shading = tree.shading(Ggx::new(f0, alpha));
        check_point(&mut shading, &query(p, Vec3::Z, v), t)?;
    }

    /// Every node's interval (with a cone) holds the sum of its lights'
    /// terms, and its estimate lies in it: the bound itself, without the
    /// cut, alone and through the eight-wide `bound_nodes`; lights
    /// grazing the plane of normal `+z`, views grazing it too.
    #[test]
    fn every_node_bound_holds(
        (p, light_set) in vec_in(8.0).prop_flat_map(|p| (Just(p), grazing_lights(p))),
        (n, v) in prop_oneof![
            normal_and_view(),
            view_for(Vec3::Z).prop_map(|v| (Vec3::Z, v)),
        ],
        f0 in colour(),
        alpha in roughness(),
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let ggx = Ggx::new(f0, alpha);
        let q = query(p, n, v);
        let surface = q.surface();
        let at = ggx.prepare(surface);
        let nodes: Vec<_> = tree.nodes().iter().filter_map(|node| Some((node, node.cone(surface.point)?))).collect();
        let mut together = vec![manylights::shader::NodeEstimate::ZERO; nodes.len()];
        let refs: Vec<_> = nodes.iter().map(|(node, _)| *node).collect();
        let cones: Vec<_> = nodes.iter().map(|(_, cone)| *cone).collect();
        ggx.bound_nodes(&at, surface, &refs, &cones, &mut together);
        for ((node, cone), joint) in nodes.iter().zip(&together) {
            let exact: DVec3 = tree.lights()[node.lights()]
                .iter()
                .map(|l| ggx.eval(&at, surface, l.position.as_dvec3(), l.intensity.as_dvec3()))
                .sum();
            let b = ggx.bound(&at, surface, node, cone);
            prop_assert_eq!(&b, joint);
            let slack = exact * ShadeResult::ROUNDING_ALLOWANCE;
            prop_assert!(
                b.lower.cmple(exact + slack).all() && (exact - slack).cmple(b.upper).all(),
                "{} outside [{}, {}] ({} lights)", exact, b.lower, b.upper, node.light_count()
            );
            prop_assert!(b.lower.cmple(b.estimate).all() && b.estimate.cmple(b.upper).all());
            prop_assert!(b.lower.min_element() >= 0.0 && b.upper.is_finite());
        }
    }

    /// The specular criterion refines every node whose upper bound exceeds
    /// it, as for Phong: no settled node's bound exceeds it.
    #[test]
    fn max_contribution_criterion(
        light_set in lights(500),
        p in vec_in(12.0),
        (n, v) in normal_and_view(),
        alpha in roughness(),
        m in -4.0f64..=1.0,
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let mut shading = tree.shading(Ggx::new(Vec3::splat(0.04), alpha));
        let q = query(p, n, v);
        let exact = shading.exact_query(&q, Unoccluded);
        let cap = 10f64.powf(m);
        let t = Threshold::absolute(f64::INFINITY).with_max_contribution(cap);
        let r = shading.shade_query(&q, t, Unoccluded).unwrap();
        check_bound(&r, exact)?;
        prop_assert!(r.error_bound.max_element() <= cap * f64::from(r.nodes_evaluated) * (1.0 + 1e-9) + 1e-300);
    }
}

/// A grid of `side^2` lamps at height 6 over `[-50, 50]^2`, warm white.
fn lamps(side: usize) -> Vec<PointLight> {
    let step = 100.0 / (side - 1) as f32;
    let mut lights = Vec::new();
    for i in 0..side {
        for j in 0..side {
            let (x, y) = (-50.0 + step * i as f32, -50.0 + step * j as f32);
            lights.push(PointLight::new(
                Vec3::new(x, y, 6.0),
                Vec3::new(1.0, 0.8, 0.6),
            ));
        }
    }
    lights
}

/// `D G2 F / (4 nl nv) * nl`, the brdf times the cosine, for a light on
/// the mirror direction (`h = n`, `n.l = n.v = c`, `v.h = c`).
fn on_mirror(alpha: f64, c: f64, f0: f64) -> f64 {
    let m = (alpha * alpha + (1.0 - alpha * alpha) * c * c).sqrt();
    let vis = 0.5 / (2.0 * c * m);
    let d = 1.0 / (std::f64::consts::PI * alpha * alpha);
    let f = f0 + (1.0 - f0) * (1.0 - c).powi(5);
    d * vis * f * c
}

/// `alpha = 1e-3` with a light exactly on the mirror direction among ten
/// thousand others: the term is the lobe's peak, and a certified 1% finds
/// it without a walk of the tree.
#[test]
fn sharpest_lobe_with_a_light_on_the_mirror_direction() {
    let mut lights = lamps(100);
    // View (3, 0, 4) / 5 from the origin: the mirror direction is
    // (-3, 0, 4) / 5, where this light sits at distance 10.
    let mirror = PointLight::new(Vec3::new(-6.0, 0.0, 8.0), Vec3::ONE);
    lights.push(mirror);
    let tree = LightTree::build(&lights).unwrap();
    let ggx = Ggx::new(Vec3::splat(0.04), 1e-3);
    let mut shading = tree.shading(ggx);
    let q = query(Vec3::ZERO, Vec3::Z, Vec3::new(3.0, 0.0, 4.0));

    let alone = LightTree::build(&[mirror]).unwrap();
    let peak = alone.shading(ggx).exact_query(&q, Unoccluded);
    let expected = on_mirror(f64::from(1e-3f32), 0.8, f64::from(0.04f32)) / 100.0;
    assert!(
        (peak - DVec3::splat(expected)).abs().max_element() <= 1e-12 * expected,
        "{peak} vs {expected}"
    );

    let exact = shading.exact_query(&q, Unoccluded);
    assert!(exact.x >= peak.x, "{exact} < {peak}");
    let r = shading
        .shade_query(&q, Threshold::relative(0.01), Unoccluded)
        .unwrap();
    assert!(r.certifies(exact), "{r:?} against {exact}");
    assert_eq!(r.stop, Stop::ThresholdMet);
    assert!(r.error_bound.max_element() <= 0.01 * r.radiance.max_element());
    assert!(
        r.cost() * 4 < lights.len() as u32,
        "cost {} for {} lights",
        r.cost(),
        lights.len()
    );
}

/// A view at `n.v = 1e-6` (the eye grazing the surface), with a light on
/// its mirror direction and a grid of others: finite terms, the peak's
/// value, the contract at every threshold kind.
#[test]
fn view_grazing_at_one_in_a_million() {
    let v = Vec3::new(1.0, 0.0, 1e-6);
    let mirror = PointLight::new(Vec3::new(-20.0, 0.0, 20e-6), Vec3::ONE);
    let mut lights = lamps(40);
    lights.push(mirror);
    for alpha in [1e-3f32, 0.02, 0.1, 0.5, 1.0] {
        let ggx = Ggx::new(Vec3::new(0.9, 0.6, 0.3), alpha);
        let q = query(Vec3::ZERO, Vec3::Z, v);
        let alone = LightTree::build(&[mirror]).unwrap();
        let peak = alone.shading(ggx).exact_query(&q, Unoccluded);
        let theirs = reference(
            &[mirror],
            Vec3::ZERO,
            Vec3::Z,
            v,
            Vec3::new(0.9, 0.6, 0.3),
            alpha,
        );
        assert!(peak.is_finite() && peak.min_element() > 0.0, "{peak}");
        assert!(agrees(peak, theirs), "alpha {alpha}: {peak} vs {theirs}");

        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(ggx);
        let exact = shading.exact_query(&q, Unoccluded);
        for t in [
            Threshold::relative(0.01),
            Threshold::relative(0.2).with_interpolation(2.0),
            Threshold::absolute(1e-6),
            Threshold::absolute(f64::INFINITY).with_max_contribution(1e-3),
            Threshold::zero(),
        ] {
            let r = shading.shade_query(&q, t, Unoccluded).unwrap();
            assert!(
                r.certifies(exact),
                "alpha {alpha} {t:?}: {r:?} against {exact}"
            );
            assert!(r.radiance.is_finite() && !r.error_bound.is_nan());
        }
    }
}

/// Lights behind the surface, or in its plane, contribute exactly 0; so
/// does every light when the eye is behind the surface, and the bound is
/// then exactly 0 at the root.
#[test]
fn lights_and_eyes_behind_the_surface_contribute_nothing() {
    let behind = [
        PointLight::new(Vec3::new(1.0, 2.0, -3.0), Vec3::ONE),
        PointLight::new(Vec3::new(-4.0, 0.5, -0.001), Vec3::ONE),
        PointLight::new(Vec3::new(5.0, -5.0, 0.0), Vec3::ONE),
    ];
    let tree = LightTree::build(&behind).unwrap();
    let mut shading = tree.shading(Ggx::new(Vec3::ONE, 0.3));
    let q = query(Vec3::ZERO, Vec3::Z, Vec3::new(0.2, 0.1, 1.0));
    assert_eq!(shading.exact_query(&q, Unoccluded), DVec3::ZERO);
    let r = shading
        .shade_query(&q, Threshold::relative(0.01), Unoccluded)
        .unwrap();
    assert_eq!((r.radiance, r.error_bound), (DVec3::ZERO, DVec3::ZERO));

    // More lights than a small scene, which is summed whole.
    let lights = lamps(40);
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Ggx::new(Vec3::ONE, 0.3));
    for v in [
        Vec3::new(1.0, 0.0, -0.5),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -1.0),
    ] {
        // Outside the root's ball, so that the root has a bound.
        let q = query(Vec3::new(200.0, 300.0, 0.0), Vec3::Z, v);
        assert_eq!(shading.exact_query(&q, Unoccluded), DVec3::ZERO);
        let r = shading
            .shade_query(&q, Threshold::relative(0.01), Unoccluded)
            .unwrap();
        assert_eq!((r.radiance, r.error_bound), (DVec3::ZERO, DVec3::ZERO));
        assert!(r.cost() <= 1, "{r:?}");
    }
}

/// Bad parameters are refused with a clear error; the convenience
/// constructor clamps them in release builds.
#[test]
fn bad_parameters_are_refused() {
    let refused = |f0: Vec3, alpha: f32| {
        matches!(Ggx::try_new(f0, alpha), Err(ShadeError::InvalidMaterial(_)))
    };
    for alpha in [0.0, 1e-4, 1.5, -0.1, f32::NAN, f32::INFINITY] {
        assert!(refused(Vec3::splat(0.04), alpha), "alpha {alpha}");
    }
    for f0 in [
        Vec3::new(1.1, 0.0, 0.0),
        Vec3::new(0.0, -0.1, 0.0),
        Vec3::new(0.0, 0.0, f32::NAN),
    ] {
        assert!(refused(f0, 0.1), "F0 {f0}");
    }
    let ok = Ggx::try_new(Vec3::new(0.0, 0.5, 1.0), 1e-3).unwrap();
    assert_eq!(
        (ok.alpha(), ok.f0()),
        (f64::from(1e-3f32), DVec3::new(0.0, 0.5, 1.0))
    );
    assert!(Ggx::try_new(Vec3::ONE, 1.0).is_ok());
}
