//! Criterion bench of shading one point: `Shading::shade` (or `shade_query`
//! with a view for the glossy scene) on each of the report's scenes at two
//! relative thresholds, and a pair showing that visibility costs nothing
//! when it is `Unoccluded`: `shade_query(.., Unoccluded)` against
//! `shade_query(.., &mut Unoccluded)` (a host passed by reference).
//!
//! ```text
//! cargo bench --bench shade
//! ```
//!
//! One iteration shades one point; successive iterations cycle through the
//! scene's shading points, so the time is an average over them.

use std::hint::black_box;
use std::time::Duration;

use criterion::{
    BenchmarkGroup, Criterion, criterion_group, criterion_main, measurement::WallTime,
};
use manylights::{Combined, Lambert, LightTree, Phong, Query, ShadeResult, Threshold, Unoccluded};

use manylights_report::scenes::{self, Scene, ShadingPoint};

const SEED: u64 = 1998;
/// Shading points cycled through per scene.
const POINTS: usize = 64;
/// Relative thresholds benchmarked on every scene.
const THRESHOLDS: [f64; 2] = [0.01, 0.001];

/// Benchmarks `shade` over `points` (shading points or queries), one point
/// per iteration.
fn cycle<P>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: String,
    points: &[P],
    mut shade: impl FnMut(&P) -> ShadeResult,
) {
    group.bench_function(id, |b| {
        let mut i = 0;
        b.iter(|| {
            let r = shade(black_box(&points[i % points.len()]));
            i += 1;
            r
        });
    });
}

fn shade(c: &mut Criterion) {
    let scenes: [Scene; 4] = [
        scenes::city(100_000, POINTS, SEED),
        scenes::chandelier(50_000, POINTS, SEED),
        scenes::strings(20_000, POINTS, SEED),
        scenes::specular(20_000, POINTS, SEED),
    ];
    let mut group = c.benchmark_group("shade");
    group
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .sample_size(20);
    for scene in &scenes {
        let tree = LightTree::build(&scene.lights).expect("valid lights");
        let lambert = Lambert::new(scene.material.kd);
        for t in THRESHOLDS {
            let threshold = Threshold::relative(t);
            let id = format!("{}/{}/rel={t}", scene.name, scene.lights.len());
            match scene.material.specular {
                None => {
                    let mut shading = tree.shading(lambert);
                    cycle(&mut group, id, &scene.points, |pt| {
                        shading
                            .shade(pt.point, pt.normal, threshold)
                            .expect("valid point")
                    });
                }
                Some(spec) => {
                    let phong = Phong::new(spec.ks, spec.exponent as f32);
                    let mut shading = tree.shading(Combined::new(lambert, phong));
                    cycle(&mut group, id, &scene.points, |pt: &ShadingPoint| {
                        let query =
                            Query::new(pt.point, pt.normal).and_then(|q| q.with_view(pt.view));
                        let query = query.expect("valid point");
                        shading
                            .shade_query(&query, threshold, Unoccluded)
                            .expect("valid threshold")
                    });
                }
            }
        }
    }
    group.finish();

    // Unoccluded compiles every visibility call away, by value or through a
    // reference: both should time the same.
    let city = &scenes[0];
    let tree = LightTree::build(&city.lights).expect("valid lights");
    let threshold = Threshold::relative(THRESHOLDS[0]);
    let mut group = c.benchmark_group("unoccluded");
    group
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .sample_size(20);
    let mut shading = tree.shading(Lambert::new(city.material.kd));
    let queries: Vec<Query> = city
        .points
        .iter()
        .map(|pt| Query::new(pt.point, pt.normal).expect("valid point"))
        .collect();
    cycle(&mut group, "by value".into(), &queries, |q| {
        shading
            .shade_query(q, threshold, Unoccluded)
            .expect("valid threshold")
    });
    cycle(&mut group, "by reference".into(), &queries, |q| {
        shading
            .shade_query(q, threshold, &mut Unoccluded)
            .expect("valid threshold")
    });
    group.finish();
}

criterion_group!(benches, shade);
criterion_main!(benches);
