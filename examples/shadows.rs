//! The night city with shadows: the buildings occlude the street lamps and
//! the lit windows.
//!
//! The host side of the crate's Warnock-style visibility: a ray-casting
//! hierarchy over the building boxes answers, for each node of the light
//! tree, whether the shaft from the shading point to the node's box is
//! certainly unoccluded, certainly blocked, or neither, and for single lights
//! casts one shadow ray. Every visible pixel is shaded by the tree
//! (`shade_occluded`) and by the exact shadowed sum (`shade_exact_occluded`,
//! one shadow ray per light per pixel, which is what limits the default size
//! below). The example prints times, errors against the certified bound, and
//! the visibility queries the tree asked per pixel against the one shadow ray
//! per light of the exact sum.
//!
//! ```text
//! cargo run --release --example shadows
//! cargo run --release --example shadows -- --lights 50000 --width 320 --height 180
//! ```
//!
//! Output: `out/shadows_tree.png`, `out/shadows_exact.png`,
//! `out/shadows_diff.png`.

#[path = "common/city.rs"]
mod city;
#[path = "common/mod.rs"]
mod common;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use city::{City, Hit, Shadows};
use common::{Camera, ErrorStats, Options, exposure, mean_per_pixel};
use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, ShadeError, ShadeResult, Threshold};
use rayon::prelude::*;

/// Blocks along each side of the city: a smaller city than `city`'s, since
/// the exact shadowed sum casts a shadow ray per light and pixel.
const BLOCKS: u32 = 16;
/// Default number of lights and image size: the exact render (lights x
/// pixels shadow rays) takes about a minute on two cores.
const DEFAULT_LIGHTS: usize = 20_000;
const DEFAULT_WIDTH: u32 = 256;
const DEFAULT_HEIGHT: u32 = 144;
/// Default relative threshold of the certified bound (1%).
const DEFAULT_THRESHOLD: f64 = 0.01;
/// Default output directory.
const DEFAULT_OUT: &str = "out";

/// The camera looks down into the streets from above one edge of the city.
const CAMERA_EYE: Vec3 = Vec3::new(250.0, -60.0, 160.0);
const CAMERA_TARGET: Vec3 = Vec3::new(330.0, 260.0, 0.0);
const CAMERA_FOV_DEGREES: f32 = 50.0;
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
    let hits = city.trace(&camera);
    let shadows = |h: &Hit| Shadows::new(&city, h.normal);

    // Unit albedo: Lambert is linear in kd, so each pixel's albedo multiplies
    // the radiance (and its bound) afterwards.
    let shader = Lambert::new(Vec3::ONE);
    let threshold = Threshold::relative(options.threshold);
    let row = options.width as usize;

    let start = Instant::now();
    let mut tree_results: Vec<Option<ShadeResult>> = vec![None; hits.len()];
    let mut answers = vec![[0u32; 3]; hits.len()];
    tree_results
        .par_chunks_mut(row)
        .zip(answers.par_chunks_mut(row))
        .zip(hits.par_chunks(row))
        .try_for_each_init(
            || tree.shading(shader),
            |shading, ((results, answers), hits)| -> Result<(), ShadeError> {
                for ((result, answer), hit) in results.iter_mut().zip(answers).zip(hits) {
                    if let Some(h) = hit {
                        let mut host = shadows(h);
                        *result =
                            Some(shading.shade_occluded(h.point, h.normal, threshold, &mut host)?);
                        *answer = host.answers;
                    }
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
                    hit.map(|h| {
                        exact_shading.shade_exact_occluded(h.point, h.normal, &mut shadows(&h))
                    })
                    .transpose()
                })
                .collect::<Vec<_>>()
        })
        .collect::<Result<_, _>>()?;
    let exact_time = start.elapsed();

    let stats = ErrorStats::new(&tree_results, &exact);
    let pixels = hits.iter().flatten().count();
    println!("city at night with shadows, Lambert");
    println!("  lights                        {:>12}", tree.len());
    println!(
        "  buildings                     {:>12}",
        city.buildings.len()
    );
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
    println!(
        "  classify queries per pixel    {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.classify_queries)
    );
    let pixel_count = pixels.max(1) as f64;
    for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
        let total: u64 = answers.iter().map(|a| u64::from(a[slot])).sum();
        println!(
            "    answered {name:<9} per pixel {:>12.1}",
            total as f64 / pixel_count
        );
    }
    println!(
        "  shadow rays per pixel, tree   {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.point_queries)
    );
    println!("  shadow rays per pixel, exact  {:>12}", tree.len());
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
    let paths =
        ["shadows_tree.png", "shadows_exact.png", "shadows_diff.png"].map(|f| options.out.join(f));
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
