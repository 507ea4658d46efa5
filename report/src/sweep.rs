//! Every configuration of every method on one unoccluded scene, and what the
//! occluded scene and the scaling part share with it: references, tree
//! builds, the crate's cut and the Monte Carlo sweeps, measured and printed.

use std::error::Error;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

use glam::DVec3;
use manylights::query::WithView;
use manylights::shader::Shader;
use manylights::{
    BoundKind, Combined, Lambert, LightTree, Phong, Query, Threshold, Unoccluded, Visibility,
};
use rayon::prelude::*;

use crate::config::{
    Config, PAPER_RELATIVE, PER_NODE, SAMPLE_COUNTS, SEED, SOA_TOLERANCE, TREE_ABSOLUTE,
    TREE_RELATIVE, build_repeats,
};
use crate::exact::SoaLights;
use crate::measure::{self, Counted, Measurement, Method, Record, Sample, measure};
use crate::sampling::{LightSampler, PowerSampler, TreeSampler};
use crate::scenes::{self, Scene, ShadingPoint};

/// What every configuration of a scene is measured on: the shading points,
/// their exact values, and the time budget of the repeated passes.
#[derive(Clone, Copy)]
pub struct Bench<'a> {
    /// The shading points some light reaches.
    pub points: &'a [ShadingPoint],
    /// Their exact values.
    pub refs: &'a [DVec3],
    /// Time budget of one configuration's repeated passes.
    pub budget: Duration,
}

impl<'a> Bench<'a> {
    /// The points with their exact values, `budget` per configuration.
    pub fn new(points: &'a [ShadingPoint], refs: &'a [DVec3], budget: Duration) -> Self {
        Self {
            points,
            refs,
            budget,
        }
    }
}

/// The query of a shading point, with its view (Lambert ignores it).
#[inline]
pub fn query(pt: &ShadingPoint) -> Query<WithView> {
    Query::new(pt.point, pt.normal)
        .and_then(|q| q.with_view(pt.view))
        .expect("scene shading points are valid")
}

/// The crate's `f64` exact sum at every point through the host `host(pt)`
/// (in parallel: not timed), keeping only the points some light reaches:
/// where every light is below the tangent plane (or hidden) the exact value
/// is 0 and a relative error means nothing. Returns the kept points and
/// their references.
pub fn references<S, V>(
    tree: &LightTree,
    shader: S,
    points: &[ShadingPoint],
    host: impl Fn(&ShadingPoint) -> V + Sync,
) -> (Vec<ShadingPoint>, Vec<DVec3>)
where
    S: Shader + Copy + Send + Sync,
    V: Visibility,
{
    let exact: Vec<DVec3> = points
        .par_iter()
        .map(|pt| tree.shading(shader).exact_query(&query(pt), host(pt)))
        .collect();
    points
        .iter()
        .zip(exact)
        .filter(|(_, e)| e.max_element() > 0.0)
        .unzip()
}

/// Builds the tree, timing it: the median of [`build_repeats`] builds.
pub fn build_tree(scene: &Scene) -> Result<(LightTree, Duration), Box<dyn Error>> {
    let repeats = build_repeats(scene.lights.len());
    let mut times = Vec::with_capacity(repeats);
    let mut tree = None;
    for _ in 0..repeats {
        // The previous tree is dropped first, so that each build finds the
        // same free memory.
        drop(tree.take());
        let t = Instant::now();
        let built = LightTree::build(&scene.lights)?;
        times.push(t.elapsed().as_secs_f64());
        tree = Some(built);
    }
    let tree = tree.expect("at least one build");
    Ok((tree, Duration::from_secs_f64(median(times))))
}

/// Checks the vectorized exact sum against the references; returns the
/// largest relative difference.
pub fn check_soa(
    soa: &SoaLights,
    scene: &Scene,
    points: &[ShadingPoint],
    refs: &[DVec3],
) -> Result<f64, Box<dyn Error>> {
    let worst = points
        .iter()
        .zip(refs)
        .map(|(pt, &exact)| {
            let v = soa.shade(&scene.material, pt.point, pt.normal, pt.view);
            measure::relative(v - exact, exact)
        })
        // A NaN anywhere makes the result NaN (f64::max would skip it).
        .fold(0.0, |a: f64, d| if d.is_nan() || d > a { d } else { a });
    if worst.is_nan() || worst > SOA_TOLERANCE {
        return Err(format!(
            "{}: the vectorized exact sum differs from the exact query by {worst:.2e} relative",
            scene.name
        )
        .into());
    }
    Ok(worst)
}

/// The vectorized exact sum over every light, measured.
pub fn measure_soa(soa: &SoaLights, scene: &Scene, bench: Bench<'_>) -> Measurement {
    measure(bench.refs, bench.budget, |i| {
        soa_sample(soa, scene, &bench.points[i])
    })
}

/// The vectorized exact sum at `pt`, as a sample (its cost: every light).
pub fn soa_sample(soa: &SoaLights, scene: &Scene, pt: &ShadingPoint) -> Sample {
    let radiance = soa.shade(&scene.material, pt.point, pt.normal, pt.view);
    Sample::estimate(radiance, scene.lights.len() as u32, None)
}

/// The median of `v`.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The crate's cut at `threshold` over `points`, measured; with the host
/// `host(pt)` in an occluded scene, made per point inside the timed loop,
/// its classifications and shadow rays counted. The session is created once
/// and reused, as a renderer would.
pub fn measure_cut<S: Shader, V: Counted>(
    tree: &LightTree,
    shader: S,
    bench: Bench<'_>,
    threshold: Threshold,
    host: Option<&dyn Fn(&ShadingPoint) -> V>,
) -> Measurement {
    let mut shading = tree.shading(shader);
    measure(bench.refs, bench.budget, |i| {
        let pt = &bench.points[i];
        let q = query(pt);
        let (r, queries) = match host {
            Some(host) => {
                let mut host = host(pt);
                let r = shading.shade_query(&q, threshold, &mut host);
                (r, Some(host.queries()))
            }
            None => (shading.shade_query(&q, threshold, Unoccluded), None),
        };
        Sample::cut(r.expect("scene thresholds are valid"), queries)
    })
}

/// Both Monte Carlo samplers (power, then down `tree`) measured at every
/// sample count of `counts` and recorded, with the same seed per point for every count;
/// shadow rays through `host(pt)` in an occluded scene.
pub fn sample_sweeps<S: Shader, V: Visibility>(
    record: &mut impl FnMut(Method, String, Measurement),
    tree: &LightTree,
    shader: &S,
    bench: Bench<'_>,
    counts: &[u32],
    host: Option<&dyn Fn(&ShadingPoint) -> V>,
) {
    let power = PowerSampler::new(tree.lights());
    for (n, m) in sample_sweep(&power, shader, bench, counts, host) {
        record(Method::PowerSampling, format!("n={n}"), m);
    }
    let tree_sampler = TreeSampler::new(tree);
    for (n, m) in sample_sweep(&tree_sampler, shader, bench, counts, host) {
        record(Method::TreeSampling, format!("n={n}"), m);
    }
}

/// A Monte Carlo sampler measured at every sample count.
fn sample_sweep<L: LightSampler, S: Shader, V: Visibility>(
    sampler: &L,
    shader: &S,
    bench: Bench<'_>,
    counts: &[u32],
    host: Option<&dyn Fn(&ShadingPoint) -> V>,
) -> Vec<(u32, Measurement)> {
    counts
        .iter()
        .map(|&n| {
            let m = measure(bench.refs, bench.budget, |i| {
                let pt = &bench.points[i];
                let mut rng = scenes::rng(SEED ^ ((i as u64) << 20));
                let q = query(pt);
                let s = q.surface();
                let (radiance, rays) = match host {
                    Some(host) => {
                        let mut host = host(pt);
                        let visible = |light| host.visible(pt.point, light);
                        sampler.estimate(shader, s, &mut rng, n, visible)
                    }
                    None => sampler.estimate(shader, s, &mut rng, n, |_| true),
                };
                Sample::estimate(radiance, n, host.map(|_| rays))
            });
            (n, m)
        })
        .collect()
}

/// Prints a scene's heading and its tree's size and build time.
pub fn print_header(scene: &Scene, tree: &LightTree, build: Duration) {
    println!("## Scene `{}`: {}", scene.name, scene.description);
    print_tree(tree, build);
}

/// Prints the tree's line of a scene's header: nodes, depth, build time
/// and memory.
pub fn print_tree(tree: &LightTree, build: Duration) {
    println!(
        "  tree: {} nodes, depth {}, built in {:.1} ms ({:.0} ns/light), {:.1} bytes/light",
        tree.nodes().len(),
        tree.depth(),
        build.as_secs_f64() * 1e3,
        build.as_secs_f64() * 1e9 / tree.len() as f64,
        tree.memory_bytes() as f64 / tree.len() as f64
    );
}

/// A closure that prints a measurement and adds it to `rows` as a record of
/// scene `name` with `lights` lights.
pub fn recorder<'a>(
    name: &'a str,
    lights: usize,
    rows: &'a mut Vec<Record>,
) -> impl FnMut(Method, String, Measurement) + 'a {
    move |method, parameter, m| {
        println!("  {}", describe(method, &parameter, &m));
        rows.push(Record {
            scene: name.to_string(),
            lights,
            method,
            parameter,
            measurement: m,
        });
    }
}

/// `abs=1e-3*median`, or `abs=0 (exact)`.
pub fn absolute_parameter(fraction: f64) -> String {
    if fraction == 0.0 {
        "abs=0 (exact)".into()
    } else {
        format!("abs={fraction:e}*median")
    }
}

/// One printed line per configuration.
fn describe(method: Method, parameter: &str, m: &Measurement) -> String {
    let mut line = format!(
        "{:<40} {:<18} {:>10.2} us/pt  err mean {:.2e} max {:.2e}",
        method.label(),
        parameter,
        m.seconds_per_point * 1e6,
        m.mean_error,
        m.max_error
    );
    if let Some((mean, max)) = m.bound {
        let _ = write!(line, "  bound mean {mean:.2e} max {max:.2e}");
    }
    let _ = write!(line, "  cost {:.0}", m.mean_cost);
    if let Some((rays, classify)) = m.queries {
        let _ = write!(line, "  rays {rays:.0} classify {classify:.0}");
    }
    if m.violations > 0 {
        let _ = write!(line, "  WARNING: {} points break the bound", m.violations);
    }
    line
}

/// Every configuration of every method on one unoccluded scene.
pub fn run_scene(scene: &Scene, cfg: &Config) -> Result<Vec<Record>, Box<dyn Error>> {
    let kd = scene.material.kd;
    match scene.material.specular {
        None => sweep(scene, cfg, |kind| Lambert::new(kd).with_bound(kind)),
        Some(spec) => sweep(scene, cfg, |kind| {
            Combined::new(
                Lambert::new(kd).with_bound(kind),
                Phong::new(spec.ks, spec.exponent as f32),
            )
        }),
    }
}

/// [`run_scene`] for the scene's shader, made with either bound by `make`.
fn sweep<S: Shader + Copy + Send + Sync>(
    scene: &Scene,
    cfg: &Config,
    make: impl Fn(BoundKind) -> S,
) -> Result<Vec<Record>, Box<dyn Error>> {
    let (tree, build) = build_tree(scene)?;
    print_header(scene, &tree, build);
    let (points, refs) = references(&tree, make(BoundKind::Series), &scene.points, |_| {
        Unoccluded
    });
    let dropped = scene.points.len() - points.len();
    let median_radiance = median(refs.iter().map(|r| r.max_element()).collect());
    let soa = SoaLights::new(&scene.lights);
    let soa_error = check_soa(&soa, scene, &points, &refs)?;
    println!(
        "  {} points ({dropped} dropped: no light above their tangent plane), median exact \
         radiance {median_radiance:.3e}; vectorized exact sum within {soa_error:.1e} of exact_query",
        points.len()
    );

    let mut rows = Vec::new();
    let mut record = recorder(scene.name, scene.lights.len(), &mut rows);
    let bench = Bench::new(&points, &refs, cfg.budget);
    record(
        Method::ExactSoa,
        "-".into(),
        measure_soa(&soa, scene, bench),
    );
    // A query with a view serves Lambert and Lambert + Phong alike (Lambert
    // ignores the view).
    let unoccluded = None::<&dyn Fn(&ShadingPoint) -> Unoccluded>;
    let cut = |kind, threshold| measure_cut(&tree, make(kind), bench, threshold, unoccluded);
    for t in PAPER_RELATIVE {
        let m = cut(BoundKind::Paper, Threshold::relative(t));
        record(Method::TreePaper, format!("t={t}"), m);
    }
    for t in TREE_RELATIVE {
        let m = cut(BoundKind::Series, Threshold::relative(t));
        record(Method::TreeRelative, format!("t={t}"), m);
    }
    for f in TREE_ABSOLUTE {
        let m = cut(BoundKind::Series, Threshold::absolute(f * median_radiance));
        record(Method::TreeAbsolute, absolute_parameter(f), m);
    }
    for t in PER_NODE {
        let m = cut(BoundKind::Series, Threshold::per_node(t));
        record(Method::PerNode, format!("t={t}"), m);
    }

    let shader = make(BoundKind::Series);
    sample_sweeps(
        &mut record,
        &tree,
        &shader,
        bench,
        &SAMPLE_COUNTS,
        unoccluded,
    );
    drop(record);
    Ok(rows)
}
