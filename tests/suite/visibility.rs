//! Visibility (Warnock-style occlusion) against the exact shadowed sum.
//!
//! The host here is a set of axis-aligned box occluders with a conservative
//! classifier ([`Occluders`]): `Visible` when no occluder meets the bounding
//! box of the shaft from the shading point to the node's box, `Occluded` when
//! one occluder provably blocks every segment of the shaft, `Partial`
//! otherwise; point-to-point visibility is an exact segment-versus-box slab
//! test. The certified-bound contract must hold against the exact shadowed
//! sum (`Shading::exact_query` with the same host, with and without a view)
//! for every threshold, an unoccluded host must cost nothing, occluded nodes
//! must contribute exactly zero, threshold 0 must give the shadowed sum, and
//! a host's visible fraction may move the estimate but never break the
//! bound.

use crate::common::{cases, check_bound, check_threshold, direction, lights, threshold, vec_in};
use glam::{DVec3, Vec3};
use manylights::{
    Aabb, Coverage, Ggx, Lambert, LightTree, NodeRegion, Phong, PointLight, Query, ShadeResult,
    Stop, Threshold, Unoccluded, Visibility,
};
use manylights_report::bvh::corners;
use proptest::prelude::*;

/// Safety margin of the classifier, in scene units. `visible` runs its slab
/// test in `f64` on `f32` coordinates of magnitude below 100, so its
/// intersection parameters err by far less than `1e-12` relative; the
/// classifier inflates occluders by this margin before declaring a shaft
/// `Visible` and shrinks them by it before declaring one `Occluded`, so that
/// no rounding in either test can make a conservative answer wrong.
const MARGIN: f64 = 1e-6;

/// Phong exponents of the property tests: a broad lobe, a glossy one and a
/// near-mirror.
const EXPONENTS: [f32; 3] = [1.0, 50.0, 1e4];

/// What [`Occluders::visible_fraction`] answers for a partially occluded
/// node.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fraction {
    /// `None`: the crate uses the middle of the certified interval.
    Default,
    /// The share of unblocked segments from the point to the node's eight
    /// corners and its centroid: a cheap estimate, as a ray tracer would
    /// make.
    Sampled,
    /// A fixed value in `[0, 1]`.
    Constant(f32),
}

/// Axis-aligned box occluders: a conservative host of the [`Visibility`]
/// contract, with counters of what it was asked.
#[derive(Clone, Debug)]
struct Occluders {
    boxes: Vec<Aabb>,
    fraction: Fraction,
    /// Answers given, in the order visible, occluded, partial.
    answers: [u32; 3],
    /// Light positions asked point-to-point.
    asked: Vec<Vec3>,
}

impl Occluders {
    fn new(boxes: Vec<Aabb>) -> Self {
        Self::with_fraction(boxes, Fraction::Default)
    }

    fn with_fraction(boxes: Vec<Aabb>, fraction: Fraction) -> Self {
        Self {
            boxes,
            fraction,
            answers: [0; 3],
            asked: Vec::new(),
        }
    }

    fn classified(&self) -> u32 {
        self.answers.iter().sum()
    }

    /// Whether some occluder blocks the closed segment `[a, b]`.
    fn blocked(&self, a: Vec3, b: Vec3) -> bool {
        let (a, b) = (a.as_dvec3(), b.as_dvec3());
        self.boxes
            .iter()
            .any(|o| segment_hits(a, b, o.min.as_dvec3(), o.max.as_dvec3()))
    }
}

/// Whether the closed segment `[a, b]` meets the closed box `[lo, hi]`
/// (slab test; a zero direction component is handled apart, so no `0 * inf`
/// arises).
fn segment_hits(a: DVec3, b: DVec3, lo: DVec3, hi: DVec3) -> bool {
    let d = b - a;
    let (mut enter, mut exit) = (0.0f64, 1.0f64);
    for k in 0..3 {
        if d[k] == 0.0 {
            if a[k] < lo[k] || a[k] > hi[k] {
                return false;
            }
            continue;
        }
        let (t0, t1) = ((lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]);
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
        if enter > exit {
            return false;
        }
    }
    true
}

impl Visibility for Occluders {
    /// * `Visible` when no occluder, inflated by [`MARGIN`], meets the box
    ///   spanning the point and the node's box: that box holds the shaft
    ///   (the convex hull of the point and the node's box), so no segment
    ///   from the point to the node can meet an occluder.
    /// * `Occluded` when the segments from the point to all eight corners of
    ///   the node's box meet one and the same occluder shrunk by [`MARGIN`].
    ///   This covers the whole box: for a convex occluder `B` and apex `p`,
    ///   the set `S = {q : [p, q] meets B} = {p + s (b - p) : b in B,
    ///   s >= 1}` is convex (for `q_j = p + s_j (b_j - p)` and weights
    ///   `l, 1 - l`, the combination is `p + m (b' - p)` with
    ///   `m = l s_1 + (1 - l) s_2 >= 1` and `b' = (l s_1 b_1 + (1 - l) s_2
    ///   b_2) / m` in `B`), so it holds the convex hull of the corners, the
    ///   node's box. Each blocked segment passes at least [`MARGIN`] deep
    ///   inside the unshrunk occluder, so `visible` says blocked too.
    /// * `Partial` otherwise.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let (p, lo, hi) = (
            point.as_dvec3(),
            node.aabb.min.as_dvec3(),
            node.aabb.max.as_dvec3(),
        );
        let (shaft_lo, shaft_hi) = (lo.min(p), hi.max(p));
        let misses_shaft = |o: &Aabb| {
            let (o_lo, o_hi) = (o.min.as_dvec3() - MARGIN, o.max.as_dvec3() + MARGIN);
            o_lo.cmpgt(shaft_hi).any() || o_hi.cmplt(shaft_lo).any()
        };
        let coverage = if self.boxes.iter().all(misses_shaft) {
            Coverage::Visible
        } else if self.boxes.iter().any(|o| {
            let (o_lo, o_hi) = (o.min.as_dvec3() + MARGIN, o.max.as_dvec3() - MARGIN);
            o_lo.cmple(o_hi).all()
                && corners(&node.aabb)
                    .iter()
                    .all(|c| segment_hits(p, c.as_dvec3(), o_lo, o_hi))
        }) {
            Coverage::Occluded
        } else {
            Coverage::Partial
        };
        self.answers[match coverage {
            Coverage::Visible => 0,
            Coverage::Occluded => 1,
            Coverage::Partial => 2,
        }] += 1;
        coverage
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.asked.push(light);
        !self.blocked(point, light)
    }

    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        match self.fraction {
            Fraction::Default => None,
            Fraction::Constant(f) => Some(f),
            Fraction::Sampled => {
                let samples = corners(&node.aabb).into_iter().chain([node.centroid]);
                let seen = samples.filter(|&q| !self.blocked(point, q)).count();
                Some(seen as f32 / 9.0)
            }
        }
    }
}

/// A host that knows nothing: every node is `Partial`, so every light the
/// cut reaches is asked point-to-point.
struct Unsure(Occluders);

impl Visibility for Unsure {
    fn classify(&mut self, _point: Vec3, _node: &NodeRegion) -> Coverage {
        Coverage::Partial
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.0.visible(point, light)
    }
}

fn aabb(min: [f32; 3], max: [f32; 3]) -> Aabb {
    Aabb {
        min: Vec3::from(min),
        max: Vec3::from(max),
    }
}

/// Everything a shadowed result must satisfy: the certified bound, the
/// threshold, the query counters, and exactness at threshold 0.
fn check_occluded(
    r: &ShadeResult,
    exact: DVec3,
    t: &Threshold,
    host: &Occluders,
) -> Result<(), TestCaseError> {
    check_bound(r, exact)?;
    check_threshold(r, t)?;
    check_counters(r, host)?;
    if *t == Threshold::zero() {
        check_exact(r, exact)?;
    }
    Ok(())
}

/// The result's query counters agree with what the host was asked.
fn check_counters(r: &ShadeResult, host: &Occluders) -> Result<(), TestCaseError> {
    prop_assert_eq!(r.classify_queries, host.classified());
    prop_assert_eq!(r.point_queries as usize, host.asked.len());
    Ok(())
}

/// Threshold 0 gives the shadowed sum up to the rounding allowance.
fn check_exact(r: &ShadeResult, exact: DVec3) -> Result<(), TestCaseError> {
    prop_assert_eq!(r.stop, Stop::ThresholdMet);
    for k in 0..3 {
        prop_assert!(
            (r.radiance[k] - exact[k]).abs() <= ShadeResult::ROUNDING_ALLOWANCE * exact[k],
            "threshold 0 with occluders is not the shadowed sum: {} vs {}",
            r.radiance,
            exact
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// A street scene: deterministic checks
// ---------------------------------------------------------------------------

/// Street lamps in two rows along `x` at height 6 (with a slight colour
/// ramp), and walls: a long one between the rows, and a few blocks.
fn street() -> (Vec<PointLight>, Vec<Aabb>) {
    let mut lights = Vec::new();
    for i in 0..400 {
        let x = -100.0 + 0.5 * i as f32;
        let tint = i as f32 / 400.0;
        for y in [-6.0, 6.0] {
            let colour = Vec3::new(1.0, 0.6 + 0.3 * tint, 0.3 + 0.2 * (1.0 - tint));
            lights.push(PointLight::new(Vec3::new(x, y, 6.0), colour * 20.0));
        }
    }
    let walls = vec![
        aabb([-60.0, -1.0, 0.0], [60.0, 1.0, 10.0]),
        aabb([-20.0, 8.0, 0.0], [-10.0, 20.0, 30.0]),
        aabb([10.0, -20.0, 0.0], [30.0, -9.0, 15.0]),
        aabb([-90.0, -4.0, 0.0], [-80.0, -3.0, 4.0]),
    ];
    (lights, walls)
}

/// Shading points on the street (normal up) and on the walls' faces
/// (normal out of the face), nudged off the surface so that the point is
/// not inside its own occluder.
fn street_points() -> Vec<(Vec3, Vec3)> {
    const NUDGE: f32 = 1e-3;
    let mut points = Vec::new();
    for i in 0..24 {
        let x = -110.0 + 9.5 * i as f32;
        for y in [-12.0, -4.0, -1.5, 0.0, 3.0, 9.0] {
            points.push((Vec3::new(x, y, 0.0), Vec3::Z));
        }
        points.push((Vec3::new(x.clamp(-60.0, 60.0), -1.0 - NUDGE, 5.0), -Vec3::Y));
        points.push((Vec3::new(x.clamp(-60.0, 60.0), 1.0 + NUDGE, 2.0), Vec3::Y));
    }
    points
}

/// Thresholds of every kind for the deterministic checks.
fn street_thresholds() -> [Threshold; 6] {
    [
        Threshold::relative(0.01),
        Threshold::relative(0.2),
        Threshold::relative(0.05).with_interpolation(3.0),
        Threshold::absolute(1e-3),
        Threshold::absolute(f64::INFINITY),
        Threshold::relative(0.01).with_budget(64),
    ]
}

#[test]
fn lambert_bound_holds_in_the_street() -> Result<(), TestCaseError> {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::new(0.8, 0.7, 0.6)));
    let mut answers = [0; 3];
    for (p, n) in street_points() {
        let exact = shading.exact_query(
            &Query::new(p, n).unwrap(),
            &mut Occluders::new(walls.clone()),
        );
        for t in street_thresholds() {
            let mut host = Occluders::new(walls.clone());
            let r = shading
                .shade_query(&Query::new(p, n).unwrap(), t, &mut host)
                .unwrap();
            check_bound(&r, exact)?;
            check_threshold(&r, &t)?;
            check_counters(&r, &host)?;
            for (total, answered) in answers.iter_mut().zip(host.answers) {
                *total += answered;
            }
        }
    }
    // The scene exercises every answer.
    assert!(answers.iter().all(|&a| a > 0), "answers {answers:?}");
    Ok(())
}

#[test]
fn phong_bound_holds_in_the_street() -> Result<(), TestCaseError> {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let eye = Vec3::new(-30.0, -40.0, 25.0);
    for exponent in EXPONENTS {
        let mut shading = tree.shading(Phong::new(Vec3::splat(0.5), exponent));
        for (p, n) in street_points() {
            let v = eye - p;
            let exact = shading.exact_query(
                &Query::new(p, n).unwrap().with_view(v).unwrap(),
                &mut Occluders::new(walls.clone()),
            );
            for t in street_thresholds() {
                let mut host = Occluders::new(walls.clone());
                let r = shading
                    .shade_query(
                        &Query::new(p, n).unwrap().with_view(v).unwrap(),
                        t,
                        &mut host,
                    )
                    .unwrap();
                check_bound(&r, exact)?;
                check_threshold(&r, &t)?;
                check_counters(&r, &host)?;
            }
        }
    }
    Ok(())
}

#[test]
fn ggx_bound_holds_in_the_street() -> Result<(), TestCaseError> {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let eye = Vec3::new(-30.0, -40.0, 25.0);
    for alpha in [1e-3, 0.05, 0.3, 1.0] {
        let shader = manylights::Combined::new(
            Lambert::new(Vec3::splat(0.3)),
            Ggx::new(Vec3::new(0.9, 0.7, 0.2), alpha),
        );
        let mut shading = tree.shading(shader);
        for (p, n) in street_points() {
            let q = Query::new(p, n).unwrap().with_view(eye - p).unwrap();
            let exact = shading.exact_query(&q, &mut Occluders::new(walls.clone()));
            for t in street_thresholds() {
                let mut host = Occluders::new(walls.clone());
                let r = shading.shade_query(&q, t, &mut host).unwrap();
                check_bound(&r, exact)?;
                check_threshold(&r, &t)?;
                check_counters(&r, &host)?;
            }
        }
    }
    Ok(())
}

#[test]
fn occlusion_changes_the_street() {
    // Guard against a vacuous scene: the walls really do cast shadows.
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let shading = tree.shading(Lambert::new(Vec3::ONE));
    let shadowed = street_points().into_iter().filter(|&(p, n)| {
        let open = shading.exact(p, n).unwrap();
        let shut = shading.exact_query(
            &Query::new(p, n).unwrap(),
            &mut Occluders::new(walls.clone()),
        );
        shut.max_element() < 0.9 * open.max_element()
    });
    assert!(shadowed.count() >= 20);
}

/// A host that answers lights asked about together on its own (last
/// first), counting them: the cut must come out as with the default, which
/// asks [`Visibility::visible`] one light at a time.
struct Batching {
    host: Occluders,
    /// Lights asked about together, and the calls that asked them.
    batched: (u32, u32),
}

impl Visibility for Batching {
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        self.host.classify(point, node)
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.host.visible(point, light)
    }

    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        for (&light, seen) in lights.iter().zip(seen.iter_mut()).rev() {
            *seen = !self.host.blocked(point, light);
        }
        self.batched.0 += lights.len() as u32;
        self.batched.1 += 1;
    }
}

#[test]
fn lights_asked_together_shade_as_one_at_a_time() {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));
    let mut calls = 0;
    for (p, n) in street_points() {
        let query = Query::new(p, n).unwrap();
        for t in street_thresholds() {
            let mut alone = Occluders::new(walls.clone());
            let one_by_one = shading.shade_query(&query, t, &mut alone).unwrap();
            let mut together = Batching {
                host: Occluders::new(walls.clone()),
                batched: (0, 0),
            };
            let batched = shading.shade_query(&query, t, &mut together).unwrap();
            assert_eq!(one_by_one, batched, "at {p} with {t:?}");
            // Every light asked is counted once, whichever way it was asked.
            assert_eq!(
                batched.point_queries,
                together.batched.0 + together.host.asked.len() as u32
            );
            calls += together.batched.1;
        }
    }
    assert!(calls > 0, "no lights were asked about together");
}

// ---------------------------------------------------------------------------
// Unoccluded: free
// ---------------------------------------------------------------------------

#[test]
fn unoccluded_is_shade_bit_for_bit() {
    let (lights, _) = street();
    let tree = LightTree::build(&lights).unwrap();
    let mut lambert = tree.shading(Lambert::new(Vec3::splat(0.7)));
    let mut phong = tree.shading(Phong::new(Vec3::splat(0.5), 50.0));
    let v = Vec3::new(0.3, -1.0, 0.8);
    for (p, n) in street_points() {
        for t in street_thresholds() {
            let plain = lambert.shade(p, n, t).unwrap();
            let occluded = lambert
                .shade_query(&Query::new(p, n).unwrap(), t, &mut Unoccluded)
                .unwrap();
            assert_eq!(plain, occluded);
            assert_eq!((occluded.classify_queries, occluded.point_queries), (0, 0));

            let plain = phong
                .shade_query(
                    &Query::new(p, n).unwrap().with_view(v).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap();
            let occluded = phong
                .shade_query(
                    &Query::new(p, n).unwrap().with_view(v).unwrap(),
                    t,
                    &mut Unoccluded,
                )
                .unwrap();
            assert_eq!(plain, occluded);
            assert_eq!((occluded.classify_queries, occluded.point_queries), (0, 0));
        }
        assert_eq!(
            lambert.exact(p, n).unwrap(),
            lambert.exact_query(&Query::new(p, n).unwrap(), &mut Unoccluded)
        );
    }
}

// ---------------------------------------------------------------------------
// Fully occluded nodes
// ---------------------------------------------------------------------------

#[test]
fn fully_occluded_tree_is_zero_with_zero_error() {
    // Every light above a ceiling that covers the whole shaft.
    let lights: Vec<PointLight> = (0..1000)
        .map(|i| {
            let (x, y) = ((i % 40) as f32 - 20.0, (i / 40) as f32 - 12.0);
            PointLight::new(Vec3::new(x, y, 8.0), Vec3::new(1.0, 0.5, 0.25))
        })
        .collect();
    let ceiling = vec![aabb([-50.0, -50.0, 3.0], [50.0, 50.0, 4.0])];
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    for t in street_thresholds().into_iter().chain([Threshold::zero()]) {
        let mut host = Occluders::new(ceiling.clone());
        let r = shading
            .shade_query(
                &Query::new(Vec3::new(1.5, -2.0, 0.0), Vec3::Z).unwrap(),
                t,
                &mut host,
            )
            .unwrap();
        assert_eq!(r.radiance, DVec3::ZERO);
        assert_eq!(r.error_bound, DVec3::ZERO);
        // The root is bounded, then asked about once when the cut takes it
        // (an infinite threshold takes nothing and asks nothing).
        if r.classify_queries > 0 {
            assert_eq!((r.nodes_evaluated, r.lights_evaluated), (1, 0));
            assert_eq!((r.classify_queries, r.point_queries), (1, 0));
            assert_eq!(host.answers, [0, 1, 0]);
        }
    }
}

#[test]
fn occluded_cluster_is_dropped_without_point_queries() {
    // Two clusters of lights; a wall hides the left one from the point.
    let cluster = |cx: f32| {
        (0..300).map(move |i| {
            let (dx, dy, dz) = ((i % 10) as f32, ((i / 10) % 10) as f32, (i / 100) as f32);
            let p = Vec3::new(cx + 0.3 * dx, -1.5 + 0.3 * dy, 5.0 + 0.3 * dz);
            PointLight::new(p, Vec3::new(1.0, 0.8, 0.6))
        })
    };
    let lights: Vec<PointLight> = cluster(-20.0).chain(cluster(20.0)).collect();
    let wall = vec![aabb([-8.0, -10.0, 0.0], [-7.0, 10.0, 20.0])];
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let (p, n) = (Vec3::new(0.0, 0.0, 0.0), Vec3::Z);
    let exact = shading.exact_query(
        &Query::new(p, n).unwrap(),
        &mut Occluders::new(wall.clone()),
    );
    let open = shading.exact(p, n).unwrap();
    assert!(
        exact.max_element() < 0.6 * open.max_element(),
        "the wall casts no shadow"
    );

    let mut host = Occluders::new(wall);
    let r = shading
        .shade_query(&Query::new(p, n).unwrap(), Threshold::zero(), &mut host)
        .unwrap();
    check_exact(&r, exact).unwrap();
    assert!(host.answers[1] > 0, "no node classified occluded");
    let hidden = host.asked.iter().filter(|l| l.x < 0.0).count();
    assert_eq!(
        hidden, 0,
        "lights of an occluded node were asked point-to-point"
    );
    // Only the visible cluster was evaluated.
    assert!(r.lights_evaluated <= 300);
}

// ---------------------------------------------------------------------------
// Threshold 0 and visible fractions
// ---------------------------------------------------------------------------

#[test]
fn threshold_zero_is_the_shadowed_sum() -> Result<(), TestCaseError> {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::new(0.9, 0.8, 0.7)));
    for (p, n) in street_points() {
        let exact = shading.exact_query(
            &Query::new(p, n).unwrap(),
            &mut Occluders::new(walls.clone()),
        );
        let r = shading
            .shade_query(
                &Query::new(p, n).unwrap(),
                Threshold::zero(),
                &mut Occluders::new(walls.clone()),
            )
            .unwrap();
        check_exact(&r, exact)?;
        // A host that knows nothing gets the same sum, one point query per
        // light above the horizon at most.
        let mut unsure = Unsure(Occluders::new(walls.clone()));
        let r = shading
            .shade_query(&Query::new(p, n).unwrap(), Threshold::zero(), &mut unsure)
            .unwrap();
        check_exact(&r, exact)?;
        prop_assert!(r.point_queries as usize <= lights.len());
    }
    Ok(())
}

#[test]
fn visible_fraction_moves_the_estimate_within_the_bound() -> Result<(), TestCaseError> {
    let (lights, walls) = street();
    let tree = LightTree::build(&lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut moved = 0;
    for (p, n) in street_points() {
        let exact = shading.exact_query(
            &Query::new(p, n).unwrap(),
            &mut Occluders::new(walls.clone()),
        );
        // Coarse thresholds leave partially occluded nodes in the cut.
        for t in [
            Threshold::relative(0.5),
            Threshold::relative(0.2),
            Threshold::relative(0.05),
        ] {
            let base = shading
                .shade_query(
                    &Query::new(p, n).unwrap(),
                    t,
                    &mut Occluders::new(walls.clone()),
                )
                .unwrap();
            for fraction in [
                Fraction::Sampled,
                Fraction::Constant(0.0),
                Fraction::Constant(1.0),
            ] {
                let mut host = Occluders::with_fraction(walls.clone(), fraction);
                let r = shading
                    .shade_query(&Query::new(p, n).unwrap(), t, &mut host)
                    .unwrap();
                check_bound(&r, exact)?;
                check_threshold(&r, &t)?;
                if r.radiance != base.radiance {
                    moved += 1;
                }
            }
        }
    }
    assert!(moved > 0, "no visible fraction changed any estimate");
    Ok(())
}

// ---------------------------------------------------------------------------
// Property tests
// ---------------------------------------------------------------------------

/// 1 to 20 boxes centred in the cube of half-size 10 that holds the lights,
/// half-extents 0.05 to 4 per axis.
fn occluders() -> impl Strategy<Value = Vec<Aabb>> {
    prop::collection::vec(
        (vec_in(10.0), (0.05f32..=4.0, 0.05f32..=4.0, 0.05f32..=4.0)),
        1..=20,
    )
    .prop_map(|boxes| {
        boxes
            .into_iter()
            .map(|(c, (hx, hy, hz))| {
                let h = Vec3::new(hx, hy, hz);
                Aabb {
                    min: c - h,
                    max: c + h,
                }
            })
            .collect()
    })
}

fn fraction() -> impl Strategy<Value = Fraction> {
    prop_oneof![
        Just(Fraction::Default),
        Just(Fraction::Sampled),
        (0.0f32..=1.0).prop_map(Fraction::Constant),
    ]
}

/// The shared thresholds, plus interpolated ones.
fn any_threshold() -> impl Strategy<Value = Threshold> {
    prop_oneof![
        4 => threshold(),
        1 => (1e-3f64..=0.5, 1.5f64..=4.0).prop_map(|(t, b)| Threshold::relative(t).with_interpolation(b)),
    ]
}

proptest! {
    #![proptest_config(cases(256))]

    #[test]
    fn lambert_bound_holds_with_occluders(
        lights in lights(500),
        boxes in occluders(),
        points in prop::collection::vec((vec_in(12.0), direction()), 1..=4),
        t in any_threshold(),
        fraction in fraction(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::new(0.9, 0.5, 0.2)));
        for (p, n) in points {
            let exact = shading
                .exact_query(&Query::new(p, n).unwrap(), &mut Occluders::new(boxes.clone()));
            let mut host = Occluders::with_fraction(boxes.clone(), fraction);
            let r = shading.shade_query(&Query::new(p, n).unwrap(), t, &mut host).unwrap();
            check_occluded(&r, exact, &t, &host)?;
        }
    }

    #[test]
    fn phong_bound_holds_with_occluders(
        lights in lights(500),
        boxes in occluders(),
        points in prop::collection::vec((vec_in(12.0), direction(), direction()), 1..=4),
        exponent in prop::sample::select(EXPONENTS.to_vec()),
        t in any_threshold(),
        fraction in fraction(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Phong::new(Vec3::new(0.3, 0.6, 0.9), exponent));
        for (p, n, v) in points {
            let exact = shading
                .exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), &mut Occluders::new(boxes.clone()));
            let mut host = Occluders::with_fraction(boxes.clone(), fraction);
            let r = shading.shade_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), t, &mut host).unwrap();
            check_occluded(&r, exact, &t, &host)?;
        }
    }

    #[test]
    fn ggx_bound_holds_with_occluders(
        lights in lights(500),
        boxes in occluders(),
        points in prop::collection::vec((vec_in(12.0), direction(), direction()), 1..=4),
        alpha in (-3.0f64..=0.0).prop_map(|u| (10f64.powf(u) as f32).clamp(1e-3, 1.0)),
        t in any_threshold(),
        fraction in fraction(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Ggx::new(Vec3::new(0.3, 0.6, 0.9), alpha));
        for (p, n, v) in points {
            let q = Query::new(p, n).unwrap().with_view(v).unwrap();
            let exact = shading.exact_query(&q, &mut Occluders::new(boxes.clone()));
            let mut host = Occluders::with_fraction(boxes.clone(), fraction);
            let r = shading.shade_query(&q, t, &mut host).unwrap();
            check_occluded(&r, exact, &t, &host)?;
        }
    }

    #[test]
    fn hosts_without_occluders_change_nothing(
        lights in lights(500),
        p in vec_in(12.0),
        n in direction(),
        t in any_threshold(),
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
        let plain = shading.shade(p, n, t).unwrap();
        let free = shading.shade_query(&Query::new(p, n).unwrap(), t, &mut Unoccluded).unwrap();
        prop_assert_eq!(plain, free);
        prop_assert_eq!((free.classify_queries, free.point_queries), (0, 0));

        // A host with no occluders answers `Visible` at the root, after which
        // nothing more is asked and the cut is the unoccluded one. The host
        // is asked only when the cut takes the root (or, with interpolation,
        // about the lights the blend reaches): a threshold that the root's
        // `[0, upper]` meets may ask nothing.
        let mut empty = Occluders::new(Vec::new());
        let r = shading.shade_query(&Query::new(p, n).unwrap(), t, &mut empty).unwrap();
        prop_assert!(r.classify_queries <= 1);
        if r.classify_queries == 1 {
            prop_assert_eq!(r.radiance, plain.radiance);
            prop_assert_eq!(r.error_bound, plain.error_bound);
            prop_assert_eq!(r.point_queries, 0);
        } else {
            check_bound(&r, shading.exact(p, n).unwrap())?;
            check_threshold(&r, &t)?;
        }
    }
}
