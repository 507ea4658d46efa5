//! The scaling part: time per shading point against the number of lights,
//! the report's street-lamp city at fixed density, with build time and
//! memory per light.

use std::error::Error;
use std::time::Duration;

use manylights::{BoundKind, Lambert, LightTree, Threshold, Unoccluded};

use crate::config::{
    BUILD_LARGE_ABOVE, BUILD_REPEATS, BUILD_REPEATS_LARGE, Config, SCALING_ABSOLUTE,
    SCALING_RELATIVE, SCALING_SWEEP, SEED,
};
use crate::exact::SoaLights;
use crate::measure::{Method, Paired, Record, Sample, paired};
use crate::scenes::{self, Scene, ShadingPoint};
use crate::sweep::{
    Bench, build_tree, check_soa, measure_cut, measure_soa, median, query, recorder, references,
    soa_sample,
};

/// One size of the scaling part.
pub struct ScalingRow {
    /// Number of lights.
    pub lights: usize,
    /// Build time of the tree.
    pub build: Duration,
    /// The tree's memory, in bytes.
    pub memory: usize,
    /// The configurations measured at this size.
    pub records: Vec<Record>,
    /// The exact sum (first) against the tree at the relative threshold
    /// [`SCALING_RELATIVE`] with the tight bound (second), timed in
    /// alternating passes.
    pub alternating: Paired,
}

/// The exact sum and the tree at [`SCALING_RELATIVE`] (tight bound) timed
/// in alternating passes over the points, so that a load drifting during
/// the run moves both alike: about four budgets' worth of rounds, at least
/// 5 and at most 41, from the times of `records`.
fn alternate(
    records: &[Record],
    tree: &LightTree,
    shader: Lambert,
    soa: &SoaLights,
    scene: &Scene,
    bench: Bench<'_>,
) -> Paired {
    let relative = format!("t={SCALING_RELATIVE}");
    let time = |method: Method, parameter: &str| {
        records
            .iter()
            .find(|r| r.method == method && r.parameter == parameter)
            .map_or(0.0, |r| r.measurement.seconds_per_point)
    };
    let pass = (time(Method::ExactSoa, "-") + time(Method::TreeRelative, &relative))
        * bench.points.len() as f64;
    let rounds = if pass > 0.0 {
        (4.0 * bench.budget.as_secs_f64() / pass) as usize
    } else {
        5
    };
    let rounds = rounds.clamp(5, 41) | 1;
    let threshold = Threshold::relative(SCALING_RELATIVE);
    let mut shading = tree.shading(shader.with_bound(BoundKind::Series));
    paired(
        bench.points.len(),
        rounds,
        |i| soa_sample(soa, scene, &bench.points[i]),
        |i| {
            let r = shading.shade_query(&query(&bench.points[i]), threshold, Unoccluded);
            Sample::cut(r.expect("scene thresholds are valid"), None)
        },
    )
}

/// Measures the exact sum and the cut at fixed thresholds at every size of
/// `cfg.scaling_sizes`.
pub fn run_scaling(cfg: &Config) -> Result<Vec<ScalingRow>, Box<dyn Error>> {
    println!(
        "## Scaling: city layout at fixed lamp density (the area grows with the number of \
         lights), {} ground points per size",
        cfg.scaling_points
    );
    println!(
        "  thresholds: relative {SCALING_RELATIVE} (tight and paper's bound), absolute \
         {SCALING_ABSOLUTE} radiance units (tight)"
    );
    println!(
        "  build times: one thread, the median of {BUILD_REPEATS} builds ({BUILD_REPEATS_LARGE} \
         above {BUILD_LARGE_ABOVE} lights)"
    );
    let unoccluded = None::<&dyn Fn(&ShadingPoint) -> Unoccluded>;
    let mut rows = Vec::new();
    for &n in cfg.scaling_sizes {
        let scene = scenes::city(n, cfg.scaling_points, SEED);
        let shader = Lambert::new(scene.material.kd);
        let (tree, build) = build_tree(&scene)?;
        let (points, refs) = references(&tree, shader, &scene.points, |_| Unoccluded);
        let soa = SoaLights::new(&scene.lights);
        check_soa(&soa, &scene, &points, &refs)?;
        let median_radiance = median(refs.iter().map(|r| r.max_element()).collect());
        println!(
            "  {n:>8} lights: build {:>8.1} ms = {:>5.0} ns/light, memory {:>6.1} bytes/light, \
             median radiance {median_radiance:.3}",
            build.as_secs_f64() * 1e3,
            build.as_secs_f64() * 1e9 / n as f64,
            tree.memory_bytes() as f64 / n as f64
        );
        let mut records = Vec::new();
        let mut record = recorder("city", n, &mut records);
        let bench = Bench::new(&points, &refs, cfg.budget);
        record(
            Method::ExactSoa,
            "-".into(),
            measure_soa(&soa, &scene, bench),
        );
        let cut = |kind, threshold| {
            measure_cut(&tree, shader.with_bound(kind), bench, threshold, unoccluded)
        };
        let relative = Threshold::relative(SCALING_RELATIVE);
        let m = cut(BoundKind::Paper, relative);
        record(Method::TreePaper, format!("t={SCALING_RELATIVE}"), m);
        for t in SCALING_SWEEP {
            let m = cut(BoundKind::Series, Threshold::relative(t));
            record(Method::TreeRelative, format!("t={t}"), m);
        }
        let m = cut(BoundKind::Series, Threshold::absolute(SCALING_ABSOLUTE));
        record(Method::TreeAbsolute, format!("abs={SCALING_ABSOLUTE}"), m);
        drop(record);
        let alternating = alternate(&records, &tree, shader, &soa, &scene, bench);
        println!(
            "  alternating passes, exact sum against the tree at t={SCALING_RELATIVE}: {:.2} and \
             {:.2} us/pt (medians), speed-up {:.1}x (median of {} rounds)",
            alternating.first * 1e6,
            alternating.second * 1e6,
            1.0 / alternating.ratio,
            alternating.rounds
        );
        rows.push(ScalingRow {
            lights: n,
            build,
            memory: tree.memory_bytes(),
            records,
            alternating,
        });
    }
    Ok(rows)
}

/// The plotted fixed-threshold series a scaling record belongs to, if any.
pub fn scaling_series_of(r: &Record) -> Option<String> {
    let relative = format!("t={SCALING_RELATIVE}");
    match r.method {
        Method::ExactSoa => Some(r.method.label().to_string()),
        Method::TreePaper | Method::TreeRelative if r.parameter == relative => {
            Some(format!("{} = {SCALING_RELATIVE}", r.method.label()))
        }
        Method::TreeAbsolute => Some(format!("{} = {SCALING_ABSOLUTE}", r.method.label())),
        _ => None,
    }
}
