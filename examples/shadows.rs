//! The night city with shadows: the buildings occlude. A smaller city than
//! the `city` example's (20,000 lights), since the exact shadowed sum casts
//! one shadow ray per light and pixel (about two minutes on two cores).
//!
//! The buildings sit in a BVH of the `obvhs` crate. The tree asks the
//! host ([`Shadows`]) whether a node is visible, occluded or partly so, a
//! conservative shaft test against that BVH (Haines and Wallace 1994), and
//! casts any-hit shadow rays only where it must; the exact shadowed sum
//! casts one per light. The example prints the table of `city` plus the
//! visibility queries, writes the images, and checks the certified bound at
//! every pixel.
//!
//! ```text
//! cargo run --release --example shadows
//! ```
//!
//! Output: `out/shadows_{tree,exact,diff}.png`.

use std::error::Error;

use glam::Vec3;
use manylights::{Query, ShadeResult, Threshold};
use manylights_report::compare::{ErrorStats, mean_per_pixel, print_comparison, print_row};
use manylights_report::options::Options;
use manylights_report::raycast::{CityView, Shot};
use manylights_report::scenes::SHADOW_BLOCKS;
use manylights_report::shadows::Shadows;

const SEED: u64 = 1998;
/// Eye, target and vertical field of view (degrees).
const SHOT: Shot = (
    Vec3::new(250.0, -60.0, 160.0),
    Vec3::new(330.0, 260.0, 0.0),
    50.0,
);

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(20_000, (256, 144));
    let view = CityView::new(SHADOW_BLOCKS, SEED, &options, SHOT)?;

    // Each pixel's host counts its answers.
    let threshold = Threshold::relative(options.threshold);
    let (shaded, tree_time) = view.shade(|s, hit| {
        let mut host = Shadows::new(&view.city.occluders, hit.normal);
        let r = s.shade_query(&Query::new(hit.point, hit.normal)?, threshold, &mut host)?;
        Ok((r, host.answers))
    })?;
    let results: Vec<Option<ShadeResult>> = shaded.iter().map(|s| s.map(|s| s.0)).collect();
    let (exact, exact_time) = view.shade(|s, hit| {
        let host = Shadows::new(&view.city.occluders, hit.normal);
        Ok(s.exact_query(&Query::new(hit.point, hit.normal)?, host))
    })?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night with shadows, Lambert");
    view.print_setup(&options, true);
    print_comparison(view.build_time, tree_time, exact_time, &results, &stats);
    let per_pixel = |f: fn(&ShadeResult) -> u32| format!("{:.1}", mean_per_pixel(&results, f));
    print_row(
        "classify queries per pixel",
        per_pixel(|r| r.classify_queries),
    );
    let pixels = shaded.iter().flatten().count().max(1) as f64;
    for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
        let total: u64 = shaded.iter().flatten().map(|s| u64::from(s.1[slot])).sum();
        print_row(
            &format!("  answered {name}"),
            format!("{:.1}", total as f64 / pixels),
        );
    }
    print_row(
        "shadow rays per pixel, tree",
        per_pixel(|r| r.point_queries),
    );
    print_row("shadow rays per pixel, exact", view.tree.len());
    view.finish(&options, "shadows", &results, &exact, &stats)
}
