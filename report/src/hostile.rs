//! The hostile part: scenes built to defeat the tree, where a certified
//! cut settles nothing early (every node near the point straddles its
//! tangent plane, or holds the point), at a certified 1% (and 10% for the
//! cluster), one core, against the vectorized exact sum ([`SoaLights`])
//! timed in the same run.
//!
//! ```text
//! cargo run --release -p manylights-report -- hostile
//! cargo run --release -p manylights-report -- hostile --quick
//! ```
//!
//! The scenes ([`crate::scenes`]): lights in the plane `x + y + z = 0`
//! with a normal `e` off the plane's, a point at the centre of a cluster
//! whose lights lie at distances `2^-k`, the pole of a logarithmic spiral,
//! and a tile of points on the ground among lights within `1e-6` of it.
//! Single points are timed one by one ([`Shading::shade_query`]); the
//! batch rows shade a tile of points by one [`Shading::shade_batch`] call
//! against the same points one by one and against the exact sum.
//!
//! Per row: evaluations per point (node bounds plus lights,
//! [`ShadeResult::cost`]) over the number of lights, the median time per
//! point over [`ROUNDS`] alternating passes, the ratios of the medians,
//! and (single points) the vectorized `f32` sum's own relative error
//! against the crate's `f64` exact sum.
//! Every result is checked against the crate's `f64` exact sum
//! ([`Shading::exact_query`]); the part fails if one breaks its bound.

use std::error::Error;
use std::hint::black_box;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{
    Lambert, LightTree, PointLight, Query, ShadeResult, Shading, Threshold, Unoccluded,
};

use crate::config::SEED;
use crate::exact::SoaLights;
use crate::scenes::{
    CLUSTER_CENTRE, Material, TILTED_POINT, geometric_cluster, log_spiral, thin_layer,
    thin_layer_points, tilted_normal, tilted_plane,
};

/// The part's name.
pub const HOSTILE: &str = "hostile";
/// Alternating rounds per row; odd, so that the median is one round's.
pub const ROUNDS: usize = 11;
/// Rounds with `--quick`.
const QUICK_ROUNDS: usize = 3;
/// The certified relative target (the cluster also at 10%).
const TARGET: f64 = 0.01;
/// Side of the batch rows' tile of points.
const TILE: usize = 16;

/// One scene's lights, tree and exact sum.
struct Lit {
    lights: Vec<PointLight>,
    tree: LightTree,
    soa: SoaLights,
}

impl Lit {
    fn new(lights: Vec<PointLight>) -> Result<Self, Box<dyn Error>> {
        let tree = LightTree::build(&lights)?;
        let soa = SoaLights::new(&lights);
        Ok(Self { lights, tree, soa })
    }

    /// The vectorized exact sum at `point`, Lambert of albedo 1.
    fn exact_soa(&self, point: Vec3, normal: Vec3) -> DVec3 {
        self.soa
            .shade(&Material::diffuse(Vec3::ONE), point, normal, normal)
    }
}

/// The times of each of `methods` (seconds per call), run in turn
/// `rounds` times.
fn alternating(rounds: usize, methods: &mut [&mut dyn FnMut()]) -> Vec<Vec<f64>> {
    let mut times = vec![Vec::new(); methods.len()];
    for _ in 0..rounds {
        for (method, times) in methods.iter_mut().zip(&mut times) {
            let t = Instant::now();
            method();
            times.push(t.elapsed().as_secs_f64());
        }
    }
    times
}

/// The median of `v`'s times.
fn median(v: &[f64]) -> f64 {
    crate::sweep::median(v.to_vec())
}

/// The median over the rounds of `a`'s time over `b`'s.
fn ratio(a: &[f64], b: &[f64]) -> f64 {
    median(&a.iter().zip(b).map(|(a, b)| a / b).collect::<Vec<_>>())
}

/// Counts results breaking their bound against `exact`.
fn check(r: &ShadeResult, exact: DVec3, violations: &mut usize) {
    if !r.certifies(exact) {
        *violations += 1;
    }
}

/// Runs the part; an error if a result breaks its certified bound.
pub fn run_hostile(quick: bool) -> Result<(), Box<dyn Error>> {
    let started = Instant::now();
    let rounds = if quick { QUICK_ROUNDS } else { ROUNDS };
    let (plane, cluster) = if quick {
        (100_000, 50_000)
    } else {
        (1_000_000, 200_000)
    };
    let quick_flag = if quick { " --quick" } else { "" };
    println!("## Hostile scenes: where the tree settles nothing early\n");
    println!(
        "  `cargo run --release -p manylights-report -- {HOSTILE}{quick_flag}`; Lambert of albedo \
         1; one core; evaluations = node bounds + lights, over the number of lights N; times are \
         medians over {rounds} alternating passes (exact sum, then cut), the ratio the median of \
         the rounds' ratios; exact = the vectorized f32 sum\n"
    );
    println!(
        "| scene | N | target | evals / N | nodes | lights | cut us/pt | exact us/pt | cut / exact \
         | exact sum's error |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut violations = 0;
    let s = Lit::new(tilted_plane(plane, SEED))?;
    for e in [1e-7f32, 1e-5, 1e-3] {
        let label = format!("plane x+y+z=0, normal off by e = {e:.0e}");
        single(
            &s,
            &label,
            TILTED_POINT,
            tilted_normal(e),
            TARGET,
            rounds,
            &mut violations,
        )?;
    }
    let s = Lit::new(geometric_cluster(cluster, SEED))?;
    for (t, normal) in [
        (TARGET, Vec3::Z),
        (0.1, Vec3::Z),
        (TARGET, Vec3::new(0.3, -0.5, 0.8)),
    ] {
        let label = format!("2^-k cluster, at its centre, normal {normal:.1}");
        let normal = normal.normalize();
        single(
            &s,
            &label,
            CLUSTER_CENTRE,
            normal,
            t,
            rounds,
            &mut violations,
        )?;
    }
    let s = Lit::new(log_spiral(cluster))?;
    for normal in [Vec3::Z, Vec3::new(0.2, 0.1, 1.0)] {
        let label = format!("log spiral, at its pole, normal {normal:.1}");
        single(
            &s,
            &label,
            Vec3::ZERO,
            normal.normalize(),
            TARGET,
            rounds,
            &mut violations,
        )?;
    }
    println!();
    println!(
        "| batch of {} points | N | evals / pt / N | batch us/pt | alone us/pt | exact us/pt | batch \
         / alone | batch / exact |",
        TILE * TILE
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    let s = Lit::new(thin_layer(plane / 10, SEED))?;
    let points: Vec<(Vec3, Vec3)> = thin_layer_points(TILE)
        .into_iter()
        .map(|p| (p, Vec3::Z))
        .collect();
    batch(
        &s,
        "ground among lights within 1e-6 of it",
        &points,
        rounds,
        &mut violations,
    )?;
    let s = Lit::new(tilted_plane(plane / 10, SEED))?;
    let normal = tilted_normal(1e-7);
    let points: Vec<(Vec3, Vec3)> = (0..TILE * TILE)
        .map(|i| {
            let (x, y) = ((i % TILE) as f32 * 0.25, (i / TILE) as f32 * 0.25);
            (Vec3::new(x, y, -(x + y)), normal)
        })
        .collect();
    batch(
        &s,
        "plane x+y+z=0, e = 1e-7",
        &points,
        rounds,
        &mut violations,
    )?;
    println!(
        "\n  results breaking their certified bound (against exact_query): {violations}; part run \
         time {:.0} s\n",
        started.elapsed().as_secs_f64()
    );
    if violations > 0 {
        return Err(format!("{violations} hostile results break their certified bound").into());
    }
    Ok(())
}

/// One point of scene `s`, at relative target `target`: its row.
fn single(
    s: &Lit,
    label: &str,
    point: Vec3,
    normal: Vec3,
    target: f64,
    rounds: usize,
    violations: &mut usize,
) -> Result<(), Box<dyn Error>> {
    let mut shading = s.tree.shading(Lambert::new(Vec3::ONE));
    let query = Query::new(point, normal)?;
    let threshold = Threshold::relative(target);
    let exact = shading.exact_query(&query, Unoccluded);
    let r = shading.shade_query(&query, threshold, Unoccluded)?;
    check(&r, exact, violations);
    let times = alternating(
        rounds,
        &mut [
            &mut || {
                black_box(s.exact_soa(black_box(point), normal));
            },
            &mut || {
                black_box(shading.shade_query(black_box(&query), threshold, Unoccluded)).ok();
            },
        ],
    );
    let n = s.lights.len();
    println!(
        "| {label} | {n} | {target} | {:.3} | {} | {} | {:.0} | {:.0} | {:.2} | {:.1e} |",
        f64::from(r.cost()) / n as f64,
        r.nodes_evaluated,
        r.lights_evaluated,
        median(&times[1]) * 1e6,
        median(&times[0]) * 1e6,
        ratio(&times[1], &times[0]),
        crate::measure::relative(s.exact_soa(point, normal) - exact, exact)
    );
    Ok(())
}

/// A tile of points of scene `s` at the target: the batch call against the
/// points one by one and the exact sum.
fn batch(
    s: &Lit,
    label: &str,
    points: &[(Vec3, Vec3)],
    rounds: usize,
    violations: &mut usize,
) -> Result<(), Box<dyn Error>> {
    let mut shading: Shading<'_, Lambert> = s.tree.shading(Lambert::new(Vec3::ONE));
    let queries: Vec<_> = points
        .iter()
        .map(|&(p, n)| Query::new(p, n))
        .collect::<Result<_, _>>()?;
    let threshold = Threshold::relative(TARGET);
    let mut results = vec![ShadeResult::default(); queries.len()];
    let stats = shading.shade_batch(&queries, threshold, Unoccluded, &mut results)?;
    let mut evaluations = stats.shared_evaluations;
    for (q, r) in queries.iter().zip(&results) {
        check(r, shading.exact_query(q, Unoccluded), violations);
        evaluations += u64::from(r.cost());
    }
    // A session of its own for the points one by one, as a renderer
    // shading them so would keep.
    let mut alone = s.tree.shading(Lambert::new(Vec3::ONE));
    let times = alternating(
        rounds,
        &mut [
            &mut || {
                for &(p, n) in points {
                    black_box(s.exact_soa(black_box(p), n));
                }
            },
            &mut || {
                for q in &queries {
                    black_box(alone.shade_query(black_box(q), threshold, Unoccluded)).ok();
                }
            },
            &mut || {
                black_box(shading.shade_batch(&queries, threshold, Unoccluded, &mut results)).ok();
            },
        ],
    );
    let (n, per) = (s.lights.len(), points.len() as f64);
    println!(
        "| {label} | {n} | {:.3} | {:.0} | {:.0} | {:.0} | {:.2} | {:.2} |",
        evaluations as f64 / per / n as f64,
        median(&times[2]) / per * 1e6,
        median(&times[1]) / per * 1e6,
        median(&times[0]) / per * 1e6,
        ratio(&times[2], &times[1]),
        ratio(&times[2], &times[0])
    );
    Ok(())
}
