//! A city at night lit by 100,000 point lights: street lamps along a grid of
//! streets and lit windows on box buildings, seen from above at an angle.
//!
//! Every visible pixel (one primary ray) is shaded three times with the
//! Lambert model: by the light tree at a relative threshold on its certified
//! error bound, and by the exact sum over every light twice, the crate's
//! `f64` reference (`Shading::exact`) and the report's sum written to
//! vectorize (`f32` lanes, `manylights_report::exact::SoaLights`), each
//! timed over the whole image on all threads as the tree's render. The tree
//! shades the image through the batch call (`Shading::shade_batch`): 16 x
//! 16 pixel tiles, eight tiles per call, the calls spread over the threads,
//! so that neighbouring pixels share certified cuts; every pixel still gets
//! its own certified bound. The example writes the tree's and the `f64`
//! reference's images and an enhanced-contrast difference image, prints the times, the errors actually made against the
//! certified bound, what the batch calls shared and the work per pixel on
//! streets, façades and roofs, and checks that the bound holds at every
//! pixel.
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
use manylights_report::compare::{
    ErrorStats, max_relative, print_errors, print_row, print_times, shade_pixels, timed,
};
use manylights_report::exact::SoaLights;
use manylights_report::options::Options;
use manylights_report::raycast::{CityView, Hit, Shot};
use manylights_report::scenes::Material;

/// A 2 km city of 50 x 50 blocks; the `f64` exact render takes most of
/// the run.
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
) -> (f64, u64) {
    let (count, work) = view
        .hits
        .iter()
        .zip(results)
        .filter_map(|(hit, r)| Some((hit.as_ref()?, r.as_ref()?)))
        .filter(|(hit, _)| keep(hit))
        .fold((0u64, 0u64), |(n, w), (_, r)| {
            (n + 1, w + u64::from(r.cost()))
        });
    (work as f64 / count.max(1) as f64, count)
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(100_000, (320, 180));
    let view = CityView::new(BLOCKS, SEED, &options, SHOT)?;

    let threshold = Threshold::relative(options.threshold);
    let (results, batch, tree_time) = view.shade_batch(threshold)?;
    let (exact, exact_time) = view.shade(|s, hit| s.exact(hit.point, hit.normal))?;
    // The sum written to vectorize, unit albedo as the sessions: the same
    // pixels, the same threads.
    let soa = SoaLights::new(&view.city.lights);
    let unit = Material::diffuse(Vec3::ONE);
    let (simd, simd_time) = timed(|| {
        shade_pixels(
            &view.hits,
            || (),
            |_, hit| Ok(soa.shade(&unit, hit.point, hit.normal, hit.normal)),
        )
    });
    let simd = simd?;

    let stats = ErrorStats::new(&results, &exact);
    println!("city at night, Lambert, no shadows");
    view.print_setup(&options, false);
    print_times(
        view.build_time,
        tree_time,
        &[
            ("exact render, f64", "speed-up vs f64 exact", exact_time),
            (
                "exact render, f32 SIMD",
                "speed-up vs f32 SIMD exact",
                simd_time,
            ),
        ],
    );
    print_row(
        "f32 SIMD vs f64, max rel. diff",
        format!("{:.1e}", max_relative(&simd, &exact)),
    );
    print_errors(&results, &stats);
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
    let streets = work_on(&view, &results, on_ground);
    let roofs = work_on(&view, &results, on_roof);
    let work = |(mean, count): (f64, u64)| format!("{mean:.0} ({count} px)");
    print_row("work per pixel, streets", work(streets));
    print_row(
        "work per pixel, facades",
        work(work_on(&view, &results, |h| h.normal.z < 0.5)),
    );
    print_row("work per pixel, roofs", work(roofs));
    print_row(
        "work per pixel, roofs/streets",
        format!("{:.1}x", roofs.0 / streets.0),
    );
    view.finish(&options, "city", &results, &exact, &stats)
}
