//! Hostile scenes that once made the cut's cost explode, each a test on
//! evaluation counts (never on times).

use glam::Vec3;
use manylights::{Lambert, LightTree, PointLight, Threshold};
use manylights_report::scenes;

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

/// Where the bounds settle nothing early, a point's cut stops bounding once
/// its work (a node bound counted as 16 lights) reaches half the scene's
/// lights, and sums what is left: every light evaluated at most once and
/// at most `N / 32 + 8` nodes bounded, against about `N / 14` for a walk
/// to the leaves.
fn at_most_a_walk_to_the_leaves(r: &manylights::ShadeResult, lights: usize) -> bool {
    r.lights_evaluated as usize <= lights && r.nodes_evaluated as usize <= lights / 32 + 8
}

/// Deterministic uniform numbers in `[0, 1)` (a 64-bit LCG's high bits).
fn uniforms(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Lights exactly in the plane `x + y + z = 0`, a point in the plane
/// among them, and a normal slightly off the plane's, as smooth shading
/// gives on a roof (`manylights_report::scenes::tilted_plane`): every node
/// at every level straddles the tangent plane. With the normal exactly the
/// plane's, every light lies in the tangent plane and the whole scene is
/// exactly 0.
#[test]
fn a_normal_slightly_off_a_plane_of_lights_costs_at_most_a_walk_to_the_leaves() {
    const LIGHTS: usize = 100_000;
    let lights = scenes::tilted_plane(LIGHTS, 57);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let p = scenes::TILTED_POINT;
    for e in [1e-7f32, 1e-5, 1e-3] {
        let normal = scenes::tilted_normal(e);
        let exact = s.exact(p, normal).unwrap();
        let r = s.shade(p, normal, Threshold::relative(0.01)).unwrap();
        assert!(r.certifies(exact), "e = {e}: {r:?}");
        assert!(
            r.error_bound.cmple(exact * 0.01).all(),
            "e = {e}: {r:?} against {exact}"
        );
        assert!(
            at_most_a_walk_to_the_leaves(&r, LIGHTS),
            "e = {e}: {} evaluations for {LIGHTS} lights",
            r.cost()
        );
        // Under a budget (here one that never binds) the cut never stops
        // bounding to sum the rest: it walks to the leaves, bounding more.
        let walk = s
            .shade(
                p,
                normal,
                Threshold::relative(0.01).with_budget(u32::MAX - 1),
            )
            .unwrap();
        assert!(walk.certifies(exact), "e = {e}: {walk:?}");
        assert!(
            r.nodes_evaluated + r.nodes_evaluated / 8 < walk.nodes_evaluated,
            "e = {e}: {r:?} against the walk {walk:?}"
        );
    }
    let flat = Vec3::ONE.normalize();
    let r = s.shade(p, flat, Threshold::relative(0.01)).unwrap();
    assert_eq!(r.radiance, glam::DVec3::ZERO, "{r:?}");
    assert!(r.cost() <= 1, "{r:?}");
}

/// Lights at distances `2^-k` from a point in random directions, the point
/// at the cluster's centre (`manylights_report::scenes::geometric_cluster`):
/// every node's ball holds the point or nearly, at every scale.
#[test]
fn a_point_at_the_centre_of_a_geometric_cluster_costs_at_most_a_walk_to_the_leaves() {
    const LIGHTS: usize = 100_000;
    let centre = scenes::CLUSTER_CENTRE;
    let lights = scenes::geometric_cluster(LIGHTS, 1998);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    for t in [0.01, 0.1] {
        for normal in [Vec3::Z, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            let exact = s.exact(centre, normal).unwrap();
            let r = s.shade(centre, normal, Threshold::relative(t)).unwrap();
            assert!(r.certifies(exact), "{r:?}");
            assert!(
                at_most_a_walk_to_the_leaves(&r, LIGHTS),
                "at {t}: {} evaluations for {LIGHTS} lights",
                r.cost()
            );
        }
    }
}

/// Lights along a logarithmic spiral in a plane, shaded at its pole
/// (`manylights_report::scenes::log_spiral`): the lights' distances span
/// many decades, and nodes near the pole hold it.
#[test]
fn a_point_at_the_pole_of_a_logarithmic_spiral_costs_at_most_a_walk_to_the_leaves() {
    const LIGHTS: usize = 100_000;
    let lights = scenes::log_spiral(LIGHTS);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    for normal in [Vec3::Z, Vec3::new(0.2, 0.1, 1.0).normalize()] {
        let exact = s.exact(Vec3::ZERO, normal).unwrap();
        let r = s
            .shade(Vec3::ZERO, normal, Threshold::relative(0.01))
            .unwrap();
        assert!(r.certifies(exact), "{r:?}");
        assert!(
            at_most_a_walk_to_the_leaves(&r, LIGHTS),
            "{} evaluations for {LIGHTS} lights",
            r.cost()
        );
    }
}

/// Lights within `1e-6` of the ground, points on the ground
/// (`manylights_report::scenes::thin_layer`): every shared node straddles
/// every point's tangent plane. The batch call costs about what its points
/// cost shaded one by one: a group whose shared cut does not pay is shaded
/// point by point.
#[test]
fn a_batch_among_lights_in_its_tangent_plane_costs_about_its_points_alone() {
    const LIGHTS: usize = 100_000;
    let lights = scenes::thin_layer(LIGHTS, 7);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let queries: Vec<_> = scenes::thin_layer_points(16)
        .into_iter()
        .map(|p| manylights::Query::new(p, Vec3::Z).unwrap())
        .collect();
    let threshold = Threshold::relative(0.01);
    let mut results = vec![manylights::ShadeResult::default(); queries.len()];
    let stats = s
        .shade_batch(&queries, threshold, manylights::Unoccluded, &mut results)
        .unwrap();
    let batch: u64 =
        results.iter().map(|r| u64::from(r.cost())).sum::<u64>() + stats.shared_evaluations;
    let mut alone = 0u64;
    for (q, r) in queries.iter().zip(&results) {
        let exact = s.exact_query(q, manylights::Unoccluded);
        assert!(r.certifies(exact), "{r:?}");
        let own = s.shade_query(q, threshold, manylights::Unoccluded).unwrap();
        assert!(own.certifies(exact), "{own:?}");
        assert!(at_most_a_walk_to_the_leaves(&own, LIGHTS), "{own:?}");
        alone += u64::from(own.cost());
    }
    assert!(
        batch <= alone + alone / 4 + 4096,
        "the batch took {batch} evaluations, its points alone {alone} ({stats:?})"
    );
}

/// Roofs among street lamps at their height (the street city of 10^5
/// lights, points 5.5 to 6.5 units up, normal up): the tangent plane runs
/// through the layer of lamps. With the nodes' slab moments (the default)
/// such a point costs within a few times a ground point's evaluations;
/// without them, many times more.
#[test]
fn roofs_inside_a_layer_of_lamps_cost_about_what_the_ground_costs() {
    let lights = manylights_report::scenes::city_lights(100_000, 1998);
    let tree = LightTree::build(&lights).expect("valid lights");
    let plain = manylights::TreeBuilder::new()
        .slab_moments(false)
        .build(&lights)
        .expect("valid lights");
    assert!(tree.memory_bytes() > plain.memory_bytes());
    let mut u = uniforms(6);
    let (mut ground, mut roofs, mut roofs_plain) = (0u64, 0u64, 0u64);
    let target = Threshold::relative(0.01);
    for _ in 0..24 {
        let (x, y) = (50.0 + 1_100.0 * u(), 50.0 + 1_100.0 * u());
        let z = 5.5 + u();
        let mut s = tree.shading(Lambert::new(Vec3::ONE));
        let on_ground = s.shade(Vec3::new(x, y, 0.0), Vec3::Z, target).unwrap();
        let roof = Vec3::new(x, y, z);
        let r = s.shade(roof, Vec3::Z, target).unwrap();
        let exact = s.exact(roof, Vec3::Z).unwrap();
        assert!(r.certifies(exact), "{roof}: {r:?} against {exact}");
        let mut p = plain.shading(Lambert::new(Vec3::ONE));
        let q = p.shade(roof, Vec3::Z, target).unwrap();
        assert!(q.certifies(exact));
        ground += u64::from(on_ground.cost());
        roofs += u64::from(r.cost());
        roofs_plain += u64::from(q.cost());
    }
    assert!(
        roofs <= 4 * ground,
        "roofs {roofs} evaluations against {ground} on the ground"
    );
    assert!(
        4 * roofs <= roofs_plain,
        "roofs {roofs} evaluations against {roofs_plain} without slab moments"
    );
}
