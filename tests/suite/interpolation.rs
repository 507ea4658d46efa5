//! Interpolation across levels: along a dense scanline the estimate's error
//! jumps far less between neighbouring points, and the bound still holds.

use glam::{DVec3, Vec3};
use proptest::prelude::*;

use crate::common::{cases, direction};
use manylights::{
    Lambert, LightTree, PointLight, Query, ShadeError, ShadeResult, Threshold, Unoccluded,
};

/// A grid of street lamps (rows along x and y every 20 units, a lamp every
/// 2), 6 units above the ground.
fn streets() -> Vec<PointLight> {
    let mut lights = Vec::new();
    for street in 0..=10 {
        let s = street as f32 * 20.0;
        for k in 0..=100 {
            let t = k as f32 * 2.0;
            let colour = Vec3::new(1.0, 0.85, 0.6 + 0.002 * k as f32);
            lights.push(PointLight::new(Vec3::new(s, t, 6.0), colour));
            lights.push(PointLight::new(Vec3::new(t, s + 1.0, 6.0), colour));
        }
    }
    lights
}

/// Largest jump of the relative error between neighbouring points, the
/// mean cost, and whether every point kept its bound.
fn scan(threshold: Threshold) -> (f64, f64) {
    let tree = LightTree::build(&streets()).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::splat(0.7)));
    let (a, b) = (Vec3::new(13.0, 7.0, 0.0), Vec3::new(187.0, 151.0, 0.0));
    let count = 3000;
    let mut previous: Option<f64> = None;
    let (mut jump, mut cost) = (0.0f64, 0.0);
    for i in 0..count {
        let p = a.lerp(b, i as f32 / (count - 1) as f32);
        let r = s.shade(p, Vec3::Z, threshold).unwrap();
        let exact = s.exact(p, Vec3::Z).unwrap();
        assert!(r.certifies(exact), "{r:?} against {exact}");
        let rel = ((r.radiance - exact) / exact).max_element();
        if let Some(prev) = previous {
            jump = jump.max((rel - prev).abs());
        }
        previous = Some(rel);
        cost += f64::from(r.cost());
    }
    (jump, cost / count as f64)
}

#[test]
fn interpolation_shrinks_jumps_along_a_scanline() {
    for t in [0.05, 0.2] {
        let (discrete, discrete_cost) = scan(Threshold::relative(t));
        let (smooth, smooth_cost) = scan(Threshold::relative(t).with_interpolation(2.0));
        assert!(
            smooth * 4.0 <= discrete,
            "threshold {t}: largest jump {smooth:e} with interpolation vs {discrete:e} without"
        );
        assert!(
            smooth_cost <= 1.6 * discrete_cost,
            "cost {smooth_cost} vs {discrete_cost}"
        );
    }
}

/// Lights over a sphere of radius 100 and a scanline of points with one
/// normal whose tangent plane cuts the sphere: many nodes straddle the
/// plane, and a node's children often have a larger summed error than the
/// node.
struct Scanline {
    tree: LightTree,
    normal: Vec3,
    ends: (Vec3, Vec3),
}

impl Scanline {
    /// 20,000 lights, panels 300 units above the sphere's centre facing
    /// `(1, 0, -0.5)`.
    fn horizon() -> Self {
        let lights = manylights_report::scenes::sphere_lights(20_000, 1998);
        Self {
            tree: LightTree::build(&lights).unwrap(),
            normal: Vec3::new(1.0, 0.0, -0.5),
            ends: (
                Vec3::new(-150.0, 10.0, 300.0),
                Vec3::new(150.0, 10.0, 300.0),
            ),
        }
    }

    /// 100,000 lights and a chord 99 units from the centre, so that the
    /// points cross just inside the shell and out again, facing `(0.6, 0.3,
    /// 1)`: near the crossings the balls of ever smaller nodes reach the
    /// points, and such a node has no finite bound.
    fn shell() -> Self {
        let lights = manylights_report::scenes::sphere_lights(100_000, 1998);
        Self {
            tree: LightTree::build(&lights).unwrap(),
            normal: Vec3::new(0.6, 0.3, 1.0).normalize(),
            ends: (Vec3::new(-25.0, 5.0, 99.0), Vec3::new(25.0, 5.0, 99.0)),
        }
    }

    fn points(&self, count: usize) -> Vec<Vec3> {
        let (a, b) = self.ends;
        (0..count)
            .map(|i| a.lerp(b, i as f32 / (count - 1) as f32))
            .collect()
    }

    fn exact(&self, points: &[Vec3]) -> Vec<DVec3> {
        let s = self.tree.shading(Lambert::new(Vec3::ONE));
        points
            .iter()
            .map(|&p| s.exact(p, self.normal).unwrap())
            .collect()
    }

    /// The largest jump of the relative error between neighbouring points,
    /// every point certified.
    fn jump(&self, threshold: Threshold, points: &[Vec3], exact: &[DVec3]) -> f64 {
        self.jump_at(threshold, points, exact).0
    }

    /// [`jump`](Self::jump), and the index of the point after it.
    fn jump_at(&self, threshold: Threshold, points: &[Vec3], exact: &[DVec3]) -> (f64, usize) {
        let mut s = self.tree.shading(Lambert::new(Vec3::ONE));
        let results: Vec<ShadeResult> = points
            .iter()
            .map(|&p| s.shade(p, self.normal, threshold).unwrap())
            .collect();
        largest_jump(&results, exact)
    }

    /// [`jump`](Self::jump) for the points shaded by one batch call.
    fn batch_jump(&self, threshold: Threshold, points: &[Vec3], exact: &[DVec3]) -> f64 {
        let mut s = self.tree.shading(Lambert::new(Vec3::ONE));
        let queries: Vec<Query> = points
            .iter()
            .map(|&p| Query::new(p, self.normal).unwrap())
            .collect();
        let mut results = vec![ShadeResult::default(); queries.len()];
        s.shade_batch(&queries, threshold, Unoccluded, &mut results)
            .unwrap();
        largest_jump(&results, exact).0
    }
}

/// The largest jump of the relative error (largest channel) between
/// neighbouring results, each checked against its exact value, and the
/// index of the result after it.
fn largest_jump(results: &[ShadeResult], exact: &[DVec3]) -> (f64, usize) {
    let mut previous: Option<f64> = None;
    let (mut jump, mut at) = (0.0f64, 0);
    for (i, (r, &exact)) in results.iter().zip(exact).enumerate() {
        assert!(r.certifies(exact), "{r:?} against {exact}");
        let rel = ((r.radiance - exact) / exact).max_element();
        if let Some(prev) = previous
            && (rel - prev).abs() > jump
        {
            (jump, at) = ((rel - prev).abs(), i);
        }
        previous = Some(rel);
    }
    (jump, at)
}

/// Near the horizon the blended cut used to miss the threshold where a
/// node's children outweighed it, fall back to the discrete cut at some
/// points and not at their neighbours, and jump more than without
/// interpolation (at 20% on a sphere of 10^5 lights: 0.163 against 0.145
/// without); and at 1% the level moved where two nodes of nearly equal
/// priority traded places near the list's last step (here a jump of about
/// 1e-3 at both densities). Nested intervals and a level solved for the
/// target leave a continuous estimate: its largest jump shrinks with the
/// spacing of the points, the discrete cut's does not. The spacing is
/// refined where the jump is largest (between the two points of the
/// largest jump on the line): a continuous estimate changes there by a
/// fraction of the jump between any two of a hundred points, a
/// discontinuity by all of it. (Over the whole line, the largest jump at a
/// tenth of the spacing can lie elsewhere, in a steep but continuous stretch
/// narrower than the coarse spacing.)
#[test]
fn interpolation_leaves_no_jumps_near_the_horizon() {
    let scene = Scanline::horizon();
    let (coarse_points, fine_points) = (scene.points(3_000), scene.points(30_000));
    let (coarse_exact, fine_exact) = (scene.exact(&coarse_points), scene.exact(&fine_points));
    for t in [0.01, 0.05, 0.2] {
        let threshold = Threshold::relative(t);
        let discrete = scene.jump(threshold, &fine_points, &fine_exact);
        let smooth = threshold.with_interpolation(2.0);
        let coarse = scene.jump(smooth, &coarse_points, &coarse_exact);
        let (fine, at) = scene.jump_at(smooth, &fine_points, &fine_exact);
        assert!(
            fine * 5.0 <= discrete,
            "threshold {t}: largest jump {fine:e} with interpolation vs {discrete:e} without"
        );
        assert!(
            fine <= coarse,
            "threshold {t}: largest jump {fine:e} at 10x the density vs {coarse:e}"
        );
        if at == 0 {
            continue; // no jump at all
        }
        let (a, b) = (fine_points[at - 1], fine_points[at]);
        let zoom: Vec<Vec3> = (0..=100).map(|i| a.lerp(b, i as f32 / 100.0)).collect();
        let zoom_exact = scene.exact(&zoom);
        let finer = scene.jump(smooth, &zoom, &zoom_exact);
        assert!(
            finer * 4.0 <= fine,
            "threshold {t}: largest jump {finer:e} between 100 points in [{a}, {b}] vs {fine:e} \
             at their ends"
        );
    }
}

#[test]
fn interpolation_keeps_the_threshold() {
    let tree = LightTree::build(&streets()).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::splat(0.7)));
    for i in 0..200 {
        let p = Vec3::new(3.0 + i as f32 * 0.9, 50.0 + (i % 7) as f32, 0.0);
        let r = s
            .shade(
                p,
                Vec3::Z,
                Threshold::relative(0.02).with_interpolation(2.0),
            )
            .unwrap();
        assert!(r.error_bound.max_element() <= 0.02 * r.radiance.max_element() * (1.0 + 1e-12));
        assert_ne!(r.radiance, DVec3::ZERO);
    }
}

#[test]
fn bad_bands_are_refused() {
    let tree = LightTree::build(&streets()).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    for band in [1.0, 0.5, -2.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            s.shade(
                Vec3::ZERO,
                Vec3::Z,
                Threshold::relative(0.01).with_interpolation(band)
            ),
            Err(ShadeError::InvalidBand(_))
        ));
    }
}

/// Regression: with interpolation and a target at or below the rounding
/// floor (zero, relative `1e-18`, absolute `1e-300`), a cut refined down to
/// its lights reported `ThresholdMet` with the nested fold's rounding
/// allowance as its bound (about `1e-14`), above the target. A cut with
/// nothing left to refine is the exact sum of its lights, as without
/// interpolation: bound 0, which meets every target.
#[test]
fn targets_below_the_rounding_floor_are_met_with_interpolation() {
    let lights = [
        PointLight::new(Vec3::new(0.3, 0.1, 1.0), Vec3::ONE),
        PointLight::new(Vec3::new(-0.7, 0.2, 0.9), Vec3::ONE),
        PointLight::new(Vec3::new(0.1, -0.4, 2.0), Vec3::ONE),
    ];
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::new(0.8, 0.6, 0.4)));
    let (p, n) = (Vec3::ZERO, Vec3::new(0.1, 0.2, 1.0));
    let exact = s.exact(p, n).unwrap();
    for t in [
        Threshold::zero(),
        Threshold::relative(0.0),
        Threshold::relative(1e-18),
        Threshold::absolute(1e-300),
    ] {
        for band in [1.5, 2.0, 8.0] {
            let r = s.shade(p, n, t.with_interpolation(band)).unwrap();
            assert_eq!(r.stop, manylights::Stop::ThresholdMet, "{t:?}");
            assert_eq!(r.error_bound, DVec3::ZERO, "{t:?} band {band}: {r:?}");
            assert!(r.certifies(exact), "{r:?} against {exact}");
        }
    }
}

/// Regression: Lightcuts' per-node target with interpolation, at a point
/// on one of the lights of a dense slab, returned radiance 0 with an
/// infinite bound and `ThresholdMet`: the blend capped the priority of a
/// child whose ball reaches the point at its parent's, mixing its whole
/// line into the sum. Such a child is now refined at every level its parent
/// is; every result has a finite bound and holds it.
#[test]
fn per_node_interpolation_at_a_light_has_a_finite_bound() {
    let mut state = 12345u64;
    let mut u = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let lights: Vec<PointLight> = (0..10_000)
        .map(|_| PointLight::new(Vec3::new(u(), u(), 0.3 * u()), Vec3::ONE))
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::splat(0.5)));
    for band in [1.5, 2.0] {
        let t = Threshold::per_node(0.3).with_interpolation(band);
        for light in lights.iter().step_by(5) {
            let r = s.shade(light.position, Vec3::Z, t).unwrap();
            let exact = s.exact(light.position, Vec3::Z).unwrap();
            assert!(r.error_bound.is_finite(), "{r:?} at {}", light.position);
            assert!(r.certifies(exact), "{r:?} against {exact}");
        }
    }
}

/// Crossing just inside a shell of lights, a point's cut must refine every
/// node whose ball reaches it. Interpolation used to make the jumps there
/// larger than without it (at 5%, 3.5e-2 against 1.8e-2): a refinement of
/// the blend's bookkeeping left a node's interval stale when its children
/// settled to nothing, and the list refined on, almost to the exact sum at
/// some points and not at their neighbours. And in the batch call a
/// group's first point could be shaded by a cut of its own, a speck of up
/// to the threshold among neighbours shaded by the group's.
#[test]
fn interpolation_smooths_a_scanline_crossing_a_shell_of_lights() {
    let scene = Scanline::shell();
    let points = scene.points(10_000);
    let exact = scene.exact(&points);
    for t in [0.05, 0.2] {
        let threshold = Threshold::relative(t);
        let smooth = threshold.with_interpolation(2.0);
        let (discrete, interpolated) = (
            scene.jump(threshold, &points, &exact),
            scene.jump(smooth, &points, &exact),
        );
        assert!(
            interpolated * 5.0 <= discrete,
            "threshold {t}: largest jump {interpolated:e} with interpolation vs {discrete:e} without"
        );
        let (discrete, interpolated) = (
            scene.batch_jump(threshold, &points, &exact),
            scene.batch_jump(smooth, &points, &exact),
        );
        assert!(
            interpolated * 5.0 <= discrete,
            "threshold {t}, batch: largest jump {interpolated:e} with interpolation vs {discrete:e} \
             without"
        );
    }
}

/// The mean evaluations per point of `points` (facing `normal`) with and
/// without interpolation at `threshold`, every result certified.
fn costs(tree: &LightTree, points: &[Vec3], normal: Vec3, threshold: Threshold) -> (f64, f64) {
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let mut cost = |th: Threshold| {
        let total: f64 = points
            .iter()
            .map(|&p| {
                let r = s.shade(p, normal, th).unwrap();
                let exact = s.exact(p, normal).unwrap();
                assert!(r.certifies(exact), "{r:?} against {exact}");
                f64::from(r.cost())
            })
            .sum();
        total / points.len() as f64
    };
    (cost(threshold), cost(threshold.with_interpolation(2.0)))
}

/// A point inside a cube of lights, on a tangent plane through it, used to
/// cost interpolation 50 times the discrete cut's evaluations (500,000
/// against 5,000 at 10^6 lights): the stale interval of a node whose
/// children settled dark kept the blend's running bound infinite, and the
/// list refined until nothing was left. The same at the centre of a
/// cluster whose lights crowd ever closer (a 2^-k cluster).
#[test]
fn interpolation_costs_no_more_than_the_discrete_cut_inside_the_lights() {
    let mut state = 99u64;
    let mut unit = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let cube: Vec<PointLight> = (0..100_000)
        .map(|_| PointLight::new(Vec3::new(unit(), unit(), unit()), Vec3::ONE))
        .collect();
    let inside: Vec<Vec3> = (0..16)
        .map(|_| Vec3::new(unit(), unit(), unit()) * 0.4 + Vec3::splat(0.3))
        .collect();
    let cluster: Vec<PointLight> = (0..40_000i32)
        .map(|i| {
            let scale = 2f32.powi(-(i % 40));
            PointLight::new(Vec3::new(unit(), unit(), unit()) * scale, Vec3::ONE)
        })
        .collect();
    let centre: Vec<Vec3> = (0..8).map(|k| Vec3::splat(2f32.powi(-3 * k - 4))).collect();
    let scenes = [
        (LightTree::build(&cube).unwrap(), inside, Vec3::Z),
        (
            LightTree::build(&cluster).unwrap(),
            centre,
            Vec3::new(0.3, 0.2, 1.0).normalize(),
        ),
    ];
    for (tree, points, normal) in &scenes {
        for t in [0.01, 0.1] {
            let (discrete, interpolated) = costs(tree, points, *normal, Threshold::relative(t));
            assert!(
                interpolated <= INTERPOLATION_COST_RATIO * discrete,
                "{} lights at {t}: {interpolated} evaluations per point with interpolation vs \
                 {discrete} without",
                tree.len()
            );
        }
    }
}

/// The documented multiple of the discrete cut's evaluations that
/// interpolation stays within (see `Threshold::with_interpolation`).
const INTERPOLATION_COST_RATIO: f64 = 2.0;

proptest! {
    #![proptest_config(cases(48))]

    /// Interpolation costs at most [`INTERPOLATION_COST_RATIO`] times the
    /// discrete cut's evaluations, points inside the lights and out: a
    /// cube, clusters, a shell and a thin layer of lights.
    #[test]
    fn interpolation_costs_at_most_a_multiple_of_the_discrete_cut(
        (lights, points) in layouts(),
        normal in direction(),
        t in prop_oneof![Just(0.01), Just(0.05), Just(0.2)],
        band in 1.5f64..=4.0,
    ) {
        let tree = LightTree::build(&lights).unwrap();
        let mut s = tree.shading(Lambert::new(Vec3::ONE));
        let (mut discrete, mut interpolated) = (0.0, 0.0);
        for &p in &points {
            let threshold = Threshold::relative(t);
            discrete += f64::from(s.shade(p, normal, threshold).unwrap().cost());
            let r = s.shade(p, normal, threshold.with_interpolation(band)).unwrap();
            prop_assert!(r.certifies(s.exact(p, normal).unwrap()), "{:?}", r);
            interpolated += f64::from(r.cost());
        }
        prop_assert!(
            interpolated <= INTERPOLATION_COST_RATIO * discrete.max(1.0),
            "{} evaluations with interpolation vs {} without", interpolated, discrete
        );
    }
}

/// Up to 20,000 lights of one of four layouts (a unit cube, a 2^-k
/// cluster, a unit sphere, a layer 0.01 thick) with 8 points inside them.
fn layouts() -> impl Strategy<Value = (Vec<PointLight>, Vec<Vec3>)> {
    let unit = || (0.0f32..1.0, 0.0f32..1.0, 0.0f32..1.0).prop_map(|(x, y, z)| Vec3::new(x, y, z));
    (
        0usize..4,
        prop::collection::vec((unit(), 0.5f32..1.5), 500..=20_000),
        prop::collection::vec(unit(), 8),
    )
        .prop_map(|(layout, lights, points)| {
            let place = |i: usize, u: Vec3| match layout {
                0 => u,
                1 => u * 2f32.powi(-((i % 20) as i32)),
                2 => {
                    let (z, phi) = (2.0 * u.z - 1.0, u.y * std::f32::consts::TAU);
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                }
                _ => Vec3::new(u.x, u.y, 0.01 * u.z),
            };
            let lights = lights
                .iter()
                .enumerate()
                .map(|(i, &(u, w))| PointLight::new(place(i, u), Vec3::splat(w)))
                .collect();
            let points = points
                .iter()
                .enumerate()
                .map(|(i, &u)| match layout {
                    1 => Vec3::splat(2f32.powi(-1 - (i as i32) % 12)),
                    2 => (u - Vec3::splat(0.5)).normalize_or(Vec3::Z) * (0.9 + 0.2 * u.x),
                    _ => place(i, u),
                })
                .collect();
            (lights, points)
        })
}
