//! The scaling part: time per shading point against the number of lights,
//! the report's street-lamp city at fixed density, with build time and
//! memory per light.

use std::error::Error;
use std::time::Duration;

use manylights::{BoundKind, Lambert, Threshold, Unoccluded};

use crate::config::{Config, SCALING_ABSOLUTE, SCALING_RELATIVE, SCALING_SWEEP, SEED};
use crate::exact::SoaLights;
use crate::measure::{Method, Record};
use crate::scenes::{self, ShadingPoint};
use crate::sweep::{
    Bench, build_tree, check_soa, measure_cut, measure_soa, median, recorder, references,
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
            let m = cut(BoundKind::Tight, Threshold::relative(t));
            record(Method::TreeRelative, format!("t={t}"), m);
        }
        let m = cut(BoundKind::Tight, Threshold::absolute(SCALING_ABSOLUTE));
        record(Method::TreeAbsolute, format!("abs={SCALING_ABSOLUTE}"), m);
        drop(record);
        rows.push(ScalingRow {
            lights: n,
            build,
            memory: tree.memory_bytes(),
            records,
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
