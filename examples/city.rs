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
use manylights::Threshold;
use manylights_report::compare::{ErrorStats, print_comparison};
use manylights_report::options::Options;
use manylights_report::raycast::{CityView, Shot};

/// A 2 km city of 50 x 50 blocks; both renders take well under a minute.
const BLOCKS: u32 = 50;
const SEED: u64 = 1998;
/// Eye, target and vertical field of view (degrees).
const SHOT: Shot = (
    Vec3::new(760.0, 120.0, 160.0),
    Vec3::new(870.0, 640.0, 0.0),
    45.0,
);

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(100_000, (320, 180));
    let view = CityView::new(BLOCKS, SEED, &options, SHOT)?;

    let threshold = Threshold::relative(options.threshold);
    let (results, tree_time) = view.shade(|s, hit| s.shade(hit.point, hit.normal, threshold))?;
    let (exact, exact_time) = view.shade(|s, hit| s.exact(hit.point, hit.normal))?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night, Lambert, no shadows");
    view.print_setup(&options, false);
    print_comparison(view.build_time, tree_time, exact_time, &results, &stats);
    view.finish(&options, "city", &results, &exact, &stats)
}
