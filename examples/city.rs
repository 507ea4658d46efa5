//! A city at night lit by 100,000 point lights: street lamps along a grid of
//! streets and lit windows on box buildings, seen from above at an angle.
//!
//! Every visible pixel (one primary ray) is shaded twice with the Lambert
//! model: by the light tree at a relative threshold on its certified error
//! bound, and by the exact sum over every light. The example writes both
//! images and an enhanced-contrast difference image, prints the times, the
//! errors actually made against the certified bound, and checks that the
//! bound holds at every pixel.
//!
//! With `--shadows` the buildings cast shadows: a smaller city (20,000
//! lights), the host's conservative classifier ([`city::Shadows`]) answering
//! the tree's Warnock-style questions and casting its shadow rays, against
//! the exact shadowed sum that casts one shadow ray per light and pixel; the
//! table adds the visibility queries.
//!
//! ```text
//! cargo run --release --example city
//! cargo run --release --example city -- --shadows
//! cargo run --release --example city -- --lights 1000000 --width 160 --height 90 \
//!     --threshold 0.02 --out out
//! ```
//!
//! Output: `out/city_{tree,exact,diff}.png`, or `out/shadows_{tree,exact,diff}.png`
//! with `--shadows`.

#[path = "common/city.rs"]
mod city;
#[path = "common/mod.rs"]
mod common;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use city::{City, Hit, Shadows};
use common::{Camera, ErrorStats, Options, exposure, mean_per_pixel, print_comparison, print_row};
use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, ShadeError, ShadeResult, Threshold};
use rayon::prelude::*;

/// One of the two scenes the example renders.
struct Setup {
    /// Blocks along each side of the city (40 m each).
    blocks: u32,
    /// Default number of lights and image size.
    lights: usize,
    width: u32,
    height: u32,
    camera_eye: Vec3,
    camera_target: Vec3,
    camera_fov_degrees: f32,
    /// Prefix of the image files, and the table's title.
    name: &'static str,
    title: &'static str,
}

/// No shadows: a 2 km city; both renders take well under a minute.
const LIT: Setup = Setup {
    blocks: 50,
    lights: 100_000,
    width: 320,
    height: 180,
    camera_eye: Vec3::new(760.0, 120.0, 160.0),
    camera_target: Vec3::new(870.0, 640.0, 0.0),
    camera_fov_degrees: 45.0,
    name: "city",
    title: "city at night, Lambert, no shadows",
};

/// Shadows: a smaller city, since the exact shadowed sum casts lights x
/// pixels shadow rays (about a minute on two cores).
const SHADOWED: Setup = Setup {
    blocks: 16,
    lights: 20_000,
    width: 256,
    height: 144,
    camera_eye: Vec3::new(250.0, -60.0, 160.0),
    camera_target: Vec3::new(330.0, 260.0, 0.0),
    camera_fov_degrees: 50.0,
    name: "shadows",
    title: "city at night with shadows, Lambert",
};

/// Default relative threshold of the certified bound (1%).
const DEFAULT_THRESHOLD: f64 = 0.01;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

fn main() -> Result<(), Box<dyn Error>> {
    let shadows = std::env::args().any(|a| a == "--shadows");
    let setup = if shadows { SHADOWED } else { LIT };
    let options = Options::parse(Options {
        lights: setup.lights,
        width: setup.width,
        height: setup.height,
        threshold: DEFAULT_THRESHOLD,
        out: PathBuf::from("out"),
        shadows,
    });
    let city = City::new(setup.blocks, options.lights);

    let start = Instant::now();
    let tree = LightTree::build(&city.lights)?;
    let build_time = start.elapsed();

    let camera = Camera::new(
        setup.camera_eye,
        setup.camera_target,
        setup.camera_fov_degrees,
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

    // The tree, per pixel: with shadows through the host's visibility (and
    // its answers counted), without through `shade`, which asks nothing.
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
                    let Some(h) = hit else { continue };
                    *result = Some(if shadows {
                        let mut host = Shadows::new(&city, h.normal);
                        let r = shading.shade_occluded(h.point, h.normal, threshold, &mut host)?;
                        *answer = host.answers;
                        r
                    } else {
                        shading.shade(h.point, h.normal, threshold)?
                    });
                }
                Ok(())
            },
        )?;
    let tree_time = start.elapsed();

    let start = Instant::now();
    let exact_shading = tree.shading(shader);
    let exact: Vec<Option<DVec3>> = hits
        .par_iter()
        .map(|hit| {
            hit.map(|h| {
                if shadows {
                    let mut host = Shadows::new(&city, h.normal);
                    exact_shading.shade_exact_occluded(h.point, h.normal, &mut host)
                } else {
                    exact_shading.shade_exact(h.point, h.normal)
                }
            })
            .transpose()
        })
        .collect::<Result<_, _>>()?;
    let exact_time = start.elapsed();

    let stats = ErrorStats::new(&tree_results, &exact);
    let pixels = hits.iter().flatten().count();
    println!("{}", setup.title);
    print_row("lights", tree.len());
    if shadows {
        print_row("buildings", city.buildings.len());
    }
    print_row("image", format!("{}x{}", options.width, options.height));
    print_row("shaded pixels", pixels);
    print_row("threshold (relative)", options.threshold);
    print_row("primary rays", format!("{:.3} s", trace_time.as_secs_f64()));
    print_comparison(build_time, tree_time, exact_time, &tree_results, &stats);
    if shadows {
        let per_pixel =
            |f: fn(&ShadeResult) -> u32| format!("{:.1}", mean_per_pixel(&tree_results, f));
        print_row(
            "classify queries per pixel",
            per_pixel(|r| r.classify_queries),
        );
        for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
            let total: u64 = answers.iter().map(|a| u64::from(a[slot])).sum();
            print_row(
                &format!("  answered {name}"),
                format!("{:.1}", total as f64 / pixels.max(1) as f64),
            );
        }
        print_row(
            "shadow rays per pixel, tree",
            per_pixel(|r| r.point_queries),
        );
        print_row("shadow rays per pixel, exact", tree.len());
    }

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
        ["tree", "exact", "diff"].map(|f| options.out.join(format!("{}_{f}.png", setup.name)));
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
