//! Criterion bench of the tree build: `LightTree::build` over city street
//! lamps (the report's layout, fixed density), 10^3 to 10^6 lights,
//! `LightTree::rebuild` (the same tree, in the memory of one built before)
//! and `LightTree::builder().build_parallel` (the same tree on rayon's
//! pool) from 10^5.
//!
//! ```text
//! cargo bench --bench build
//! ```
//!
//! Throughput is reported in lights per second; the report
//! (`cargo run --release -p manylights-report`) prints build time and memory
//! per light as well.

use std::hint::black_box;
use std::time::Duration;

use criterion::{
    BenchmarkId, Criterion, SamplingMode, Throughput, criterion_group, criterion_main,
};
use manylights::LightTree;

use manylights_report::scenes;

/// Numbers of lights.
const SIZES: [usize; 4] = [1_000, 10_000, 100_000, 1_000_000];
/// From this size on, a build takes a good fraction of a second: few flat
/// samples and a longer measurement window.
const LARGE: usize = 1_000_000;
const SEED: u64 = 1998;

fn build(c: &mut Criterion) {
    let mut group = c.benchmark_group("build");
    group.warm_up_time(Duration::from_millis(500));
    for n in SIZES {
        let lights = scenes::city_lights(n, SEED);
        group.throughput(Throughput::Elements(n as u64));
        if n >= LARGE {
            group
                .sampling_mode(SamplingMode::Flat)
                .sample_size(10)
                .measurement_time(Duration::from_secs(10));
        } else {
            group
                .sampling_mode(SamplingMode::Auto)
                .sample_size(20)
                .measurement_time(Duration::from_secs(2));
        }
        group.bench_with_input(BenchmarkId::new("one thread", n), &lights, |b, lights| {
            b.iter(|| LightTree::build(black_box(lights)).expect("valid lights"));
        });
        group.bench_with_input(BenchmarkId::new("rebuild", n), &lights, |b, lights| {
            let mut tree = LightTree::build(lights).expect("valid lights");
            b.iter(|| tree.rebuild(black_box(lights)).expect("valid lights"));
        });
        if n >= PARALLEL_FROM {
            group.bench_with_input(BenchmarkId::new("pool", n), &lights, |b, lights| {
                b.iter(|| {
                    LightTree::builder()
                        .build_parallel(black_box(lights))
                        .expect("valid lights")
                });
            });
        }
    }
    group.finish();
}

/// Sizes from which the parallel build is measured too (it builds smaller
/// trees on the calling thread).
const PARALLEL_FROM: usize = 100_000;

criterion_group!(benches, build);
criterion_main!(benches);
