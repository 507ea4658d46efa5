//! Criterion bench of how shading one point scales with the number of
//! lights: the street city at 10^4, 10^5 and 10^6 lights (fixed lamp
//! density, so the area grows with the lights), `Shading::shade` at a
//! certified 1% beside the report's vectorized `f32` exact sum on the same
//! points. The speed-up at each size is the ratio of the two times; the
//! report's `scaling` part measures the same in alternating passes.
//!
//! ```text
//! cargo bench --bench scaling
//! ```
//!
//! One iteration shades one point; successive iterations cycle through the
//! scene's shading points, so the time is an average over them.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use manylights::{Lambert, LightTree, Threshold};
use manylights_report::exact::SoaLights;
use manylights_report::scenes;

const SEED: u64 = 1998;
/// Shading points cycled through per size.
const POINTS: usize = 128;
/// The certified relative threshold.
const THRESHOLD: f64 = 0.01;

fn scaling(c: &mut Criterion) {
    let mut group = c.benchmark_group("scaling");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20);
    for n in [10_000, 100_000, 1_000_000] {
        let scene = scenes::city(n, POINTS, SEED);
        let tree = LightTree::build(&scene.lights).expect("valid lights");
        let mut shading = tree.shading(Lambert::new(scene.material.kd));
        let threshold = Threshold::relative(THRESHOLD);
        let points = &scene.points;
        group.bench_function(BenchmarkId::new("tree, certified 1%", n), |b| {
            let mut i = 0;
            b.iter(|| {
                let pt = black_box(&points[i % points.len()]);
                i += 1;
                shading
                    .shade(pt.point, pt.normal, threshold)
                    .expect("valid point")
            });
        });
        let soa = SoaLights::new(&scene.lights);
        group.bench_function(BenchmarkId::new("SIMD exact sum", n), |b| {
            let mut i = 0;
            b.iter(|| {
                let pt = black_box(&points[i % points.len()]);
                i += 1;
                soa.shade(&scene.material, pt.point, pt.normal, pt.view)
            });
        });
    }
    group.finish();
}

criterion_group!(benches, scaling);
criterion_main!(benches);
