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
