//! The emitters part: oriented emitters at a certified 1%, per point and
//! per pixel (one `shade_batch` call over a camera's view), against the
//! vectorized exact sum of the same model ([`SoaEmitters`]).
//!
//! ```text
//! cargo run --release -p manylights-report -- emitters
//! cargo run --release -p manylights-report -- emitters --quick
//! ```
//!
//! * The spot-lit street city: the lamps of the street city as glTF spots
//!   aimed down ([`spot_city_lights`]), 10^4 to 10^6 of them, against the
//!   same lamps isotropic (the report's `city`), on the city's ground
//!   points; then a camera's view of the ground at 10^6 lamps through the
//!   batch call.
//! * The VPL room: instant radiosity in a furnished room ([`Room`]): four
//!   primary lights and 10^5 or 10^6 virtual point lights (cosine lobes)
//!   traced from them, on points of the room's surfaces and through a
//!   camera's view; against the same lights isotropic, and with the tree
//!   split by position alone (`group_by_axis(false)`).
//!
//! Every result on the sampled points and pixels is checked against the
//! crate's `f64` exact sum (`Shading::exact_query`); the part fails if one
//! breaks its bound. Times are medians of paired rounds (the tree's pass,
//! then the exact sum's), one core; a speed-up is the median of the rounds'
//! ratios.

use std::error::Error;
use std::hint::black_box;

use glam::{DVec3, Vec3};
use manylights::{Emitter, Lambert, LightTree, Query, ShadeResult, Threshold, Unoccluded};

use crate::batch::paired;
use crate::camera::Camera;
use crate::config::SEED;
use crate::exact::SoaLights;
use crate::exact_emitters::SoaEmitters;
use crate::scenes::{self, Material, Room, spot_city_lights};

/// The part's name.
pub const EMITTERS: &str = "emitters";

/// The certified relative target.
const TARGET: f64 = 0.01;
/// Largest relative difference allowed between the `f32` exact sum and
/// the crate's `f64` one (spots' ramps magnify the `f32` cosines).
const SOA_TOLERANCE: f64 = 1e-4;
/// The city's camera, relative to the block corner nearest the city's
/// centre: eye, target, vertical field of view (the `batch` part's shot).
const CITY_EYE: Vec3 = Vec3::new(22.0, -35.0, 30.0);
const CITY_TARGET: Vec3 = Vec3::new(52.0, 45.0, 0.0);
const CITY_FOV: f32 = 50.0;
/// Side of the street city's blocks.
const BLOCK: f32 = 60.0;
/// The room's camera.
const ROOM_EYE: Vec3 = Vec3::new(0.6, 0.5, 1.7);
const ROOM_TARGET: Vec3 = Vec3::new(7.0, 5.5, 0.6);
const ROOM_FOV: f32 = 70.0;
/// Pixels sampled for the exact sums and the checks: the centres of a grid
/// of cells over the image.
const SAMPLE_GRID: (u32, u32) = (16, 10);

/// Sizes of one run.
#[derive(Clone, Copy, Debug)]
struct Sizes {
    /// Lamps of the city, and points at each.
    city: &'static [(usize, usize)],
    /// VPLs of the room, and points at each.
    room: &'static [(usize, usize)],
    /// The city's image and the room's.
    image: (u32, u32),
    room_image: (u32, u32),
    /// Paired rounds per timing.
    rounds: usize,
}

const FULL: Sizes = Sizes {
    city: &[(10_000, 128), (100_000, 64), (1_000_000, 32)],
    room: &[(100_000, 64), (1_000_000, 16)],
    image: (320, 180),
    room_image: (160, 90),
    rounds: 5,
};
const QUICK: Sizes = Sizes {
    city: &[(10_000, 32), (100_000, 16)],
    room: &[(100_000, 16)],
    image: (160, 90),
    room_image: (80, 45),
    rounds: 3,
};

/// Checks every result against its exact sum; the largest ratio of the
/// actual error to the bound.
fn check(what: &str, results: &[ShadeResult], exact: &[DVec3]) -> Result<f64, String> {
    let mut worst = 0.0f64;
    for (r, &e) in results.iter().zip(exact) {
        if !r.certifies(e) {
            return Err(format!("{what}: {r:?} against the exact {e}"));
        }
        let ratio = ((r.radiance - e).abs() / r.error_bound).max_element();
        worst = worst.max(if ratio.is_finite() { ratio } else { 0.0 });
    }
    Ok(worst)
}

/// Checks the `f32` exact sums against the crate's.
fn check_soa(what: &str, soa: &[DVec3], exact: &[DVec3]) -> Result<(), String> {
    for (s, e) in soa.iter().zip(exact) {
        let scale = e.max_element().max(1e-30);
        if (*s - *e).abs().max_element() > SOA_TOLERANCE * scale {
            return Err(format!("{what}: SIMD sum {s} against the exact {e}"));
        }
    }
    Ok(())
}

/// Mean evaluations (node bounds plus lights) of results.
fn mean_cost(results: &[ShadeResult]) -> f64 {
    results.iter().map(|r| f64::from(r.cost())).sum::<f64>() / results.len().max(1) as f64
}

/// One tree's figures on a set of queries.
struct PointRow {
    evaluations: f64,
    max_evaluations: u32,
    us: f64,
    exact_us: f64,
    ratio: f64,
    worst: f64,
}

/// Shades `queries` at [`TARGET`] with `tree` and times the passes against
/// `exact` (the SIMD sum of one query); checks every result.
fn per_point(
    what: &str,
    tree: &LightTree,
    queries: &[Query],
    rounds: usize,
    mut exact: impl FnMut(&Query) -> DVec3,
) -> Result<PointRow, Box<dyn Error>> {
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let threshold = Threshold::relative(TARGET);
    let reference: Vec<DVec3> = queries
        .iter()
        .map(|q| shading.exact_query(q, Unoccluded))
        .collect();
    let simd: Vec<DVec3> = queries.iter().map(&mut exact).collect();
    check_soa(what, &simd, &reference)?;
    let mut results = vec![ShadeResult::default(); queries.len()];
    let timing = paired(
        rounds,
        (queries.len(), queries.len()),
        || {
            for (q, r) in queries.iter().zip(results.iter_mut()) {
                *r = shading
                    .shade_query(q, threshold, Unoccluded)
                    .expect("valid threshold");
            }
        },
        || {
            for q in queries {
                black_box(exact(q));
            }
        },
    );
    let worst = check(what, &results, &reference)?;
    Ok(PointRow {
        evaluations: mean_cost(&results),
        max_evaluations: results.iter().map(ShadeResult::cost).max().unwrap_or(0),
        us: timing.us,
        exact_us: timing.exact_us,
        ratio: timing.ratio,
        worst,
    })
}

/// A camera's image through the batch call at [`TARGET`] against the SIMD
/// exact sum on the sampled pixels: microseconds per pixel of both, the
/// speed-up, the worst error over bound on the sampled pixels, the mean
/// evaluations per pixel and the share of pixels that shared a cut.
struct PixelRow {
    pixels: usize,
    us: f64,
    exact_us: f64,
    ratio: f64,
    worst: f64,
    shared: f64,
}

fn per_pixel(
    what: &str,
    tree: &LightTree,
    queries: &[Query],
    rounds: usize,
    mut exact: impl FnMut(&Query) -> DVec3,
) -> Result<PixelRow, Box<dyn Error>> {
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let threshold = Threshold::relative(TARGET);
    let step = (queries.len() / (SAMPLE_GRID.0 * SAMPLE_GRID.1) as usize).max(1);
    let samples: Vec<usize> = (0..queries.len()).step_by(step).collect();
    let reference: Vec<DVec3> = samples
        .iter()
        .map(|&k| shading.exact_query(&queries[k], Unoccluded))
        .collect();
    let simd: Vec<DVec3> = samples.iter().map(|&k| exact(&queries[k])).collect();
    check_soa(what, &simd, &reference)?;
    let mut results = vec![ShadeResult::default(); queries.len()];
    let mut stats = Ok(Default::default());
    let timing = paired(
        rounds,
        (queries.len(), samples.len()),
        || stats = shading.shade_batch(queries, threshold, Unoccluded, &mut results),
        || {
            for &k in &samples {
                black_box(exact(&queries[k]));
            }
        },
    );
    let stats = stats?;
    let sampled: Vec<ShadeResult> = samples.iter().map(|&k| results[k]).collect();
    let worst = check(what, &sampled, &reference)?;
    Ok(PixelRow {
        pixels: queries.len(),
        us: timing.us,
        exact_us: timing.exact_us,
        ratio: timing.ratio,
        worst,
        shared: f64::from(stats.shared_points) / queries.len().max(1) as f64,
    })
}

/// Runs the part.
pub fn run_emitters(quick: bool) -> Result<(), Box<dyn Error>> {
    let sizes = if quick { QUICK } else { FULL };
    println!("## Oriented emitters: certified {TARGET}, Lambert, one core\n");
    println!(
        "  `cargo run --release -p manylights-report -- {EMITTERS}{}`; times are medians of {} \
         paired rounds against the vectorized exact sum of the same model; evaluations = node \
         bounds + lights",
        if quick { " --quick" } else { "" },
        sizes.rounds
    );
    spot_city(&sizes)?;
    vpl_room(&sizes)?;
    Ok(())
}

/// The spot-lit street city, per point and per pixel.
fn spot_city(sizes: &Sizes) -> Result<(), Box<dyn Error>> {
    println!("\n### The street city, lamps as spots aimed down (tilts up to 12 degrees)\n");
    println!(
        "| lamps | points | spots: evals mean (max) | us/pt | exact us/pt | speed-up | isotropic: \
         evals mean | us/pt | speed-up | worst error / bound |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let material = Material::diffuse(Vec3::ONE);
    for &(n, count) in sizes.city {
        let scene = scenes::city(n, count, SEED);
        let spots = spot_city_lights(n, SEED);
        let tree = LightTree::build_emitters(&spots)?;
        let plain = LightTree::build(&scene.lights)?;
        let soa = SoaEmitters::new(&spots).ok_or("spots vectorize")?;
        let soa_plain = SoaLights::new(&scene.lights);
        let queries: Vec<Query> = scene
            .points
            .iter()
            .map(|p| Query::new(p.point, p.normal))
            .collect::<Result<_, _>>()?;
        let spot = per_point("spot city", &tree, &queries, sizes.rounds, |q| {
            soa.shade(Vec3::ONE, q.point(), q.surface().normal.as_vec3())
        })?;
        let iso = per_point("isotropic city", &plain, &queries, sizes.rounds, |q| {
            let n = q.surface().normal.as_vec3();
            soa_plain.shade(&material, q.point(), n, n)
        })?;
        println!(
            "| {n} | {count} | {:.0} ({}) | {:.2} | {:.0} | {:.1}x | {:.0} | {:.2} | {:.1}x | {:.2} |",
            spot.evaluations,
            spot.max_evaluations,
            spot.us,
            spot.exact_us,
            spot.ratio,
            iso.evaluations,
            iso.us,
            iso.ratio,
            spot.worst.max(iso.worst)
        );
    }
    // The camera's view at the largest size.
    let &(n, _) = sizes.city.last().expect("sizes");
    let spots = spot_city_lights(n, SEED);
    let tree = LightTree::build_emitters(&spots)?;
    let soa = SoaEmitters::new(&spots).ok_or("spots vectorize")?;
    let (lo, hi) = spots.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), e| (lo.min(e.light.position), hi.max(e.light.position)),
    );
    let corner = (((lo + hi) * 0.5) / BLOCK).floor().with_z(0.0) * BLOCK;
    let camera = Camera::new(
        corner + CITY_EYE,
        corner + CITY_TARGET,
        CITY_FOV,
        sizes.image.0,
        sizes.image.1,
    );
    let queries: Vec<Query> = (0..camera.width * camera.height)
        .filter_map(|i| {
            let d = camera.ray(i % camera.width, i / camera.width);
            (d.z < 0.0).then(|| (camera.eye - d * (camera.eye.z / d.z)).with_z(0.0))
        })
        .map(|p| Query::new(p, Vec3::Z))
        .collect::<Result<_, _>>()?;
    let row = per_pixel("spot city view", &tree, &queries, sizes.rounds, |q| {
        soa.shade(Vec3::ONE, q.point(), Vec3::Z)
    })?;
    println!(
        "\n  camera view, {n} spot lamps, {}x{}: {} ground pixels through one batch call, {:.2} \
         us per pixel against {:.0} us for the exact sum: **{:.1}x per pixel**; {:.0}% of pixels \
         shared a cut; worst error / bound on {} sampled pixels {:.2}",
        sizes.image.0,
        sizes.image.1,
        row.pixels,
        row.us,
        row.exact_us,
        row.ratio,
        100.0 * row.shared,
        SAMPLE_GRID.0 * SAMPLE_GRID.1,
        row.worst
    );
    Ok(())
}

/// The VPL room, per point (with the isotropic lights and the tree split
/// by position alone beside it) and per pixel.
fn vpl_room(sizes: &Sizes) -> Result<(), Box<dyn Error>> {
    println!("\n### The VPL room: four primary lights and VPLs traced from them\n");
    println!(
        "| VPLs | points | tree | evals mean (max) | us/pt | exact us/pt | speed-up | worst error \
         / bound |"
    );
    println!("|---:|---:|---|---:|---:|---:|---:|---:|");
    let room = Room::new();
    let mut last: Option<(usize, Vec<Emitter>)> = None;
    for &(n, count) in sizes.room {
        let emitters = room.emitters(n, SEED);
        let soa = SoaEmitters::new(&emitters).ok_or("VPLs vectorize")?;
        let plain_lights = scenes::isotropic(&emitters);
        let soa_plain = SoaLights::new(&plain_lights);
        let material = Material::diffuse(Vec3::ONE);
        let queries: Vec<Query> = room
            .points(count, SEED)
            .into_iter()
            .map(|(p, n)| Query::new(p, n))
            .collect::<Result<_, _>>()?;
        let by_axis = LightTree::build_emitters(&emitters)?;
        let by_position = LightTree::builder()
            .group_by_axis(false)
            .build_emitters(&emitters)?;
        let isotropic = LightTree::build(&plain_lights)?;
        let exact = |q: &Query| soa.shade(Vec3::ONE, q.point(), q.surface().normal.as_vec3());
        let rows = [
            (
                "split by axis",
                per_point("VPL room", &by_axis, &queries, sizes.rounds, exact)?,
            ),
            (
                "by position alone",
                per_point("VPL room", &by_position, &queries, sizes.rounds, exact)?,
            ),
            (
                "same lights, isotropic",
                per_point("isotropic room", &isotropic, &queries, sizes.rounds, |q| {
                    let n = q.surface().normal.as_vec3();
                    soa_plain.shade(&material, q.point(), n, n)
                })?,
            ),
        ];
        for (label, r) in rows {
            println!(
                "| {n} | {count} | {label} | {:.0} ({}) | {:.1} | {:.0} | {:.2}x | {:.2} |",
                r.evaluations, r.max_evaluations, r.us, r.exact_us, r.ratio, r.worst
            );
        }
        last = Some((n, emitters));
    }
    let (n, emitters) = last.ok_or("sizes")?;
    let tree = LightTree::build_emitters(&emitters)?;
    let soa = SoaEmitters::new(&emitters).ok_or("VPLs vectorize")?;
    let (w, h) = sizes.room_image;
    let camera = Camera::new(ROOM_EYE, ROOM_TARGET, ROOM_FOV, w, h);
    let queries: Vec<Query> = (0..camera.width * camera.height)
        .filter_map(|i| {
            let d = camera.ray(i % camera.width, i / camera.width);
            room.hit(camera.eye, d)
                .map(|(at, normal, _)| (at + normal * scenes::POINT_OFFSET, normal))
        })
        .map(|(p, n)| Query::new(p, n))
        .collect::<Result<_, _>>()?;
    let row = per_pixel("VPL room view", &tree, &queries, sizes.rounds, |q| {
        soa.shade(Vec3::ONE, q.point(), q.surface().normal.as_vec3())
    })?;
    println!(
        "\n  camera view, {n} VPLs, {w}x{h}: {} pixels through one batch call, {:.1} us per pixel \
         against {:.0} us for the exact sum: **{:.2}x per pixel**; {:.0}% of pixels shared a \
         cut; worst error / bound on the sampled pixels {:.2}",
        row.pixels,
        row.us,
        row.exact_us,
        row.ratio,
        100.0 * row.shared,
        row.worst
    );
    Ok(())
}
