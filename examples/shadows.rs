//! The night city with shadows: the buildings occlude. A smaller city than
//! the `city` example's (20,000 lights), since the exact shadowed sum casts
//! one shadow ray per light and pixel (about a minute on two cores).
//!
//! The tree asks the host's conservative Warnock-style classifier
//! ([`Shadows`]) whether a node is visible, occluded or partly so, and casts
//! shadow rays only where it must; the exact shadowed sum casts one per
//! light. The example prints the table of `city` plus the visibility
//! queries, writes the images, and checks the certified bound at every
//! pixel.
//!
//! ```text
//! cargo run --release --example shadows
//! ```
//!
//! Output: `out/shadows_{tree,exact,diff}.png`.

use std::error::Error;

use glam::Vec3;
use manylights::{Lambert, LightTree, ShadeResult, Threshold};
use manylights_report::camera::Camera;
use manylights_report::compare::{
    ErrorStats, mean_per_pixel, print_comparison, print_row, shade_pixels, timed,
};
use manylights_report::image::write_comparison;
use manylights_report::options::Options;
use manylights_report::raycast::albedo_image;
use manylights_report::scenes::{City, SHADOW_BLOCKS};
use manylights_report::shadows::Shadows;

const SEED: u64 = 1998;
const EYE: Vec3 = Vec3::new(250.0, -60.0, 160.0);
const TARGET: Vec3 = Vec3::new(330.0, 260.0, 0.0);
const FOV_DEGREES: f32 = 50.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(Options {
        lights: 20_000,
        width: 256,
        height: 144,
        threshold: 0.01,
        out: "out".into(),
    });
    let city = City::new(SHADOW_BLOCKS, options.lights, SEED);
    let (tree, build_time) = timed(|| LightTree::build(&city.lights));
    let tree = tree?;
    let (w, h) = (options.width, options.height);
    let camera = Camera::new(EYE, TARGET, FOV_DEGREES, w, h);
    let (hits, trace_time) = timed(|| city.trace(&camera));

    // Unit albedo, as in `city`; each pixel's host counts its answers.
    let shading = || tree.shading(Lambert::new(Vec3::ONE));
    let threshold = Threshold::relative(options.threshold);
    let (shaded, tree_time) = timed(|| {
        shade_pixels(&hits, shading, |s, hit| {
            let mut host = Shadows::new(&city, hit.normal);
            let r = s.shade_occluded(hit.point, hit.normal, threshold, &mut host)?;
            Ok((r, host.answers))
        })
    });
    let shaded = shaded?;
    let results: Vec<Option<ShadeResult>> = shaded.iter().map(|s| s.map(|s| s.0)).collect();
    let (exact, exact_time) = timed(|| {
        shade_pixels(&hits, shading, |s, hit| {
            let mut host = Shadows::new(&city, hit.normal);
            s.shade_exact_occluded(hit.point, hit.normal, &mut host)
        })
    });
    let exact = exact?;

    let stats = ErrorStats::new(&results, &exact);
    let pixels = hits.iter().flatten().count();
    println!("city at night with shadows, Lambert");
    print_row("lights", tree.len());
    print_row("buildings", city.buildings.len());
    print_row("image", format!("{w}x{h}"));
    print_row("shaded pixels", pixels);
    print_row("threshold (relative)", options.threshold);
    print_row("primary rays", format!("{:.3} s", trace_time.as_secs_f64()));
    print_comparison(build_time, tree_time, exact_time, &results, &stats);
    let per_pixel = |f: fn(&ShadeResult) -> u32| format!("{:.1}", mean_per_pixel(&results, f));
    print_row(
        "classify queries per pixel",
        per_pixel(|r| r.classify_queries),
    );
    for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
        let total: u64 = shaded.iter().flatten().map(|s| u64::from(s.1[slot])).sum();
        let mean = total as f64 / pixels.max(1) as f64;
        print_row(&format!("  answered {name}"), format!("{mean:.1}"));
    }
    print_row(
        "shadow rays per pixel, tree",
        per_pixel(|r| r.point_queries),
    );
    print_row("shadow rays per pixel, exact", tree.len());

    let tree_image = albedo_image(&hits, results.iter().map(|r| r.map(|r| r.radiance)));
    write_comparison(
        &options.out,
        "shadows",
        (w, h),
        &tree_image,
        &albedo_image(&hits, exact.into_iter()),
        options.threshold,
        EXPOSURE_PERCENTILE,
    )?;
    stats.ensure_certified()
}
