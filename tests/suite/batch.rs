//! Batch shading: every point of a batch keeps the certified contract, for
//! coherent patches and scattered points, both shaders, with and without
//! occluders; points share cuts where they can.

use crate::common::{
    Wall, cases, check_bound, check_threshold, direction, lights, threshold, vec_in,
};
use glam::Vec3;
use manylights::shader::Shader;
use manylights::{
    Combined, Coverage, Ggx, Lambert, LightTree, NodeRegion, Phong, PointLight, Query, ShadeError,
    ShadeResult, Stop, Threshold, Unoccluded, Visibility,
};
use proptest::prelude::*;

/// A coherent patch: `count` points within `radius` of `centre`, spread in
/// the plane across `normal` with a little relief, normals tilted from
/// `normal` by up to `tilt` (radians, roughly).
fn patch() -> impl Strategy<Value = Vec<(Vec3, Vec3)>> {
    (
        vec_in(12.0),
        direction(),
        0.001f32..=3.0,
        0.0f32..=0.6,
        prop::collection::vec(
            (-1.0f32..=1.0, -1.0f32..=1.0, -0.05f32..=0.05, vec_in(1.0)),
            1..=150,
        ),
    )
        .prop_map(|(centre, normal, radius, tilt, offsets)| {
            let n = normal.normalize();
            let (u, v) = n.any_orthonormal_pair();
            offsets
                .into_iter()
                .map(|(a, b, h, wobble)| {
                    let p = centre + (u * a + v * b + n * h) * radius;
                    (p, n + wobble * tilt)
                })
                .collect()
        })
}

/// A coherent patch large enough to make several groups, so that groups
/// blend their neighbours' halos.
fn large_patch() -> impl Strategy<Value = Vec<(Vec3, Vec3)>> {
    (
        vec_in(12.0),
        direction(),
        0.01f32..=6.0,
        0.0f32..=0.6,
        129usize..=600,
        any::<u64>(),
    )
        .prop_map(|(centre, normal, radius, tilt, count, seed)| {
            let n = normal.normalize();
            let (u, v) = n.any_orthonormal_pair();
            let mut state = seed;
            let mut unit = move || {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            };
            (0..count)
                .map(|_| {
                    let (a, b, h) = (unit(), unit(), 0.05 * unit());
                    let wobble = Vec3::new(unit(), unit(), unit());
                    (centre + (u * a + v * b + n * h) * radius, n + wobble * tilt)
                })
                .collect()
        })
}

/// An interpolated threshold, relative or absolute.
fn interpolated() -> impl Strategy<Value = Threshold> {
    prop_oneof![
        (1e-4f64..=0.5, 1.1f64..=8.0)
            .prop_map(|(t, band)| Threshold::relative(t).with_interpolation(band)),
        (-6.0f64..=3.0, 1.1f64..=8.0)
            .prop_map(|(u, band)| Threshold::absolute(10f64.powf(u)).with_interpolation(band)),
    ]
}

/// Points anywhere in the cube of half-size 12, normals anywhere.
fn scattered() -> impl Strategy<Value = Vec<(Vec3, Vec3)>> {
    prop::collection::vec((vec_in(12.0), direction()), 1..=80)
}

/// Queries for `points`, skipping any whose jittered normal came out zero.
fn queries(points: &[(Vec3, Vec3)]) -> Vec<Query> {
    points
        .iter()
        .filter_map(|&(p, n)| Query::new(p, n).ok())
        .collect()
}

/// Every result of a batch against the exact sum of its own query, and the
/// batch's count of its points: each shaded once, through a shared cut or
/// on its own, all on their own under a budget (which cannot share).
fn check_batch<S: Shader + manylights::shader::ViewIndependent + Copy>(
    light_set: &[PointLight],
    shader: S,
    points: &[(Vec3, Vec3)],
    t: Threshold,
) -> Result<(), TestCaseError> {
    let tree = LightTree::build(light_set).unwrap();
    let mut shading = tree.shading(shader);
    let qs = queries(points);
    let mut results = vec![placeholder(); qs.len()];
    let stats = shading
        .shade_batch(&qs, t, Unoccluded, &mut results)
        .unwrap();
    if std::env::var("BATCH_DEBUG").is_ok() {
        eprintln!(
            "STATS {} {} {}",
            stats.shared_points, stats.points_alone, stats.groups
        );
    }
    prop_assert_eq!(
        (stats.shared_points + stats.points_alone) as usize,
        qs.len(),
        "{:?}",
        stats
    );
    prop_assert!(stats.shared_points == 0 || stats.groups > 0, "{:?}", stats);
    if t.budget().is_some() {
        prop_assert_eq!(stats.points_alone as usize, qs.len(), "{:?}", stats);
    }
    for (q, r) in qs.iter().zip(&results) {
        check_bound(r, shading.exact_query(q, Unoccluded))?;
        check_threshold(r, &t)?;
    }
    Ok(())
}

/// A result to be overwritten. The default result's infinite bound would
/// certify any value, so the radiance is NaN: a result left unwritten
/// certifies nothing and fails every check of a finite radiance.
fn placeholder() -> ShadeResult {
    let mut r = ShadeResult::default();
    assert!(r.error_bound.max_element() == f64::INFINITY && r.stop == Stop::Budget);
    r.radiance = glam::DVec3::NAN;
    assert!(!r.certifies(glam::DVec3::ZERO));
    r
}

proptest! {
    #![proptest_config(cases(96))]

    #[test]
    fn coherent_patches_keep_the_contract(
        light_set in lights(2000),
        points in patch(),
        t in threshold(),
        kd in vec_in(1.0).prop_map(|v| v.abs()),
    ) {
        check_batch(&light_set, Lambert::new(kd), &points, t)?;
    }

    #[test]
    fn scattered_points_keep_the_contract(
        light_set in lights(2000),
        points in scattered(),
        t in threshold(),
    ) {
        check_batch(&light_set, Lambert::new(Vec3::new(0.7, 0.5, 0.3)), &points, t)?;
    }

    #[test]
    fn blended_groups_keep_the_contract(
        light_set in lights(2000),
        points in large_patch(),
        t in interpolated(),
    ) {
        check_batch(&light_set, Lambert::new(Vec3::new(0.6, 0.8, 0.4)), &points, t)?;
    }

    /// A sum of two diffuse terms is diffuse, its albedo the sum of theirs
    /// (so the batch may share its cuts), and keeps the contract.
    #[test]
    fn two_diffuse_terms_keep_the_contract(
        light_set in lights(1000),
        points in patch(),
        t in threshold(),
    ) {
        let (a, b) = (Vec3::splat(0.3), Vec3::new(0.1, 0.4, 0.0));
        let shader = Combined::new(Lambert::new(a), Lambert::new(b));
        check_batch(&light_set, shader, &points, t)?;
    }

    #[test]
    fn glossy_batches_keep_the_contract(
        light_set in lights(1000),
        points in patch(),
        views in prop::collection::vec(direction(), 150),
        t in threshold(),
        exponent in 1.0f32..=200.0,
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let shader = Combined::new(Lambert::new(Vec3::splat(0.5)), Phong::new(Vec3::splat(0.5), exponent));
        let mut shading = tree.shading(shader);
        let qs: Vec<_> = queries(&points)
            .into_iter()
            .zip(&views)
            .filter_map(|(q, &v)| q.with_view(v).ok())
            .collect();
        let mut results = vec![placeholder(); qs.len()];
        shading.shade_batch(&qs, t, Unoccluded, &mut results).unwrap();
        for (q, r) in qs.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, Unoccluded))?;
            check_threshold(r, &t)?;
        }
    }

    /// GGX beside Lambert in a batch (each point shaded on its own, the
    /// shader not being diffuse), with and without occluders; roughness
    /// log-uniform over the whole range.
    #[test]
    fn ggx_batches_keep_the_contract(
        light_set in lights(1000),
        points in patch(),
        views in prop::collection::vec(direction(), 150),
        t in threshold(),
        alpha in (-3.0f64..=0.0).prop_map(|u| (10f64.powf(u) as f32).clamp(1e-3, 1.0)),
        f0 in (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0),
        wall in -8.0f32..=8.0,
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let ggx = Ggx::new(Vec3::new(f0.0, f0.1, f0.2), alpha);
        let mut shading = tree.shading(Combined::new(Lambert::new(Vec3::splat(0.5)), ggx));
        let qs: Vec<_> = queries(&points)
            .into_iter()
            .zip(&views)
            .filter_map(|(q, &v)| q.with_view(v).ok())
            .collect();
        let mut results = vec![placeholder(); qs.len()];
        let stats = shading.shade_batch(&qs, t, Unoccluded, &mut results).unwrap();
        prop_assert_eq!(stats.points_alone as usize, qs.len());
        for (q, r) in qs.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, Unoccluded))?;
            check_threshold(r, &t)?;
        }
        let mut host = Wall { x: wall };
        shading.shade_batch(&qs, t, &mut host, &mut results).unwrap();
        for (q, r) in qs.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, &mut host))?;
            check_threshold(r, &t)?;
        }
    }

    #[test]
    fn batches_with_occluders_keep_the_contract(
        light_set in lights(1000),
        points in patch(),
        t in threshold(),
        wall in -8.0f32..=8.0,
    ) {
        let tree = LightTree::build(&light_set).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::ONE));
        let qs = queries(&points);
        let mut results = vec![placeholder(); qs.len()];
        let mut host = Wall { x: wall };
        shading.shade_batch(&qs, t, &mut host, &mut results).unwrap();
        for (q, r) in qs.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, &mut host))?;
            check_threshold(r, &t)?;
        }
        // A host that cannot classify groups: every point on its own.
        let mut alone = PerPoint(Wall { x: wall });
        let stats = shading.shade_batch(&qs, t, &mut alone, &mut results).unwrap();
        prop_assert_eq!(stats.points_alone as usize, qs.len());
        for (q, r) in qs.iter().zip(&results) {
            check_bound(r, shading.exact_query(q, &mut alone))?;
        }
    }
}

/// The wall answering point by point only.
struct PerPoint(Wall);

impl Visibility for PerPoint {
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        self.0.classify(point, node)
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.0.visible(point, light)
    }
}

/// A street of lamps and a patch of road under it, large enough that
/// sharing pays.
fn street_patch() -> (LightTree, Vec<Query>) {
    let lights: Vec<PointLight> = (0..20_000)
        .map(|i| {
            let (x, side) = ((i / 2) as f32 * 3.0, if i % 2 == 0 { -6.0 } else { 6.0 });
            PointLight::new(Vec3::new(x, side, 5.0), Vec3::new(1.0, 0.6, 0.3) * 50.0)
        })
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    let queries = (0..256)
        .map(|k| {
            let (a, b) = ((k % 16) as f32, (k / 16) as f32);
            Query::new(Vec3::new(1000.0 + a * 0.25, -2.0 + b * 0.25, 0.0), Vec3::Z).unwrap()
        })
        .collect();
    (tree, queries)
}

#[test]
fn a_coherent_patch_shares_its_cuts_and_meets_its_threshold() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    let t = Threshold::relative(0.01);
    let mut results = vec![placeholder(); queries.len()];
    let stats = shading
        .shade_batch(&queries, t, Unoccluded, &mut results)
        .unwrap();
    assert!(stats.groups >= 1, "{stats:?}");
    assert!(
        stats.shared_points as usize >= queries.len() * 9 / 10,
        "{stats:?}"
    );
    for (q, r) in queries.iter().zip(&results) {
        let exact = shading.exact_query(q, Unoccluded);
        assert!(r.certifies(exact), "{r:?} against {exact}");
        assert!(r.error_bound.max_element() <= 0.01 * r.radiance.max_element());
    }
    // A point shaded through a shared cut sums fewer node estimates than
    // the whole tree has lights.
    assert!(results.iter().all(|r| (r.cost() as usize) < 20_000));
}

/// Two diffuse terms are one to the batch: their albedos add
/// ([`Shader::diffuse_albedo`]), and the pair shares its cuts over the
/// street's patch point for point as one term of the summed albedo does,
/// each result that term's up to the rounding of summing two terms. The
/// albedos are sums exact in `f32`, so the one term's albedo is the pair's
/// to the bit.
#[test]
fn two_diffuse_terms_share_as_one() {
    let (tree, queries) = street_patch();
    let (a, b) = (Vec3::new(0.5, 0.25, 0.375), Vec3::new(0.25, 0.5, 0.0));
    let mut pair = tree.shading(Combined::new(Lambert::new(a), Lambert::new(b)));
    let mut one = tree.shading(Lambert::new(a + b));
    assert_eq!(
        pair.shader().first.kd() + pair.shader().second.kd(),
        one.shader().kd()
    );
    for t in [
        Threshold::relative(0.01),
        Threshold::relative(0.2),
        Threshold::relative(0.01).with_interpolation(2.0),
    ] {
        let mut results = vec![placeholder(); queries.len()];
        let stats = pair
            .shade_batch(&queries, t, Unoccluded, &mut results)
            .unwrap();
        let mut expected = vec![placeholder(); queries.len()];
        let one_stats = one
            .shade_batch(&queries, t, Unoccluded, &mut expected)
            .unwrap();
        assert!(
            stats.groups > 0 && stats.shared_points > 0,
            "{t:?}: {stats:?}"
        );
        assert_eq!(stats, one_stats, "{t:?}");
        for ((q, r), e) in queries.iter().zip(&results).zip(&expected) {
            let exact = pair.exact_query(q, Unoccluded);
            assert!(r.certifies(exact), "{t:?}: {r:?} against {exact}");
            assert_eq!(r.stop, Stop::ThresholdMet, "{t:?}: {r:?}");
            assert_eq!(
                (r.nodes_evaluated, r.lights_evaluated),
                (e.nodes_evaluated, e.lights_evaluated),
                "{t:?} at {}",
                q.point()
            );
            // Each within the rounding allowance of the same model value.
            let slack = 2.0 * ShadeResult::ROUNDING_ALLOWANCE * exact;
            assert!(
                (r.radiance - e.radiance).abs().cmple(slack).all()
                    && (r.error_bound - e.error_bound).abs().cmple(slack).all(),
                "{t:?}: {r:?} against one term's {e:?}"
            );
        }
    }
}

#[test]
fn settings_that_cannot_share_give_the_single_point_results() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    let t = Threshold::relative(0.01).with_budget(300);
    let mut results = vec![placeholder(); queries.len()];
    let stats = shading
        .shade_batch(&queries, t, Unoccluded, &mut results)
        .unwrap();
    assert_eq!(stats.points_alone as usize, queries.len());
    for (q, r) in queries.iter().zip(&results) {
        assert_eq!(*r, shading.shade_query(q, t, Unoccluded).unwrap());
    }
}

#[test]
fn a_results_slice_of_the_wrong_length_is_an_error() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut results = vec![placeholder(); 3];
    let e = shading.shade_batch(
        &queries,
        Threshold::relative(0.01),
        Unoccluded,
        &mut results,
    );
    assert_eq!(
        e,
        Err(ShadeError::BatchLength {
            queries: 256,
            results: 3
        })
    );
    let e = shading.shade_batch(
        &queries[..3],
        Threshold::relative(f64::NAN),
        Unoccluded,
        &mut results,
    );
    assert!(matches!(e, Err(ShadeError::InvalidThreshold(_))));
    // An empty batch is fine.
    let stats = shading
        .shade_batch::<_, _>(
            &queries[..0],
            Threshold::relative(0.01),
            Unoccluded,
            &mut [],
        )
        .unwrap();
    assert_eq!(stats.shared_points + stats.points_alone, 0);
}

#[cfg(feature = "rayon")]
#[test]
fn the_parallel_batch_gives_the_same_bits() {
    let (tree, mut queries) = street_patch();
    // Scattered points too, so that some groups do not pay and are shaded
    // point by point.
    queries.extend((0..64).map(|k| {
        let x = (k * 977 % 30_000) as f32;
        Query::new(
            Vec3::new(x, (k % 7) as f32 - 3.0, 0.5),
            Vec3::new(0.1, 0.0, 1.0),
        )
        .unwrap()
    }));
    let mut shading = tree.shading(Lambert::new(Vec3::new(0.8, 0.6, 0.4)));
    for t in [
        Threshold::relative(0.01),
        Threshold::absolute(1e-3),
        Threshold::relative(0.05).with_budget(200),
        Threshold::relative(0.01).with_interpolation(2.0),
    ] {
        let mut serial = vec![placeholder(); queries.len()];
        let mut parallel = vec![placeholder(); queries.len()];
        let a = shading
            .shade_batch(&queries, t, Unoccluded, &mut serial)
            .unwrap();
        let b = shading
            .shade_batch_parallel(&queries, t, Unoccluded, &mut parallel)
            .unwrap();
        assert_eq!(a, b);
        assert_eq!(serial, parallel);
    }
}

#[cfg(feature = "rayon")]
#[test]
fn the_parallel_batch_takes_empty_and_tiny_batches_and_checks_lengths() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    let t = Threshold::relative(0.01);
    let none: [Query; 0] = [];
    let stats = shading
        .shade_batch_parallel(&none, t, Unoccluded, &mut [])
        .unwrap();
    assert_eq!(stats, manylights::BatchStats::default());
    for n in [1, 2, 5, 200] {
        let mut serial = vec![placeholder(); n];
        let mut parallel = vec![placeholder(); n];
        let a = shading
            .shade_batch(&queries[..n], t, Unoccluded, &mut serial)
            .unwrap();
        let b = shading
            .shade_batch_parallel(&queries[..n], t, Unoccluded, &mut parallel)
            .unwrap();
        assert_eq!((a, &serial), (b, &parallel), "{n} points");
        assert!(parallel.iter().all(|r| r.stop == Stop::ThresholdMet));
    }
    let mut short = vec![placeholder(); 1];
    let error = shading.shade_batch_parallel(&queries[..2], t, Unoccluded, &mut short);
    assert!(
        matches!(error, Err(manylights::ShadeError::BatchLength { .. })),
        "{error:?}"
    );
}

#[test]
fn a_wall_across_the_street_is_asked_once_per_group() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    let t = Threshold::relative(0.01);
    // The wall hides the half of the street beyond x = 1010 from the patch.
    let mut host = Wall { x: 1010.0 };
    let mut results = vec![placeholder(); queries.len()];
    let stats = shading
        .shade_batch(&queries, t, &mut host, &mut results)
        .unwrap();
    assert!(
        stats.shared_points as usize >= queries.len() * 9 / 10,
        "{stats:?}"
    );
    assert!(stats.shared_classifications > 0, "{stats:?}");
    let mut unshadowed = vec![placeholder(); queries.len()];
    shading
        .shade_batch(&queries, t, Unoccluded, &mut unshadowed)
        .unwrap();
    for ((q, r), free) in queries.iter().zip(&results).zip(&unshadowed) {
        let exact = shading.exact_query(q, &mut host);
        assert!(r.certifies(exact), "{r:?} against {exact}");
        assert!(r.error_bound.max_element() <= 0.01 * r.radiance.max_element());
        // The wall takes away the lamps beyond it.
        assert!(r.radiance.max_element() < free.radiance.max_element());
    }
}

#[test]
fn interpolation_is_shared_too() {
    let (tree, queries) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    let t = Threshold::relative(0.01).with_interpolation(2.0);
    let mut results = vec![placeholder(); queries.len()];
    let stats = shading
        .shade_batch(&queries, t, Unoccluded, &mut results)
        .unwrap();
    assert!(
        stats.shared_points as usize >= queries.len() * 9 / 10,
        "{stats:?}"
    );
    let mut plain = vec![placeholder(); queries.len()];
    shading
        .shade_batch(&queries, Threshold::relative(0.01), Unoccluded, &mut plain)
        .unwrap();
    let mut moved = 0;
    for ((q, r), p) in queries.iter().zip(&results).zip(&plain) {
        let exact = shading.exact_query(q, Unoccluded);
        assert!(r.certifies(exact), "{r:?} against {exact}");
        assert!(r.error_bound.max_element() <= 0.01 * r.radiance.max_element());
        moved += usize::from(r.radiance != p.radiance);
    }
    // The blend changed the estimates (it refines the last nodes partly).
    assert!(moved > queries.len() / 2, "{moved}");
}

/// The relative error of each result against the exact sum of its query
/// (largest channel).
fn relative_errors(
    shading: &mut manylights::Shading<'_, Lambert>,
    queries: &[Query],
    results: &[ShadeResult],
) -> Vec<f64> {
    queries
        .iter()
        .zip(results)
        .map(|(q, r)| {
            let exact = shading.exact_query(q, Unoccluded);
            ((r.radiance - exact) / exact).max_element()
        })
        .collect()
}

#[test]
fn blended_groups_leave_no_seams_at_their_borders() {
    let (tree, _) = street_patch();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
    // A line of points along the street, crossing the borders of several
    // groups of at most 128 points.
    let queries: Vec<Query> = (0..1024)
        .map(|k| Query::new(Vec3::new(1000.0 + k as f32 * 0.05, 1.0, 0.0), Vec3::Z).unwrap())
        .collect();
    let jumps = |shading: &mut manylights::Shading<'_, Lambert>, t: Threshold| {
        let mut results = vec![placeholder(); queries.len()];
        let stats = shading
            .shade_batch(&queries, t, Unoccluded, &mut results)
            .unwrap();
        assert!(stats.groups >= 8, "{stats:?}");
        let errors = relative_errors(shading, &queries, &results);
        errors
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0f64, f64::max)
    };
    let plain = jumps(&mut shading, Threshold::relative(0.01));
    let blended = jumps(
        &mut shading,
        Threshold::relative(0.01).with_interpolation(2.0),
    );
    // Without interpolation two groups' cuts differ as wholes and the error
    // jumps at their border; with it each group's cut also serves its
    // neighbours' points near the border, blended in by distance.
    assert!(plain > 5e-5, "{plain}");
    assert!(
        blended < plain / 4.0 && blended < 5e-5,
        "{blended} against {plain}"
    );
}
