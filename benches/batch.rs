//! Criterion bench of batch shading: one `Shading::shade_batch` call over
//! every ground pixel of a small camera view of the street city (100,000
//! lights), at two relative thresholds, beside `shade_query` point by point
//! on a sample of the same pixels; with the `rayon` feature, also
//! `shade_batch_parallel` over the thread pool.
//!
//! ```text
//! cargo bench --bench batch
//! cargo bench --bench batch --features rayon
//! ```
//!
//! Times are per call; the throughput line gives them per pixel.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use manylights::{Lambert, LightTree, Query, ShadeResult, Threshold, Unoccluded};

use manylights_report::camera::Camera;
use manylights_report::scenes::city_lights;

const SEED: u64 = 7;
const LIGHTS: usize = 100_000;
/// The view: 160 x 90 pixels from above the streets.
const WIDTH: u32 = 160;
const HEIGHT: u32 = 90;
/// Relative thresholds benchmarked.
const THRESHOLDS: [f64; 2] = [0.01, 0.05];
/// Every this many pixels are shaded point by point for comparison.
const SINGLE_STRIDE: usize = 16;

/// The ground point (z = 0, normal up) seen through every pixel that sees
/// the ground.
fn ground_queries(lights: &[manylights::PointLight]) -> Vec<Query> {
    let (lo, hi) = lights.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
    );
    let centre = ((lo + hi) * 0.5).with_z(0.0);
    let eye = centre + Vec3::new(-30.0, -80.0, 30.0);
    let camera = Camera::new(eye, centre, 60.0, WIDTH, HEIGHT);
    let mut queries = Vec::new();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let d = camera.ray(x, y);
            if d.z < 0.0 {
                let p = eye + d * (-eye.z / d.z);
                queries.push(Query::new(p.with_z(0.0), Vec3::Z).expect("a unit normal"));
            }
        }
    }
    queries
}

fn batch(c: &mut Criterion) {
    let lights = city_lights(LIGHTS, SEED);
    let tree = LightTree::build(&lights).expect("valid lights");
    let queries = ground_queries(&lights);
    let sample: Vec<Query> = queries.iter().step_by(SINGLE_STRIDE).cloned().collect();
    let shader = Lambert::new(Vec3::ONE);
    let mut results = vec![ShadeResult::default(); queries.len()];

    let mut group = c.benchmark_group("batch");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(10);
    for t in THRESHOLDS {
        let threshold = Threshold::relative(t);
        let mut shading = tree.shading(shader);
        group.throughput(Throughput::Elements(queries.len() as u64));
        group.bench_function(format!("shade_batch/city/{LIGHTS}/rel={t}"), |b| {
            b.iter(|| {
                shading
                    .shade_batch(black_box(&queries), threshold, Unoccluded, &mut results)
                    .expect("valid threshold")
            });
        });
        #[cfg(feature = "rayon")]
        {
            let pool = tree.shading(shader);
            group.bench_function(format!("shade_batch_parallel/city/{LIGHTS}/rel={t}"), |b| {
                b.iter(|| {
                    pool.shade_batch_parallel(
                        black_box(&queries),
                        threshold,
                        Unoccluded,
                        &mut results,
                    )
                    .expect("valid threshold")
                });
            });
        }
        group.throughput(Throughput::Elements(sample.len() as u64));
        group.bench_function(format!("shade_query/city/{LIGHTS}/rel={t}"), |b| {
            b.iter(|| {
                for q in &sample {
                    black_box(
                        shading
                            .shade_query(black_box(q), threshold, Unoccluded)
                            .expect("valid threshold"),
                    );
                }
            });
        });
    }
    group.finish();
}

criterion_group!(benches, batch);
criterion_main!(benches);
