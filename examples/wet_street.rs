//! A wet street at night: the street-lamp city seen from eye height down
//! one of its streets, the asphalt shaded with
//! `Combined::new(Lambert, Ggx)`: GGX microfacet reflection, smooth
//! (`alpha = 0.06`) in puddles and rough (`alpha = 0.35`) elsewhere, `F0 =
//! 0.04` (water), by the light tree at a certified relative threshold and
//! by the exact sum.
//!
//! Prints the same table as the `city` example (times, speed-up, mean and
//! maximum relative error, nodes per pixel), writes
//! `out/wet_street_{tree,exact,diff}.png` and checks the certified bound
//! at every pixel.
//!
//! ```text
//! cargo run --release --example wet_street
//! cargo run --release --example wet_street -- --lights 100000 --threshold 0.02
//! ```

use std::error::Error;

use glam::{DVec3, Vec3};
use manylights::{Combined, Ggx, Lambert, LightTree, Query, Threshold, Unoccluded};
use manylights_report::camera::Camera;
use manylights_report::compare::{ErrorStats, print_comparison, print_row, shade_pixels, timed};
use manylights_report::config::SEED;
use manylights_report::image::write_comparison;
use manylights_report::options::Options;
use manylights_report::scenes::city_lights;

/// Eye height above the street, and where the camera looks: down the
/// street along `x` at `y = 0`, between its two rows of lamps.
const EYE: Vec3 = Vec3::new(-8.0, 1.5, 1.7);
const TARGET: Vec3 = Vec3::new(120.0, 0.0, 0.0);
const FOV_DEGREES: f32 = 55.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;
/// Asphalt's diffuse albedo.
const ASPHALT: Vec3 = Vec3::new(0.06, 0.06, 0.065);
/// Water's reflectance at normal incidence.
const WATER_F0: f32 = 0.04;
/// Roughness of the puddles and of the wet asphalt around them.
const PUDDLE_ALPHA: f32 = 0.06;
const ASPHALT_ALPHA: f32 = 0.35;

/// Whether the street at `(x, y)` lies under a puddle: a smooth pattern of
/// blobs, no randomness.
fn puddle(x: f32, y: f32) -> bool {
    let wave = (0.37 * x).sin() * (0.61 * y + 0.3 * x).cos() + 0.5 * (0.11 * x - 0.9 * y).sin();
    wave > 0.35
}

/// What a pixel's ray hits: a point of the street (the plane `z = 0`) and
/// the direction back to the eye.
struct Hit {
    point: Vec3,
    view: Vec3,
}

impl Hit {
    fn query(&self) -> Result<Query<manylights::query::WithView>, manylights::ShadeError> {
        Query::new(self.point, Vec3::Z)?.with_view(self.view)
    }

    fn shader(&self) -> Combined<Lambert, Ggx> {
        let alpha = if puddle(self.point.x, self.point.y) {
            PUDDLE_ALPHA
        } else {
            ASPHALT_ALPHA
        };
        Combined::new(
            Lambert::new(ASPHALT),
            Ggx::new(Vec3::splat(WATER_F0), alpha),
        )
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(10_000, (320, 180));
    let lights = city_lights(options.lights, SEED);
    let (tree, build_time) = timed(|| LightTree::build(&lights));
    let tree = tree?;
    let (w, h) = (options.width, options.height);
    let hits = Camera::new(EYE, TARGET, FOV_DEGREES, w, h).trace(|eye, dir| {
        // The street: rays going down meet the plane z = 0.
        (dir.z < 0.0).then(|| Hit {
            point: eye + dir * (-eye.z / dir.z),
            view: -dir,
        })
    });

    // The roughness varies per hit: one session per pixel (sessions are
    // cheap).
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
    println!(
        "a wet street under street lamps, Lambert + GGX (alpha {PUDDLE_ALPHA} in puddles, \
         {ASPHALT_ALPHA} elsewhere, F0 {WATER_F0})"
    );
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
        "wet_street",
        (w, h),
        &tree_image,
        &exact_image,
        options.threshold,
        EXPOSURE_PERCENTILE,
    )?;
    stats.ensure_certified()
}
