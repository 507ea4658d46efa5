//! A city at night lit by 100,000 point lights: street lamps along a grid of
//! streets and lit windows on box buildings, seen from above at an angle.
//!
//! Every visible pixel (one primary ray, no shadows) is shaded twice with the
//! Lambert model: by the light tree at a relative threshold on its certified
//! error bound, and by the exact sum over every light. The example writes
//! both images and an enhanced-contrast difference image, prints the times,
//! the errors actually made against the certified bound, and checks that the
//! bound holds at every pixel.
//!
//! ```text
//! cargo run --release --example city
//! cargo run --release --example city -- --lights 1000000 --width 160 --height 90 \
//!     --threshold 0.02 --out out
//! ```
//!
//! The defaults (100,000 lights, 320x180) take about a minute; the exact
//! render's time grows with lights times pixels.
//!
//! Output: `out/city_tree.png`, `out/city_exact.png`, `out/city_diff.png`.

#[path = "common/city.rs"]
mod city;
#[path = "common/mod.rs"]
mod common;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use city::{City, Hit};
use common::{Camera, ErrorStats, Options, exposure, mean_per_pixel};
use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, ShadeError, ShadeResult, Threshold};
use rayon::prelude::*;

/// Blocks along each side of the city (2 km at 40 m per block).
const BLOCKS: u32 = 50;
/// Default number of lights.
const DEFAULT_LIGHTS: usize = 100_000;
/// Default image size: both renders together take about a minute on two
/// busy cores.
const DEFAULT_WIDTH: u32 = 320;
const DEFAULT_HEIGHT: u32 = 180;
/// Default relative threshold of the certified bound (1%).
const DEFAULT_THRESHOLD: f64 = 0.01;
/// Default output directory.
const DEFAULT_OUT: &str = "out";

/// The camera hovers above the southern streets, looking north across the
/// city to its far edge.
const CAMERA_EYE: Vec3 = Vec3::new(760.0, 120.0, 160.0);
const CAMERA_TARGET: Vec3 = Vec3::new(870.0, 640.0, 0.0);
const CAMERA_FOV_DEGREES: f32 = 45.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(Options {
        lights: DEFAULT_LIGHTS,
        width: DEFAULT_WIDTH,
        height: DEFAULT_HEIGHT,
        threshold: DEFAULT_THRESHOLD,
        out: PathBuf::from(DEFAULT_OUT),
    });
    let city = City::new(BLOCKS, options.lights);

    let start = Instant::now();
    let tree = LightTree::build(&city.lights)?;
    let build_time = start.elapsed();

    let camera = Camera::new(
        CAMERA_EYE,
        CAMERA_TARGET,
        CAMERA_FOV_DEGREES,
        options.width,
        options.height,
    );
    let start = Instant::now();
    let hits = city.trace(&camera);
    let trace_time = start.elapsed();

    // Unit albedo: Lambert is linear in kd, so each pixel's albedo multiplies
    // the radiance (and its bound) afterwards.
    let shader = Lambert::new(Vec3::ONE);
    let threshold = Threshold::relative(options.threshold);
    let row = options.width as usize;

    let start = Instant::now();
    let mut tree_results: Vec<Option<ShadeResult>> = vec![None; hits.len()];
    tree_results
        .par_chunks_mut(row)
        .zip(hits.par_chunks(row))
        .try_for_each_init(
            || tree.shading(shader),
            |shading, (results, hits)| -> Result<(), ShadeError> {
                for (result, hit) in results.iter_mut().zip(hits) {
                    *result = hit
                        .map(|h| shading.shade(h.point, h.normal, threshold))
                        .transpose()?;
                }
                Ok(())
            },
        )?;
    let tree_time = start.elapsed();

    let start = Instant::now();
    let exact_shading = tree.shading(shader);
    let exact: Vec<Option<DVec3>> = hits
        .par_chunks(row)
        .flat_map_iter(|hits| {
            hits.iter()
                .map(|hit| {
                    hit.map(|h| exact_shading.shade_exact(h.point, h.normal))
                        .transpose()
                })
                .collect::<Vec<_>>()
        })
        .collect::<Result<_, _>>()?;
    let exact_time = start.elapsed();

    let stats = ErrorStats::new(&tree_results, &exact);
    let pixels = hits.iter().flatten().count();
    println!("city at night, Lambert, no shadows");
    println!("  lights                        {:>12}", tree.len());
    println!(
        "  image                         {:>12}",
        format!("{}x{}", options.width, options.height)
    );
    println!("  shaded pixels                 {pixels:>12}");
    println!("  threshold (relative)          {:>12}", options.threshold);
    println!(
        "  tree build                    {:>10.3} s",
        build_time.as_secs_f64()
    );
    println!(
        "  primary rays                  {:>10.3} s",
        trace_time.as_secs_f64()
    );
    println!(
        "  tree render                   {:>10.3} s",
        tree_time.as_secs_f64()
    );
    println!(
        "  exact render                  {:>10.3} s",
        exact_time.as_secs_f64()
    );
    println!(
        "  speed-up                      {:>11.2}x",
        exact_time.as_secs_f64() / tree_time.as_secs_f64()
    );
    println!(
        "  mean relative error           {:>12.3e}",
        stats.mean_relative
    );
    println!(
        "  max relative error            {:>12.3e}",
        stats.max_relative
    );
    println!(
        "  mean certified bound / value  {:>12.3e}",
        stats.mean_bound_relative
    );
    println!(
        "  nodes evaluated per pixel     {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.nodes_evaluated)
    );
    println!(
        "  lights evaluated per pixel    {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.lights_evaluated)
    );
    println!("  pixels violating the bound    {:>12}", stats.violations);

    let albedo = |hit: &Option<Hit>| hit.map_or(DVec3::ZERO, |h| h.albedo.as_dvec3());
    let tree_image: Vec<DVec3> = tree_results
        .iter()
        .zip(&hits)
        .map(|(r, h)| r.map_or(DVec3::ZERO, |r| r.radiance) * albedo(h))
        .collect();
    let exact_image: Vec<DVec3> = exact
        .iter()
        .zip(&hits)
        .map(|(e, h)| e.unwrap_or(DVec3::ZERO) * albedo(h))
        .collect();
    let exposure = exposure(&exact_image, EXPOSURE_PERCENTILE);
    std::fs::create_dir_all(&options.out)?;
    let (w, h) = (options.width, options.height);
    let paths = ["city_tree.png", "city_exact.png", "city_diff.png"].map(|f| options.out.join(f));
    common::write_radiance(&paths[0], w, h, &tree_image, exposure)?;
    common::write_radiance(&paths[1], w, h, &exact_image, exposure)?;
    common::write_difference(
        &paths[2],
        w,
        h,
        &tree_image,
        &exact_image,
        options.threshold,
    )?;
    for path in &paths {
        println!("wrote {}", path.display());
    }
    if stats.violations > 0 {
        return Err(format!("{} pixels violate the certified bound", stats.violations).into());
    }
    Ok(())
}
