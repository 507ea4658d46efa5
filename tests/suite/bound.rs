//! Property tests of the certified-bound contract against the exact sum
//! (`Shading::exact_query`), for Lambert (both bounds), Phong across
//! exponents, and their sum.

use crate::common::*;
use glam::Vec3;
use manylights::shader::Shader;
use manylights::{
    BoundKind, Combined, Lambert, LightTree, Phong, Query, ShadeResult, Shading, Stop, Threshold,
    Unoccluded,
};
use proptest::prelude::*;

/// Phong exponents from the constant lobe to the sharpest supported, all property-tested.
const EXPONENTS: [f32; 6] = [0.0, 1.0, 10.0, 100.0, 1e4, 1e6];

fn albedo() -> impl Strategy<Value = Vec3> {
    (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0).prop_map(|(r, g, b)| Vec3::new(r, g, b))
}

/// Checks the contract, the threshold, and the two limits (threshold 0 is
/// exact, an infinite one evaluates the root only) at one point.
fn check_point<S: Shader>(
    shading: &mut Shading<'_, S>,
    shade: impl Fn(&mut Shading<'_, S>, Threshold) -> manylights::ShadeResult,
    exact: glam::DVec3,
    t: Threshold,
    point: Vec3,
) -> Result<(), TestCaseError> {
    let r = shade(shading, t);
    check_bound(&r, exact)?;
    check_threshold(&r, &t)?;

    let zero = shade(shading, Threshold::zero());
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

    let inf = shade(shading, Threshold::absolute(f64::INFINITY));
    check_bound(&inf, exact)?;
    // The root alone, unless its ball reaches the shading point (then it has
    // no finite bound and must be refined whatever the threshold).
    let root = shading.tree().root().unwrap();
    if root.light_count() == 1 || root.cone(point.as_dvec3()).is_some() {
        prop_assert!(
            inf.nodes_evaluated + inf.lights_evaluated <= 1,
            "infinite threshold refined: {inf:?}"
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(cases(96))]

    #[test]
    fn lambert_bound_holds(
        lights in lights(2000),
        p in vec_in(12.0),
        n in direction(),
        kd in albedo(),
        t in threshold(),
        paper in any::<bool>(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        prop_assert_eq!(tree.validate(), Ok(()));
        let kind = if paper { BoundKind::Paper } else { BoundKind::Series };
        let mut shading = tree.shading(Lambert::new(kd).with_bound(kind));
        let exact = shading.exact(p, n).unwrap();
        check_point(&mut shading, |s, t| s.shade(p, n, t).unwrap(), exact, t, p)?;
    }

    #[test]
    fn phong_bound_holds(
        lights in lights(2000),
        p in vec_in(12.0),
        n in direction(),
        v in direction(),
        ks in albedo(),
        e in prop::sample::select(EXPONENTS.to_vec()),
        t in threshold(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        prop_assert_eq!(tree.validate(), Ok(()));
        let mut shading = tree.shading(Phong::new(ks, e));
        let exact = shading.exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), Unoccluded);
        check_point(&mut shading, |s, t| s.shade_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), t, Unoccluded).unwrap(), exact, t, p)?;
    }

    #[test]
    fn combined_bound_holds(
        lights in lights(2000),
        p in vec_in(12.0),
        n in direction(),
        v in direction(),
        kd in albedo(),
        ks in albedo(),
        e in prop::sample::select(EXPONENTS.to_vec()),
        t in threshold(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Combined::new(Lambert::new(kd), Phong::new(ks, e)));
        let exact = shading.exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), Unoccluded);
        check_point(&mut shading, |s, t| s.shade_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), t, Unoccluded).unwrap(), exact, t, p)?;
    }

    /// Shading points on a receiving plane under lights above it: the layout
    /// of the paper's scenes, where the second-order bound is active.
    #[test]
    fn lambert_bound_holds_above_plane(
        lights in lights(2000),
        (x, y) in (-15.0f32..=15.0, -15.0f32..=15.0),
        tilt in vec_in(0.3),
        kd in albedo(),
        t in threshold(),
    ) {
        let lifted: Vec<_> = lights
            .into_iter()
            .map(|l| manylights::PointLight::new(l.position + Vec3::new(0.0, 0.0, 14.0), l.intensity))
            .collect();
        let tree = LightTree::build(&lifted).unwrap();
        let mut shading = tree.shading(Lambert::new(kd));
        let (p, n) = (Vec3::new(x, y, 0.0), Vec3::Z + tilt);
        let exact = shading.exact(p, n).unwrap();
        check_point(&mut shading, |s, t| s.shade(p, n, t).unwrap(), exact, t, p)?;
    }

    /// Lights in a slab of thickness `10^-6` to `10` around a plane at any
    /// tilt, shading points inside the slab with normals from exactly the
    /// plane's to a tenth of a radian off it (either side): every node the
    /// cut meets straddles the tangent plane, which the bound's clamp terms
    /// (depth and chord) must cover. Single points and a batch.
    #[test]
    fn lambert_bound_holds_in_slabs_around_tilted_planes(
        count in 50usize..1500,
        axis in direction(),
        thickness in -6.0f32..=1.0,
        seed in any::<u64>(),
        colours in prop::collection::vec(intensity(), 8),
        (u, v, h) in (-40.0f32..=40.0, -40.0f32..=40.0, -0.5f32..=0.5),
        tilt in (-7.0f32..=-1.0, direction(), any::<bool>(), any::<bool>()),
        kd in albedo(),
        t in threshold(),
    ) {
        let a = axis.normalize();
        let b = a.any_orthonormal_vector();
        let c = a.cross(b);
        let thickness = 10f32.powf(thickness);
        let mut state = seed;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let lights: Vec<_> = (0..count)
            .map(|i| {
                let position = b * (100.0 * uniform()) + c * (100.0 * uniform()) + a * (thickness * uniform());
                manylights::PointLight::new(position, colours[i % colours.len()])
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Lambert::new(kd));
        let p = b * u + c * v + a * (thickness * h);
        let (angle, off, exact_plane, flip) = tilt;
        let n = if exact_plane { a } else { (a + off.normalize() * 10f32.powf(angle)).normalize() };
        let n = if flip { -n } else { n };
        let exact = shading.exact(p, n).unwrap();
        check_point(&mut shading, |s, t| s.shade(p, n, t).unwrap(), exact, t, p)?;

        let queries: Vec<_> = (0..16)
            .filter_map(|i| {
                let q = p + b * ((i % 4) as f32 * 0.3) + c * ((i / 4) as f32 * 0.3);
                Query::new(q, n).ok()
            })
            .collect();
        let mut results = vec![ShadeResult::default(); queries.len()];
        shading.shade_batch(&queries, t, Unoccluded, &mut results).unwrap();
        for (q, r) in queries.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, Unoccluded))?;
        }
    }

    /// The specular criterion refines every node whose upper bound exceeds
    /// it: afterwards no single node's bound can exceed it, so the whole
    /// error bound is at most (number of unrefined nodes) times it.
    #[test]
    fn max_contribution_criterion(
        lights in lights(500),
        p in vec_in(12.0),
        n in direction(),
        v in direction(),
        m in -4.0f64..=1.0,
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Phong::new(Vec3::ONE, 50.0));
        let exact = shading.exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), Unoccluded);
        let cap = 10f64.powf(m);
        let t = Threshold::absolute(f64::INFINITY).with_max_contribution(cap);
        let r = shading.shade_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), t, Unoccluded).unwrap();
        check_bound(&r, exact)?;
        prop_assert!(r.error_bound.max_element() <= cap * f64::from(r.nodes_evaluated) * (1.0 + 1e-9) + 1e-300);
    }
}

#[test]
fn empty_tree_shades_to_zero() {
    let tree = LightTree::build(&[]).unwrap();
    tree.validate().unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let r = s.shade(Vec3::ZERO, Vec3::Z, Threshold::zero()).unwrap();
    assert_eq!(r.radiance, glam::DVec3::ZERO);
    assert_eq!(r.error_bound, glam::DVec3::ZERO);
    assert_eq!(r.stop, Stop::ThresholdMet);
}
