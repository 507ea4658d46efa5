//! Hostile scenes that once made the cut's cost explode, each a test on
//! evaluation counts (never on times).

use glam::Vec3;
use manylights::{Lambert, LightTree, PointLight, Threshold};

/// `n` coincident lights at `at`.
fn stack(n: usize, at: Vec3) -> Vec<PointLight> {
    vec![PointLight::new(at, Vec3::new(1.0, 0.5, 0.25)); n]
}

/// Coincident lights are one virtual light: a point on the stack, or beside
/// it, costs the same whatever the number of lights.
#[test]
fn coincident_stack_costs_a_constant() {
    let at = Vec3::new(1.0, 2.0, 3.0);
    let mut costs = Vec::new();
    // The smallest stack fits in a leaf by count (the default leaves hold
    // up to 32 lights), the others only as coincident lights.
    for n in [25, 1_000, 200_000] {
        let mut lights = stack(n, at);
        // A few other lights so that the stack is a leaf below the root.
        lights.extend((0..8).map(|i| PointLight::new(Vec3::new(i as f32, -5.0, 0.0), Vec3::ONE)));
        let tree = LightTree::build(&lights).unwrap();
        tree.validate().unwrap();
        let mut s = tree.shading(Lambert::new(Vec3::ONE));
        let mut cost = Vec::new();
        for (p, normal) in [
            (at, Vec3::Z),
            (at - Vec3::Z, Vec3::Z),
            (at + Vec3::X, -Vec3::X),
        ] {
            for t in [Threshold::zero(), Threshold::relative(0.01)] {
                let r = s.shade(p, normal, t).unwrap();
                assert!(r.certifies(s.exact(p, normal).unwrap()), "{r:?}");
                cost.push(r.cost());
            }
        }
        costs.push(cost);
    }
    assert!(costs.iter().all(|c| *c == costs[0]), "{costs:?}");
    assert!(costs[0].iter().all(|&c| c <= 16), "{costs:?}");
}

/// Lights clustered at `2^-k` for many `k`: spatial splits separate one
/// cluster per level, which once left a leaf of most of the lights at the
/// maximum depth. Leaves stay small, and so does the cost of a point.
#[test]
fn exponentially_clustered_lights_leave_small_leaves() {
    let mut lights = Vec::new();
    for k in 0..120 {
        let x = 2f32.powi(-k);
        for j in 0..500 {
            let jitter = Vec3::new(0.0, (j % 25) as f32, (j / 25) as f32);
            lights.push(PointLight::new(Vec3::new(x, 0.0, 10.0) + jitter, Vec3::ONE));
        }
    }
    // Leaves of distinct lights stay within `max_leaf_lights`: the
    // default, 32, and a smaller one.
    for (builder, most) in [
        (LightTree::builder(), 32),
        (LightTree::builder().max_leaf_lights(16), 16),
    ] {
        let tree = builder.build(&lights).unwrap();
        tree.validate().unwrap();
        let largest_leaf = tree
            .nodes()
            .iter()
            .filter(|n| n.children().is_empty() && n.radius() > 0.0)
            .map(|n| n.light_count())
            .max()
            .unwrap();
        assert!(
            largest_leaf <= most,
            "a leaf holds {largest_leaf} distinct lights (at most {most})"
        );
    }
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let p = Vec3::new(0.5, 12.0, -40.0);
    let r = s.shade(p, Vec3::Z, Threshold::relative(0.01)).unwrap();
    assert!(r.certifies(s.exact(p, Vec3::Z).unwrap()));
    assert!(
        r.cost() < 3_000,
        "cost {} for {} lights",
        r.cost(),
        lights.len()
    );
}

/// `count` lights in rows of 20, one unit apart, 3 to 5 units up.
fn rows_of_lights(count: usize) -> Vec<PointLight> {
    (0..count)
        .map(|i| {
            let (x, y) = ((i % 20) as f32, (i / 20) as f32);
            PointLight::new(
                Vec3::new(x, y, 3.0 + (i % 3) as f32),
                Vec3::new(1.0, 0.5, 0.25),
            )
        })
        .collect()
}

/// A small scene is summed light by light rather than cut, where its lights
/// are known visible: the root's bound, then every light, with no error
/// (or, with coarse sums, their rounding's small bound). A
/// threshold the root meets alone still stops there, and with
/// interpolation, a budget below the lights, or coincident lights, the cut
/// bounds nodes as before.
#[test]
fn a_small_scene_is_summed_light_by_light() {
    let lights = rows_of_lights(200);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    // Beside the lights, outside the root's ball, facing them.
    let (p, n) = (Vec3::new(-14.0, 4.5, 0.0), Vec3::X);
    assert!(tree.root().unwrap().cone(p.as_dvec3()).is_some());
    let exact = s.exact(p, n).unwrap();
    for t in [0.01, 0.001, 1e-4] {
        let r = s.shade(p, n, Threshold::relative(t)).unwrap();
        assert_eq!((r.nodes_evaluated, r.lights_evaluated), (1, 200), "{r:?}");
        if t < 1.0 / 4096.0 {
            // Summed in `f64`: no error.
            assert_eq!(r.error_bound, glam::DVec3::ZERO);
        } else {
            // Coarse sums: their rounding only, at most a thirty-second of
            // the target.
            let share = r.radiance * (t / 32.0);
            assert!(r.error_bound.cmple(share).all(), "{r:?}");
        }
        assert!(r.certifies(exact), "{r:?}");
    }
    // Thresholds the root meets alone stop there.
    for t in [Threshold::relative(0.3), Threshold::absolute(f64::INFINITY)] {
        let root = s.shade(p, n, t).unwrap();
        assert_eq!(root.cost(), 1, "{root:?}");
        assert!(root.certifies(exact), "{root:?}");
    }
    let blended = s
        .shade(p, n, Threshold::relative(0.01).with_interpolation(2.0))
        .unwrap();
    assert!(blended.nodes_evaluated > 1, "{blended:?}");
    assert!(blended.certifies(exact), "{blended:?}");
    let budgeted = s
        .shade(p, n, Threshold::relative(0.01).with_budget(150))
        .unwrap();
    assert!(
        budgeted.nodes_evaluated > 1 && budgeted.cost() <= 150,
        "{budgeted:?}"
    );
    assert!(budgeted.certifies(exact), "{budgeted:?}");

    // A stack of coincident lights (one leaf, one light to the cut) makes
    // the scene one the cut handles as before.
    let mut stacked = lights.clone();
    stacked.extend(std::iter::repeat_n(lights[0], 40));
    let tree = LightTree::build(&stacked).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let r = s.shade(p, n, Threshold::relative(0.01)).unwrap();
    assert!(r.nodes_evaluated > 1, "{r:?}");
    assert!(r.certifies(s.exact(p, n).unwrap()), "{r:?}");
}

/// A scene of a few hundred lights (more than 256, at most 512) is summed
/// whole only where its lights are summed coarsely (a relative target of
/// at least `2^-12`), since a coarse sum costs a fraction of an `f64` one;
/// below that target the cut bounds nodes.
#[test]
fn a_few_hundred_lights_are_summed_whole_where_the_sums_are_coarse() {
    let lights = rows_of_lights(400);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let (p, n) = (Vec3::new(-24.0, 9.5, 0.0), Vec3::X);
    assert!(tree.root().unwrap().cone(p.as_dvec3()).is_some());
    let exact = s.exact(p, n).unwrap();
    let coarse = s.shade(p, n, Threshold::relative(0.01)).unwrap();
    assert_eq!(
        (coarse.nodes_evaluated, coarse.lights_evaluated),
        (1, 400),
        "{coarse:?}"
    );
    assert!(coarse.certifies(exact), "{coarse:?}");
    let fine = s.shade(p, n, Threshold::relative(1e-4)).unwrap();
    assert!(fine.nodes_evaluated > 1, "{fine:?}");
    assert!(fine.certifies(exact), "{fine:?}");
}

/// A point on the ground far beyond the edge of the street city of 10^6
/// lamps sees every lamp at a grazing angle, where each node is worth a
/// small fraction of `I kd / D^2`, the scale of the single-precision bounds'
/// rounding (which also grows with the distance): a certified 1% must not
/// drive the cut down to single lights (it once took 60,000 evaluations
/// here). It costs about what the `f64` bounds need (those of a relative
/// target below the single-precision bounds' range, which meets 1% too).
#[test]
fn a_point_far_beyond_the_edge_of_a_city_sees_it_at_a_grazing_angle() {
    let lights = manylights_report::scenes::city_lights(1_000_000, 1998);
    let tree = LightTree::build(&lights).expect("valid lights");
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    for point in [
        Vec3::new(-7_700.0, 60_300.0, 0.0),
        Vec3::new(52_500.0, 37_700.0, 0.0),
        Vec3::new(-2_700.0, 58_400.0, 0.0),
    ] {
        let coarse = shading
            .shade(point, Vec3::Z, Threshold::relative(0.01))
            .expect("valid point");
        // Below 2^-12: bounds in f64 throughout, and still within 1%.
        let fine = shading
            .shade(point, Vec3::Z, Threshold::relative(2e-4))
            .expect("valid point");
        let exact = shading.exact(point, Vec3::Z).expect("valid point");
        assert!(coarse.certifies(exact) && fine.certifies(exact));
        let (cost, f64_cost) = (coarse.cost(), fine.cost());
        assert!(
            cost <= 2 * f64_cost + 1024,
            "at {point}: {cost} evaluations at 1% against {f64_cost} with f64 bounds at 0.02%"
        );
    }
}
