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
//! ```text
//! cargo run --release --example city
//! cargo run --release --example city -- --lights 1000000 --width 160 --height 90 \
//!     --threshold 0.02 --out out
//! ```
//!
//! Output: `out/city_{tree,exact,diff}.png`.

use std::error::Error;

use glam::Vec3;
use manylights::{Lambert, LightTree, Threshold};
use manylights_report::camera::Camera;
use manylights_report::compare::{ErrorStats, print_comparison, print_row, shade_pixels, timed};
use manylights_report::image::write_comparison;
use manylights_report::options::Options;
use manylights_report::raycast::albedo_image;
use manylights_report::scenes::City;

/// A 2 km city of 50 x 50 blocks; both renders take well under a minute.
const BLOCKS: u32 = 50;
const SEED: u64 = 1998;
const EYE: Vec3 = Vec3::new(760.0, 120.0, 160.0);
const TARGET: Vec3 = Vec3::new(870.0, 640.0, 0.0);
const FOV_DEGREES: f32 = 45.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(Options {
        lights: 100_000,
        width: 320,
        height: 180,
        threshold: 0.01,
        out: "out".into(),
    });
    let city = City::new(BLOCKS, options.lights, SEED);
    let (tree, build_time) = timed(|| LightTree::build(&city.lights));
    let tree = tree?;
    let (w, h) = (options.width, options.height);
    let camera = Camera::new(EYE, TARGET, FOV_DEGREES, w, h);
    let (hits, trace_time) = timed(|| city.trace(&camera));

    // Unit albedo: Lambert is linear in kd, so each pixel's albedo multiplies
    // the radiance (and its bound) afterwards.
    let shading = || tree.shading(Lambert::new(Vec3::ONE));
    let threshold = Threshold::relative(options.threshold);
    let (results, tree_time) = timed(|| {
        shade_pixels(&hits, shading, |s, hit| {
            s.shade(hit.point, hit.normal, threshold)
        })
    });
    let results = results?;
    let (exact, exact_time) = timed(|| {
        shade_pixels(&hits, shading, |s, hit| {
            s.shade_exact(hit.point, hit.normal)
        })
    });
    let exact = exact?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night, Lambert, no shadows");
    print_row("lights", tree.len());
    print_row("image", format!("{w}x{h}"));
    print_row("shaded pixels", hits.iter().flatten().count());
    print_row("threshold (relative)", options.threshold);
    print_row("primary rays", format!("{:.3} s", trace_time.as_secs_f64()));
    print_comparison(build_time, tree_time, exact_time, &results, &stats);

    let tree_image = albedo_image(&hits, results.iter().map(|r| r.map(|r| r.radiance)));
    write_comparison(
        &options.out,
        "city",
        (w, h),
        &tree_image,
        &albedo_image(&hits, exact.into_iter()),
        options.threshold,
        EXPOSURE_PERCENTILE,
    )?;
    stats.ensure_certified()
}
