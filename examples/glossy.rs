//! Phong highlights from strings of lights: bulbs on strings hung in arcs
//! above a glossy floor with glossy spheres, shaded with
//! `Combined::new(Lambert, Phong)` seen from a camera (the view direction
//! matters), by the light tree and by the exact sum.
//!
//! Prints the same table as the `city` example (times, speed-up, mean and
//! maximum relative error, nodes per pixel), writes
//! `out/glossy_{tree,exact,diff}.png` and checks the certified bound at
//! every pixel.
//!
//! ```text
//! cargo run --release --example glossy
//! cargo run --release --example glossy -- --lights 100000 --threshold 0.02
//! ```

use std::error::Error;

use glam::{DVec3, Vec3};
use manylights::{LightTree, Threshold, Unoccluded};
use manylights_report::camera::Camera;
use manylights_report::compare::{ErrorStats, print_comparison, print_row, shade_pixels, timed};
use manylights_report::image::write_comparison;
use manylights_report::options::Options;
use manylights_report::scenes::{GLOSSY_SCENE_EXPONENT, Glossy};

const EYE: Vec3 = Vec3::new(0.0, -9.0, 3.0);
const TARGET: Vec3 = Vec3::new(0.0, 8.0, 0.6);
const FOV_DEGREES: f32 = 60.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(20_000, (320, 200));
    let scene = Glossy::new(options.lights);
    let (tree, build_time) = timed(|| LightTree::build(&scene.lights));
    let tree = tree?;
    let (w, h) = (options.width, options.height);
    let hits = Camera::new(EYE, TARGET, FOV_DEGREES, w, h).trace(|o, d| scene.intersect(o, d));

    // The material varies per hit: one session per pixel (sessions are cheap).
    let threshold = Threshold::relative(options.threshold);
    let (results, tree_time) = timed(|| {
        shade_pixels(
            &hits,
            || (),
            |_, hit| {
                tree.shading(hit.shader())
                    .shade_query(&hit.query()?, threshold, Unoccluded)
            },
        )
    });
    let results = results?;
    let (exact, exact_time) = timed(|| {
        shade_pixels(
            &hits,
            || (),
            |_, hit| {
                Ok(tree
                    .shading(hit.shader())
                    .exact_query(&hit.query()?, Unoccluded))
            },
        )
    });
    let exact = exact?;

    let stats = ErrorStats::new(&results, &exact);
    let e = GLOSSY_SCENE_EXPONENT;
    println!("light strings over a glossy floor and spheres, Lambert + Phong (e = {e})");
    print_row("lights", tree.len());
    print_row("image", format!("{w}x{h}"));
    print_row("threshold (relative)", options.threshold);
    print_comparison(build_time, tree_time, exact_time, &results, &stats);

    let tree_image: Vec<DVec3> = results
        .iter()
        .map(|r| r.map_or(DVec3::ZERO, |r| r.radiance))
        .collect();
    let exact_image: Vec<DVec3> = exact.iter().map(|e| e.unwrap_or_default()).collect();
    write_comparison(
        &options.out,
        "glossy",
        (w, h),
        &tree_image,
        &exact_image,
        options.threshold,
        EXPOSURE_PERCENTILE,
    )?;
    stats.ensure_certified()
}
