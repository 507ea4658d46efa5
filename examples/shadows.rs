//! The night city with shadows: the buildings occlude. A smaller city than
//! the `city` example's (20,000 lights), since the exact shadowed sum casts
//! one shadow ray per light and pixel (about two minutes on two cores).
//!
//! The buildings sit in a BVH of the `obvhs` crate. The tree asks the
//! host ([`Shadows`]) whether a node is visible, occluded or partly so, a
//! conservative shaft test against that BVH (Haines and Wallace 1994), and
//! casts any-hit shadow rays only where it must; the exact shadowed sum
//! casts one per light. The image is shaded through the batch call
//! (`shade_batch`, one call per tile chunk and normal direction): the host
//! classifies nodes for whole groups of neighbouring pixels (the shaft
//! between the pixels' box and the node's box), and only lights left partly
//! hidden are asked point-to-point. The example prints the table of `city`
//! plus the visibility queries, the same image shaded pixel by pixel for
//! comparison, writes the images, and checks the certified bound at every
//! pixel of both.
//!
//! ```text
//! cargo run --release --example shadows
//! ```
//!
//! Output: `out/shadows_{tree,exact,diff}.png`.

use std::error::Error;

use glam::Vec3;
use manylights::{Query, ShadeResult, Threshold};
use manylights_report::compare::{ErrorStats, print_comparison, print_row};
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
    let threshold = Threshold::relative(options.threshold);

    // The image through the batch call: neighbouring pixels share cuts and
    // the host's answers for whole groups of them.
    let (results, batch, answers, tree_time) = view.shade_batch_shadowed(threshold)?;
    // The same pixels one by one, each with its own host, for comparison.
    let (single, single_time) = view.shade(|s, hit| {
        let mut host = Shadows::new(&view.city.occluders, hit.normal);
        let r = s.shade_query(&Query::new(hit.point, hit.normal)?, threshold, &mut host)?;
        Ok((r, host.classifications(), host.rays))
    })?;
    let (exact, exact_time) = view.shade(|s, hit| {
        let host = Shadows::new(&view.city.occluders, hit.normal);
        Ok(s.exact_query(&Query::new(hit.point, hit.normal)?, host))
    })?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night with shadows, Lambert, through the batch call");
    view.print_setup(&options, true);
    print_comparison(view.build_time, tree_time, exact_time, &results, &stats);
    let pixels = results.iter().flatten().count().max(1) as f64;
    print_row(
        "groups sharing a cut",
        format!(
            "{} ({} pixels shared, {} alone)",
            batch.groups, batch.shared_points, batch.points_alone
        ),
    );
    print_row(
        "classifications per pixel",
        format!(
            "{:.1} ({:.1} for whole groups)",
            (answers[0] + answers[1] + answers[2]) as f64 / pixels,
            batch.shared_classifications as f64 / pixels
        ),
    );
    for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
        print_row(
            &format!("  answered {name}"),
            format!("{:.1}", answers[slot] as f64 / pixels),
        );
    }
    print_row(
        "shadow rays per pixel, tree",
        format!("{:.1}", answers[3] as f64 / pixels),
    );
    print_row("shadow rays per pixel, exact", view.tree.len());
    let single_results: Vec<Option<ShadeResult>> = single.iter().map(|s| s.map(|s| s.0)).collect();
    let single_stats = ErrorStats::new(&single_results, &exact);
    let per_pixel = |f: fn(&(ShadeResult, u32, u32)) -> u32| {
        single
            .iter()
            .flatten()
            .map(|s| f64::from(f(s)))
            .sum::<f64>()
            / pixels
    };
    print_row(
        "pixel by pixel (shade_query)",
        format!(
            "{:.3} s, {:.2}x the exact render; {:.1} classifications and {:.1} shadow rays per \
             pixel; max relative error {:.3e}",
            single_time.as_secs_f64(),
            exact_time.as_secs_f64() / single_time.as_secs_f64(),
            per_pixel(|s| s.1),
            per_pixel(|s| s.2),
            single_stats.max_relative
        ),
    );
    single_stats.ensure_certified()?;
    view.finish(&options, "shadows", &results, &exact, &stats)
}
