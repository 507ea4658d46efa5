//! The GGX part: the microfacet shader at a certified 1% on the street
//! city at fixed density, 10^4 to 10^6 lights, roughness 0.02, 0.1 and
//! 0.5, against Phong of the matching lobe (`e = 2 / alpha^2 - 2`) and
//! against the vectorized exact sum of the same GGX model
//! ([`SoaLights::shade_ggx`]).
//!
//! ```text
//! cargo run --release -p manylights-report -- ggx
//! ```
//!
//! Shading points: the city's ground points (normals up, a quarter
//! tilted), each seen from a view 10 to 80 degrees above the ground in a
//! random direction, so that the mirror lobes sweep the lamps. `F0 =
//! 0.04` (a dielectric: plastic, wet asphalt). Every GGX result is checked
//! against the crate's `f64` exact sum (`Shading::exact_query`), and the
//! vectorized sum against it too.

use std::error::Error;
use std::hint::black_box;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{Ggx, LightTree, Phong, Query, ShadeResult, Threshold, Unoccluded};
use rand::RngExt;

use crate::config::SEED;
use crate::exact::{GgxMaterial, SoaLights};
use crate::scenes::{self, rng};

/// Numbers of lights, and shading points at each (few at 10^6, where the
/// `f64` reference sum is slow).
const SIZES: [(usize, usize); 3] = [(10_000, 64), (100_000, 32), (1_000_000, 8)];
/// Roughness values.
const ALPHAS: [f32; 3] = [0.02, 0.1, 0.5];
/// `F0` of the dielectric measured.
const F0: f32 = 0.04;
/// The certified relative target.
const TARGET: f64 = 0.01;
/// Timed passes over the points per configuration; the fastest is kept.
const PASSES: usize = 3;
/// Elevation of the views above the ground, degrees.
const ELEVATION: (f32, f32) = (10.0, 80.0);
/// Largest relative difference allowed between the vectorized `f32` sum
/// and the crate's `f64` reference (`f32` angles near the lobe's axis,
/// magnified by `2 / alpha`).
const SOA_TOLERANCE: f64 = 1e-3;

/// Fastest of [`PASSES`] passes of `f` over `count` points, seconds per
/// point.
fn time_per_point(count: usize, mut f: impl FnMut(usize)) -> f64 {
    (0..PASSES)
        .map(|_| {
            let start = Instant::now();
            (0..count).for_each(&mut f);
            start.elapsed().as_secs_f64() / count as f64
        })
        .fold(f64::INFINITY, f64::min)
}

/// Mean and maximum cost of the results.
fn costs(results: &[ShadeResult]) -> (f64, u32) {
    let total: f64 = results.iter().map(|r| f64::from(r.cost())).sum();
    let max = results.iter().map(ShadeResult::cost).max().unwrap_or(0);
    (total / results.len().max(1) as f64, max)
}

/// Prints the GGX table.
pub fn print_ggx() -> Result<(), Box<dyn Error>> {
    println!("## GGX: certified {TARGET} on the street city, F0 = {F0}");
    println!(
        "  `cargo run --release -p manylights-report -- ggx`; views {}-{} degrees up; \
         evaluations = node bounds + lights; time per point = fastest of {PASSES} passes",
        ELEVATION.0, ELEVATION.1
    );
    println!();
    println!(
        "| lights | points | alpha | GGX evals mean (max) | GGX us/pt | Phong e | Phong evals \
         mean (max) | Phong us/pt | exact SIMD us/pt | speed-up per point | worst error / allowed |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (n, count) in SIZES {
        let scene = scenes::city(n, count, SEED);
        let tree = LightTree::build(&scene.lights)?;
        let soa = SoaLights::new(&scene.lights);
        let mut views = rng(SEED ^ 0x66);
        let queries: Vec<Query<_>> = scene
            .points
            .iter()
            .map(|pt| {
                let up = views.random_range(ELEVATION.0..ELEVATION.1).to_radians();
                let around = views.random_range(0.0..std::f32::consts::TAU);
                let v = Vec3::new(up.cos() * around.cos(), up.cos() * around.sin(), up.sin());
                Query::new(pt.point, pt.normal)?.with_view(v)
            })
            .collect::<Result<_, _>>()?;
        for alpha in ALPHAS {
            let ggx = Ggx::try_new(Vec3::splat(F0), alpha)?;
            let mut shading = tree.shading(ggx);
            let threshold = Threshold::relative(TARGET);
            let exact: Vec<DVec3> = queries
                .iter()
                .map(|q| shading.exact_query(q, Unoccluded))
                .collect();
            let mut results = vec![ShadeResult::default(); queries.len()];
            let ggx_time = time_per_point(queries.len(), |i| {
                results[i] = shading
                    .shade_query(&queries[i], threshold, Unoccluded)
                    .expect("valid threshold");
            });
            // The worst ratio of actual error to what the contract allows
            // (the certified bound plus the rounding allowance); every
            // result must certify its exact sum.
            let mut worst = 0.0f64;
            for (r, &e) in results.iter().zip(&exact) {
                if !r.certifies(e) {
                    return Err(format!("GGX alpha {alpha} at {n} lights: {r:?} vs {e}").into());
                }
                let allowed = r.error_bound + e.abs() * ShadeResult::ROUNDING_ALLOWANCE;
                let ratio = ((r.radiance - e).abs() / allowed).max_element();
                worst = worst.max(if ratio.is_nan() { 0.0 } else { ratio });
            }
            let (ggx_mean, ggx_max) = costs(&results);

            let material = GgxMaterial {
                f0: Vec3::splat(F0),
                alpha,
            };
            let simd = |i: usize| {
                let q = &queries[i];
                let s = q.surface();
                soa.shade_ggx(&material, q.point(), s.normal.as_vec3(), s.view.as_vec3())
            };
            for (i, &e) in exact.iter().enumerate() {
                let d = ((simd(i) - e).abs() / e.max_element().max(1e-300)).max_element();
                if !(d <= SOA_TOLERANCE) {
                    return Err(format!("SIMD GGX sum off by {d:e} relative").into());
                }
            }
            let soa_time = time_per_point(queries.len(), |i| {
                black_box(simd(i));
            });

            let e = 2.0 / (alpha * alpha) - 2.0;
            let mut phong = tree.shading(Phong::try_new(Vec3::splat(F0), e)?);
            let mut phong_results = vec![ShadeResult::default(); queries.len()];
            let phong_time = time_per_point(queries.len(), |i| {
                phong_results[i] = phong
                    .shade_query(&queries[i], threshold, Unoccluded)
                    .expect("valid threshold");
            });
            let (phong_mean, phong_max) = costs(&phong_results);
            println!(
                "| {n} | {count} | {alpha} | {ggx_mean:.0} ({ggx_max}) | {:.1} | {e:.0} | \
                 {phong_mean:.0} ({phong_max}) | {:.1} | {:.1} | {:.1}x | {worst:.2} |",
                ggx_time * 1e6,
                phong_time * 1e6,
                soa_time * 1e6,
                soa_time / ggx_time
            );
        }
    }
    println!();
    Ok(())
}
