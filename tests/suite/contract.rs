//! Regression tests at the edges of the documented contract: a met
//! threshold holds for the bound as reported, infinite thresholds stop at
//! the root, budgets cap all the work, refits of the wrong size say so.

use glam::Vec3;
use manylights::{
    BuildError, Lambert, LightTree, Phong, PointLight, Query, Stop, Target, Threshold, Unoccluded,
};

/// A street of lamps over a 100 x 100 ground, 5 units up.
fn street() -> Vec<PointLight> {
    (0..2000)
        .map(|i| {
            let (x, y) = ((i % 50) as f32 * 2.0, (i / 50) as f32 * 2.5);
            let tint = Vec3::new(1.0, 0.8 + 0.1 * (i % 3) as f32, 0.6);
            PointLight::new(Vec3::new(x, y, 5.0), tint)
        })
        .collect()
}

/// "Met" means the reported bound meets the threshold, with no slack: the
/// stop test and the reported bound are the same number. Checked over 80
/// neighbouring thresholds of each kind, where a stop test on the raw sum
/// and a bound inflated afterwards disagree by a few ulps.
#[test]
fn met_threshold_holds_for_the_reported_bound() {
    let tree = LightTree::build(&street()).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::splat(0.7)));
    let p = Vec3::new(37.0, 41.0, 0.0);
    let reference = s.shade(p, Vec3::Z, Threshold::relative(0.01)).unwrap();
    let (mut absolute, mut relative) = (reference.error_bound.max_element(), 0.01);
    for _ in 0..80 {
        for t in [Threshold::absolute(absolute), Threshold::relative(relative)] {
            let r = s.shade(p, Vec3::Z, t).unwrap();
            assert_eq!(r.stop, Stop::ThresholdMet);
            let limit = match t.target() {
                Target::Absolute(a) => a,
                Target::Relative(q) => q * r.radiance.max_element(),
                Target::PerNode(_) => unreachable!(),
            };
            assert!(
                r.error_bound.max_element() <= limit,
                "{t:?}: bound {} > {limit}",
                r.error_bound.max_element()
            );
        }
        absolute = absolute.next_down();
        relative = relative.next_down();
    }
}

/// With every light outside a narrow Phong lobe the estimate is 0, and an
/// infinite relative or per-node threshold (`inf * 0`) still stops at the
/// root.
#[test]
fn infinite_thresholds_stop_at_the_root_on_a_zero_estimate() {
    let tree = LightTree::build(&street()).unwrap();
    let mut s = tree.shading(Phong::new(Vec3::ONE, 1e4));
    // Far below the lamps (the root's ball does not reach the point), with
    // the mirror direction pointing straight down, away from every light.
    let q = Query::new(Vec3::new(50.0, 50.0, -300.0), Vec3::Z)
        .unwrap()
        .with_view(Vec3::NEG_Z)
        .unwrap();
    for t in [
        Threshold::relative(f64::INFINITY),
        Threshold::per_node(f64::INFINITY),
        Threshold::absolute(f64::INFINITY),
    ] {
        let r = s.shade_query(&q, t, Unoccluded).unwrap();
        assert_eq!(r.cost(), 1, "{t:?}: {r:?}");
        assert_eq!(r.stop, Stop::ThresholdMet);
        assert!(r.certifies(s.exact_query(&q, Unoccluded)));
    }
}

/// A budget caps everything a call evaluates, interpolation included.
#[test]
fn budgets_cap_interpolation_too() {
    let tree = LightTree::build(&street()).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::splat(0.7)));
    for band in [2.0, 8.0, 1e6] {
        for budget in [50, 200, 482, 1000] {
            for i in 0..20 {
                let p = Vec3::new(3.0 + 4.7 * i as f32, 11.0 + 3.1 * i as f32, 0.0);
                let t = Threshold::relative(0.01)
                    .with_interpolation(band)
                    .with_budget(budget);
                let r = s.shade(p, Vec3::Z, t).unwrap();
                assert!(
                    r.cost() <= budget,
                    "band {band}: cost {} > {budget}",
                    r.cost()
                );
                assert!(r.certifies(s.exact(p, Vec3::Z).unwrap()));
            }
        }
    }
}

#[test]
fn refit_with_the_wrong_number_of_lights_is_a_count_mismatch() {
    let lights = street();
    let mut tree = LightTree::build(&lights).unwrap();
    assert_eq!(
        tree.refit(&lights[..10]),
        Err(BuildError::LightCountMismatch {
            expected: lights.len(),
            got: 10
        })
    );
    assert_eq!(tree.refit(&lights), Ok(()));
}
