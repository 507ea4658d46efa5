//! The `sampling` part: one light per shading point, as a path tracer
//! samples, by the crate's [`LightSampler`](manylights::LightSampler)
//! against power sampling, pbrt-v4's BVH importance and Cycles' light tree
//! importance on the same tree ([`crate::sampling`]); and the crate's
//! stochastic cut ([`Shading::shade_stochastic`](manylights::Shading::shade_stochastic)).
//! The scenes: the street city, a sphere of lights seen from orbit, and
//! instant radiosity's virtual point lights (cosine lobes) in the VPL room
//! ([`Room`]), where every method's terms and the exact reference carry the
//! emission profiles.
//!
//! ```text
//! cargo run --release -p manylights-report -- sampling
//! ```
//!
//! For each scene and method: the exact relative variance of the
//! one-sample estimate `f / pmf` (its variance over the squared exact
//! value, channels summed, from every light's probability at each point;
//! mean and median over the points), the time per sample (choosing the
//! light, its probability and its exact term, measured over many samples),
//! and their product: the mean squared error at equal time, up to the time
//! given.

use std::error::Error;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::query::WithView;
use manylights::shader::Shader;
use manylights::{Emission, Emitter, Lambert, LightTree, PointLight, Query, Threshold, Unoccluded};
use rand::RngExt;
use rayon::prelude::*;

use crate::config::SEED;
use crate::sampling::{CratePick, CyclesPick, OneSample, PbrtPick, PowerPick};
use crate::scenes::{Room, SPHERE_RADIUS, SceneRng, city, rng, sphere_lights};

/// The part's name on the command line.
pub const SAMPLING: &str = "sampling";

/// Samples per point behind each time per sample.
const SAMPLES: usize = 4096;
/// Shading points per scene.
const POINTS: usize = 128;
/// Calls per point of the stochastic cut, and its points.
const STOCHASTIC_CALLS: usize = 64;
const STOCHASTIC_POINTS: usize = 32;
/// The stochastic cut's thresholds.
const STOCHASTIC_THRESHOLDS: [(&str, Threshold); 3] = [
    ("relative 30%", Threshold::relative(0.3)),
    ("relative 10%", Threshold::relative(0.1)),
    ("per-node 10%", Threshold::per_node(0.1)),
];

/// A scene of the part: lights (with their emission profiles when the
/// scene has oriented emitters), queries, the receivers' albedo, and each
/// query's exact value.
struct Case {
    name: String,
    lights: Vec<PointLight>,
    /// Each light's profile, in the order of `lights`; empty for isotropic
    /// lights.
    emission: Vec<Emission>,
    queries: Vec<Query<WithView>>,
    kd: Vec3,
    exact: Vec<DVec3>,
}

/// Points in orbit about the sphere of lights, at 1.5 to 3 radii from its
/// centre, whose tangent planes cut the sphere (panels tilted towards it):
/// many nodes straddle the plane.
fn orbit_points(count: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut rng = rng(seed);
    let mut out = Vec::with_capacity(count);
    while out.len() < count {
        let z: f32 = rng.random_range(-1.0..1.0);
        let phi: f32 = rng.random_range(0.0..std::f32::consts::TAU);
        let s = (1.0 - z * z).max(0.0).sqrt();
        let radial = Vec3::new(s * phi.cos(), s * phi.sin(), z);
        let p = radial * SPHERE_RADIUS * rng.random_range(1.5..3.0);
        let tangent = radial.any_orthonormal_vector();
        let tangent =
            glam::Quat::from_axis_angle(radial, rng.random_range(0.0..std::f32::consts::TAU))
                * tangent;
        let beta: f32 = rng.random_range(-0.3..1.0);
        let normal = (tangent * beta.cos() - radial * beta.sin()).normalize();
        if normal.dot(p).abs() < 0.9 * SPHERE_RADIUS {
            out.push((p, normal));
        }
    }
    out
}

/// The VPL counts of the room: 10^5 and 10^6 (`--quick`: 10^4).
fn vpl_counts(quick: bool) -> &'static [usize] {
    if quick {
        &[10_000]
    } else {
        &[100_000, 1_000_000]
    }
}

/// The scenes: the street city at 10^5 and 10^6 lights (`--quick`: 10^4
/// and 10^5), 10^5 lights over a sphere seen from orbit (`--quick`:
/// 10^4), and the VPL room's points lit by its VPLs ([`vpl_counts`]).
fn cases(quick: bool) -> Result<Vec<Case>, Box<dyn Error>> {
    let sizes: [usize; 2] = if quick {
        [10_000, 100_000]
    } else {
        [100_000, 1_000_000]
    };
    let mut out = Vec::new();
    for n in sizes {
        let scene = city(n, POINTS, SEED);
        let queries = scene
            .points
            .iter()
            .map(|p| Query::new(p.point, p.normal)?.with_view(p.view))
            .collect::<Result<_, _>>()?;
        out.push(Case {
            name: format!("street city, {n} lights"),
            lights: scene.lights,
            emission: Vec::new(),
            queries,
            kd: scene.material.kd,
            exact: Vec::new(),
        });
    }
    let n = if quick { 10_000 } else { 100_000 };
    let queries = orbit_points(POINTS, SEED ^ 0x0B17)
        .into_iter()
        .map(|(p, normal)| Query::new(p, normal)?.with_view(p.normalize()))
        .collect::<Result<_, _>>()?;
    out.push(Case {
        name: format!("sphere of lights from orbit, {n} lights"),
        lights: sphere_lights(n, SEED),
        emission: Vec::new(),
        queries,
        kd: Vec3::splat(0.5),
        exact: Vec::new(),
    });
    let room = Room::new();
    for &n in vpl_counts(quick) {
        let emitters = room.emitters(n, SEED);
        let queries = room
            .points(POINTS, SEED)
            .into_iter()
            .map(|(p, normal)| Query::new(p, normal)?.with_view(normal))
            .collect::<Result<_, _>>()?;
        out.push(Case {
            name: format!("VPL room, {n} VPLs (cosine lobes) and 4 primary lights"),
            lights: emitters.iter().map(|e| e.light).collect(),
            emission: emitters.iter().map(|e| e.emission).collect(),
            queries,
            kd: Vec3::splat(0.5),
            exact: Vec::new(),
        });
    }
    Ok(out)
}

/// One method's measurements on one scene.
struct Row {
    name: &'static str,
    /// Relative variance of the one-sample estimate: mean and median over
    /// the points.
    mean: f64,
    median: f64,
    /// Seconds per sample.
    time: f64,
}

/// The one-sample estimate of `method` at `query`: `f / pmf`, channels
/// summed, `f` the light's Lambert term times its profile's factor (the
/// model's, [`Emission::factor`]) when `emission` has the lights' profiles.
#[inline]
fn estimate(
    method: &impl OneSample,
    lambert: &Lambert,
    lights: &[PointLight],
    emission: &[Emission],
    query: &Query<WithView>,
    u: f64,
) -> f64 {
    let Some((index, pmf)) = method.pick(query, u) else {
        return 0.0;
    };
    term(lambert, lights, emission, index, query) / pmf
}

/// Light `index`'s exact term at `query`, channels summed: its Lambert term
/// times its profile's factor (the model's, [`Emission::factor`]) when
/// `emission` has the lights' profiles.
#[inline]
fn term(
    lambert: &Lambert,
    lights: &[PointLight],
    emission: &[Emission],
    index: usize,
    query: &Query<WithView>,
) -> f64 {
    let light = &lights[index];
    let f = lambert.eval(
        &(),
        query.surface(),
        light.position.as_dvec3(),
        light.intensity.as_dvec3(),
    );
    let factor = emission
        .get(index)
        .map_or(1.0, |e| e.factor(light.position, query.point()));
    sum(f) * factor
}

/// Channels summed.
fn sum(v: DVec3) -> f64 {
    v.x + v.y + v.z
}

/// The exact relative variances of `method`'s one-sample estimate (per
/// point with a positive exact value): `sum_i f_i^2 / pmf_i / F^2 - 1` over
/// every light, from every light's probability
/// ([`OneSample::probabilities`]), infinite where a lit light has
/// probability 0; and the time per sample, from [`SAMPLES`] samples at each
/// point. A variance measured from samples would miss the rare lights whose
/// `f / pmf` is huge, and read low exactly where a method is poor.
fn variances(method: &(impl OneSample + Sync), case: &Case, rng: &mut SceneRng) -> (Vec<f64>, f64) {
    let lambert = Lambert::new(case.kd);
    let started = Instant::now();
    let mut total = 0.0;
    for query in &case.queries {
        for _ in 0..SAMPLES {
            let u = rng.random::<f64>();
            total += estimate(method, &lambert, &case.lights, &case.emission, query, u);
        }
    }
    std::hint::black_box(total);
    let time = started.elapsed().as_secs_f64() / (SAMPLES * case.queries.len()) as f64;
    let relative = case
        .queries
        .par_iter()
        .filter_map(|query| {
            let mut pmf = vec![0.0; case.lights.len()];
            method.probabilities(query, &mut pmf);
            let (mut exact, mut second) = (0.0, 0.0);
            for (i, &p) in pmf.iter().enumerate() {
                let f = term(&lambert, &case.lights, &case.emission, i, query);
                if f > 0.0 {
                    exact += f;
                    second += if p > 0.0 { f * f / p } else { f64::INFINITY };
                }
            }
            (exact > 0.0).then(|| (second / (exact * exact) - 1.0).max(0.0))
        })
        .collect();
    (relative, time)
}

/// Mean and median.
fn mean_median(mut v: Vec<f64>) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    v.sort_by(f64::total_cmp);
    (mean, v[v.len() / 2])
}

/// Runs the part: a table per scene, then the stochastic cut's table.
pub fn run_sampling(quick: bool) -> Result<(), Box<dyn Error>> {
    println!("## Light sampling: one light per point, as a path tracer samples\n");
    println!(
        "Command: `cargo run --release -p manylights-report -- {SAMPLING}`. Lambert receivers, \
         no occluders, one thread. Relative variance = exact variance of the one-sample \
         estimate f / pmf (channels summed), sum f^2 / pmf - F^2 over every light, over the \
         squared exact value F^2, at each of {POINTS} points (mean and median over the \
         points). Time = per sample, over {SAMPLES} samples a point: choosing the light and \
         its probability, its exact term, the random number. Variance x time is the mean \
         squared error at equal time, up to the time given. \
         Methods: power (alias table; Shirley et al. 1996, pbrt-v4's PowerLightSampler); \
         pbrt-v4 (BVHLightSampler's descent with LightBounds::Importance of each node's box \
         and summed largest channels, leaf lights by their own importance); Cycles (light \
         tree, 0.5 (p_max + p_min), point-light groups' minimum importance 0); crate \
         (LightSampler: estimates clamped into certified bounds). All on the crate's tree (octree, up to 32 lights a \
         leaf). VPL room: the lights' profiles (cosine lobes, spots) \
         in every term and in the exact reference, the tree built from the emitters; \
         pbrt-v4's bounds as its area and spot lights' (cone of axes, theta_e), Cycles' \
         cones likewise; power sampling by intensity.\n"
    );
    for mut case in cases(quick)? {
        let emitters: Option<Vec<Emitter>> = (!case.emission.is_empty()).then(|| {
            case.lights
                .iter()
                .zip(&case.emission)
                .map(|(l, e)| l.with_emission(*e))
                .collect()
        });
        let tree = match &emitters {
            Some(emitters) => LightTree::build_emitters(emitters)?,
            None => LightTree::build(&case.lights)?,
        };
        let shading = tree.shading(Lambert::new(case.kd));
        case.exact = case
            .queries
            .par_iter()
            .map(|q| shading.exact_query(q, Unoccluded))
            .collect();
        run_case(&case, &tree, emitters.as_deref(), quick)?;
    }
    Ok(())
}

/// The tables of one scene.
fn run_case(
    case: &Case,
    tree: &LightTree,
    emitters: Option<&[Emitter]>,
    quick: bool,
) -> Result<(), Box<dyn Error>> {
    let mut rng = rng(SEED ^ 0x5A);
    let power = PowerPick::new(&case.lights);
    let pbrt = PbrtPick::new(tree, emitters);
    let cycles = CyclesPick::new(tree, emitters);
    let ours = CratePick {
        sampler: tree.sampler(Lambert::new(case.kd)),
    };
    let mut rows = Vec::new();
    let measured = [
        ("power", variances(&power, case, &mut rng)),
        ("pbrt-v4", variances(&pbrt, case, &mut rng)),
        ("Cycles", variances(&cycles, case, &mut rng)),
        ("crate", variances(&ours, case, &mut rng)),
    ];
    for (name, (relative, time)) in measured {
        let (mean, median) = mean_median(relative);
        rows.push(Row {
            name,
            mean,
            median,
            time,
        });
    }
    println!("### {} ({} points)\n", case.name, case.queries.len());
    println!(
        "| method | rel. variance, mean | median | time / sample | variance x time (pbrt = 1) \
         | MSE at equal time, pbrt / method |"
    );
    println!("|---|---|---|---|---|---|");
    let pbrt_row = rows[1].mean * rows[1].time;
    for r in &rows {
        let product = r.mean * r.time / pbrt_row;
        println!(
            "| {} | {:.3e} | {:.3e} | {:.2} us | {:.3} | {:.2}x |",
            r.name,
            r.mean,
            r.median,
            r.time * 1e6,
            product,
            1.0 / product
        );
    }
    println!();
    if !quick || case.lights.len() <= 100_000 {
        stochastic_table(case, tree, &rows[3])?;
    }
    Ok(())
}

/// The stochastic cut at a few thresholds: its relative variance, time per
/// call, how its reported variance compares with the measured one, and its
/// mean squared error at equal time against the crate's one-sample sampler.
fn stochastic_table(case: &Case, tree: &LightTree, sampler: &Row) -> Result<(), Box<dyn Error>> {
    let mut shading = tree.shading(Lambert::new(case.kd));
    let mut rng = rng(SEED ^ 0x57);
    println!(
        "Stochastic cut (certified cut, then two lights sampled per node it leaves), {} points, \
         {STOCHASTIC_CALLS} calls each:\n",
        STOCHASTIC_POINTS.min(case.queries.len())
    );
    println!(
        "| threshold | nodes sampled | time / call | rel. variance, mean | reported / measured \
         variance (per channel) | variance x time, sampler / stochastic |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, threshold) in STOCHASTIC_THRESHOLDS {
        let (mut relative, mut nodes, mut elapsed) = (Vec::new(), 0.0, 0.0);
        let (mut reported, mut measured) = (0.0, 0.0);
        for (query, exact) in case.queries.iter().zip(&case.exact).take(STOCHASTIC_POINTS) {
            let (mut s, mut s2, mut rep) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
            let (mut t, mut t2) = (0.0, 0.0);
            let started = Instant::now();
            for _ in 0..STOCHASTIC_CALLS {
                let r = shading
                    .shade_stochastic(query, threshold, Unoccluded, || rng.random::<f64>())?;
                (s, s2, rep) = (
                    s + r.radiance,
                    s2 + r.radiance * r.radiance,
                    rep + r.variance,
                );
                let x = sum(r.radiance);
                (t, t2) = (t + x, t2 + x * x);
                nodes += f64::from(r.nodes_sampled);
            }
            elapsed += started.elapsed().as_secs_f64();
            let n = STOCHASTIC_CALLS as f64;
            let unbiased = |s: f64, s2: f64| (s2 / n - (s / n) * (s / n)).max(0.0) * n / (n - 1.0);
            let exact = sum(*exact);
            if exact > 0.0 {
                relative.push(unbiased(t, t2) / (exact * exact));
                // Per channel: the reported variance is per channel.
                measured += unbiased(s.x, s2.x) + unbiased(s.y, s2.y) + unbiased(s.z, s2.z);
                reported += sum(rep) / n;
            }
        }
        let calls = (STOCHASTIC_CALLS * STOCHASTIC_POINTS.min(case.queries.len())) as f64;
        let time = elapsed / calls;
        let (mean, _) = mean_median(relative);
        println!(
            "| {name} | {:.1} | {:.2} us | {:.3e} | {:.2} | {:.1} |",
            nodes / calls,
            time * 1e6,
            mean,
            reported / measured,
            (sampler.mean * sampler.time) / (mean * time)
        );
    }
    println!();
    Ok(())
}
