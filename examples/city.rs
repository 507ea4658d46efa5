//! A city at night lit by 100,000 point lights: street lamps along a grid of
//! streets and lit windows on box buildings, seen from above at an angle.
//!
//! Every visible pixel (one primary ray) is shaded twice with the Lambert
//! model: by the light tree at a relative threshold on its certified error
//! bound, and by the exact sum over every light. The tree shades the image
//! through the batch call (`Shading::shade_batch`): 16 x 16 pixel tiles,
//! eight tiles per call, the calls spread over the threads, so that
//! neighbouring pixels share certified cuts; every pixel still gets its own
//! certified bound. The example writes both images and an enhanced-contrast
//! difference image, prints the times, the errors actually made against the
//! certified bound and what the batch calls shared, and checks that the
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
use manylights::{ShadeResult, Threshold};
use manylights_report::compare::{ErrorStats, print_comparison, print_row};
use manylights_report::options::Options;
use manylights_report::raycast::{CityView, Hit, Shot};

/// A 2 km city of 50 x 50 blocks; both renders take well under a minute.
const BLOCKS: u32 = 50;
const SEED: u64 = 1998;
/// Eye, target and vertical field of view (degrees).
const SHOT: Shot = (
    Vec3::new(760.0, 120.0, 160.0),
    Vec3::new(870.0, 640.0, 0.0),
    45.0,
);

/// Mean work per pixel (node estimates and single lights) on the pixels
/// whose hit passes `keep`, and how many there are.
fn work_on(
    view: &CityView,
    results: &[Option<ShadeResult>],
    keep: impl Fn(&Hit) -> bool,
) -> String {
    let (count, work) = view
        .hits
        .iter()
        .zip(results)
        .filter_map(|(hit, r)| Some((hit.as_ref()?, r.as_ref()?)))
        .filter(|(hit, _)| keep(hit))
        .fold((0u64, 0u64), |(n, w), (_, r)| {
            (n + 1, w + u64::from(r.cost()))
        });
    format!("{:.0} ({count} px)", work as f64 / count.max(1) as f64)
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(100_000, (320, 180));
    let view = CityView::new(BLOCKS, SEED, &options, SHOT)?;

    let threshold = Threshold::relative(options.threshold);
    let (results, batch, tree_time) = view.shade_batch(threshold)?;
    let (exact, exact_time) = view.shade(|s, hit| s.exact(hit.point, hit.normal))?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night, Lambert, no shadows");
    view.print_setup(&options, false);
    print_comparison(view.build_time, tree_time, exact_time, &results, &stats);
    let pixels = results.iter().flatten().count().max(1) as f64;
    print_row("groups sharing a cut", batch.groups);
    print_row("pixels shaded in groups", batch.shared_points);
    print_row("pixels shaded alone", batch.points_alone);
    print_row(
        "shared node bounds per pixel",
        format!("{:.1}", batch.shared_evaluations as f64 / pixels),
    );
    let on_ground = |h: &Hit| h.normal.z > 0.5 && h.point.z < 1e-3;
    let on_roof = |h: &Hit| h.normal.z > 0.5 && h.point.z >= 1e-3;
    print_row(
        "work per pixel, streets",
        work_on(&view, &results, on_ground),
    );
    print_row(
        "work per pixel, facades",
        work_on(&view, &results, |h| h.normal.z < 0.5),
    );
    print_row("work per pixel, roofs", work_on(&view, &results, on_roof));
    view.finish(&options, "city", &results, &exact, &stats)
}
