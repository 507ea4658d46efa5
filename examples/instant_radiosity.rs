//! Instant radiosity (Keller 1997) in a furnished room: four primary lights
//! (three spots in the ceiling, a floor lamp) and 100,000 virtual point
//! lights (VPLs) traced from them, one tree of mixed emission profiles.
//!
//! The report's room ([`Room`]) shoots rays from each primary light, in
//! proportion to its power, through a BVH of the room's boxes (walls,
//! floor, ceiling, furniture; `obvhs`); each first hit becomes a VPL, a
//! cosine lobe (`Emission::cosine(normal, 1.0)`) about the surface's normal
//! carrying the ray's flux times the surface's albedo. The primaries
//! (glTF spots and an isotropic lamp) and the VPLs go into one tree,
//! `LightTree::build_emitters`, which bounds every node's emission by the
//! profiles of its lights.
//!
//! The camera's view is shaded through the batch call (`shade_batch`, one
//! call per chunk of pixel tiles, the calls spread over the threads) at a
//! certified relative threshold, with the room's shadows: a [`Shadows`]
//! host classifies nodes for whole groups of neighbouring pixels (shafts
//! against the BVH) and casts any-hit shadow rays where it must. Every
//! pixel is shaded with unit albedo (`Lambert::new(Vec3::ONE)`), and its
//! radiance multiplied by its surface's albedo afterwards: the Lambert
//! model is linear in `kd`, so this equals shading with the albedo, and
//! each channel's certified bound scales with that channel's albedo. The
//! checks compare the unit-albedo results.
//!
//! The exact shadowed sum casts one shadow ray per light and pixel (10^5
//! rays a pixel, several minutes for the whole image on two cores), so it
//! is taken on a fixed grid of sampled pixels (the centre of each cell of
//! `SAMPLE_GRID`). The example prints the errors there, the time per pixel
//! against the exact sum's, the work per pixel and what the batch calls
//! and the host shared; writes the tree's image, tone-mapped as the other
//! examples' (the exposure maps the 99.5th percentile to white, here of
//! the tree's image); and fails if a sampled pixel breaks its certified
//! bound.
//!
//! ```text
//! cargo run --release --example instant_radiosity
//! cargo run --release --example instant_radiosity -- --lights 30000 --width 320 --height 180 \
//!     --threshold 0.02 --out out
//! ```
//!
//! Output: `out/instant_radiosity_tree.png`.

use std::error::Error;
use std::time::Duration;

use glam::{DVec3, Vec3};
use manylights::{BatchStats, Lambert, LightTree, Query, ShadeError, ShadeResult, Threshold};
use manylights_report::camera::Camera;
use manylights_report::compare::{ErrorStats, mean_per_pixel, print_row, timed};
use manylights_report::config::SEED;
use manylights_report::image::{exposure, write_radiance};
use manylights_report::options::Options;
use manylights_report::raycast::{CHUNK_TILES, Hit, TILE};
use manylights_report::scenes::{POINT_OFFSET, Room};
use manylights_report::shadows::Shadows;
use rayon::prelude::*;

/// Eye, target and vertical field of view (degrees): from a corner of the
/// room across the table towards the sofa and the pillar.
const EYE: Vec3 = Vec3::new(0.6, 0.5, 1.7);
const TARGET: Vec3 = Vec3::new(7.0, 5.5, 0.6);
const FOV_DEGREES: f32 = 70.0;
/// The exact sum is taken at the centre pixel of each cell of this grid
/// over the image (columns, rows).
const SAMPLE_GRID: (u32, u32) = (32, 18);
/// Percentile of the image that the exposure maps to white (the other
/// examples' choice).
const EXPOSURE_PERCENTILE: f64 = 0.995;

/// Tiles of the image, row-major, each its hit pixels' indices (row-major
/// inside the tile), in chunks of [`CHUNK_TILES`] tiles: one batch call each.
fn chunks(hits: &[Option<Hit>], (width, height): (u32, u32)) -> Vec<Vec<usize>> {
    let mut tiles = Vec::new();
    for ty in (0..height).step_by(TILE as usize) {
        for tx in (0..width).step_by(TILE as usize) {
            let columns = tx..(tx + TILE).min(width);
            let pixels: Vec<usize> = (ty..(ty + TILE).min(height))
                .flat_map(|y| columns.clone().map(move |x| (y * width + x) as usize))
                .filter(|&i| hits[i].is_some())
                .collect();
            tiles.push(pixels);
        }
    }
    tiles.chunks(CHUNK_TILES).map(<[_]>::concat).collect()
}

/// The queries of some hit pixels.
fn queries(hits: &[Option<Hit>], pixels: &[usize]) -> Result<Vec<Query>, ShadeError> {
    pixels
        .iter()
        .map(|&i| {
            let hit = hits[i].expect("only hit pixels are listed");
            Query::new(hit.point, hit.normal)
        })
        .collect()
}

/// What the batch calls gave: each pixel's result (`None` where the ray
/// left the room), the calls' summed statistics, and the hosts' answers
/// (visible, occluded, partial) and shadow rays, summed.
type Shaded = (Vec<Option<ShadeResult>>, BatchStats, [u64; 4]);

/// Shades the hit pixels through the batch call with the room's shadows,
/// unit albedo: one call per chunk of tiles, the chunks over rayon's
/// threads with a session per thread and a host per call.
fn shade(
    tree: &LightTree,
    room: &Room,
    hits: &[Option<Hit>],
    size: (u32, u32),
    threshold: Threshold,
) -> Result<Shaded, ShadeError> {
    let chunks = chunks(hits, size);
    let session = || tree.shading(Lambert::new(Vec3::ONE));
    let shaded = chunks
        .par_iter()
        .map_init(session, |s, pixels| {
            let queries = queries(hits, pixels)?;
            let mut results = vec![ShadeResult::default(); queries.len()];
            // Shading points already sit `POINT_OFFSET` off their surfaces
            // and VPLs `VPL_OFFSET` off theirs: the host lifts nothing, so
            // one host serves every normal of the chunk.
            let mut host = Shadows::new(&room.occluders, Vec3::ZERO);
            let stats = s.shade_batch(&queries, threshold, &mut host, &mut results)?;
            let [visible, occluded, partial] = host.answers.map(u64::from);
            Ok((
                results,
                stats,
                [visible, occluded, partial, u64::from(host.rays)],
            ))
        })
        .collect::<Result<Vec<_>, ShadeError>>()?;
    let mut image = vec![None; hits.len()];
    let (mut total, mut answers) = (BatchStats::default(), [0u64; 4]);
    for (pixels, (results, stats, a)) in chunks.iter().zip(shaded) {
        for (&i, r) in pixels.iter().zip(results) {
            image[i] = Some(r);
        }
        total += stats;
        for (sum, x) in answers.iter_mut().zip(a) {
            *sum += x;
        }
    }
    Ok((image, total, answers))
}

/// The pixels the exact sum is taken at: the centre of each cell of
/// [`SAMPLE_GRID`] over the image, where the ray hit the room.
fn samples(hits: &[Option<Hit>], (width, height): (u32, u32)) -> Vec<usize> {
    let (columns, rows) = (SAMPLE_GRID.0.min(width), SAMPLE_GRID.1.min(height));
    (0..rows)
        .flat_map(|r| (0..columns).map(move |c| (c, r)))
        .map(|(c, r)| {
            let x = ((2 * c + 1) * width) / (2 * columns);
            let y = ((2 * r + 1) * height) / (2 * rows);
            (y * width + x) as usize
        })
        .filter(|&i| hits[i].is_some())
        .collect()
}

/// The exact shadowed sums (unit albedo) at the `sampled` pixels, over
/// rayon's threads, with a host per pixel.
fn exact_sums(
    tree: &LightTree,
    room: &Room,
    hits: &[Option<Hit>],
    sampled: &[usize],
) -> Result<Vec<DVec3>, ShadeError> {
    sampled
        .par_iter()
        .map_init(
            || tree.shading(Lambert::new(Vec3::ONE)),
            |s, &i| {
                let hit = hits[i].expect("sampled pixels are hit");
                let host = Shadows::new(&room.occluders, Vec3::ZERO);
                Ok(s.exact_query(&Query::new(hit.point, hit.normal)?, host))
            },
        )
        .collect()
}

/// Prints the work per pixel: node bounds and lights, what the batch calls
/// shared, the hosts' classifications (`answers`: visible, occluded,
/// partial) and shadow rays (`answers[3]`) against the exact sum's, one
/// per light.
fn print_work(
    results: &[Option<ShadeResult>],
    batch: &BatchStats,
    answers: [u64; 4],
    lights: usize,
) {
    print_row(
        "nodes evaluated per pixel",
        format!("{:.1}", mean_per_pixel(results, |r| r.nodes_evaluated)),
    );
    print_row(
        "lights evaluated per pixel",
        format!("{:.1}", mean_per_pixel(results, |r| r.lights_evaluated)),
    );
    print_row(
        "groups sharing a cut",
        format!(
            "{} ({} pixels shared, {} alone)",
            batch.groups, batch.shared_points, batch.points_alone
        ),
    );
    let count = results.iter().flatten().count().max(1) as f64;
    print_row(
        "classifications per pixel",
        format!(
            "{:.1} ({:.1} for whole groups)",
            (answers[0] + answers[1] + answers[2]) as f64 / count,
            batch.shared_classifications as f64 / count
        ),
    );
    print_row(
        "shadow rays per pixel, tree",
        format!("{:.1}", answers[3] as f64 / count),
    );
    print_row("shadow rays per pixel, exact", lights);
}

/// Writes `<out>/instant_radiosity_tree.png`: each pixel's unit-albedo
/// radiance times its surface's albedo, at the exposure that maps
/// [`EXPOSURE_PERCENTILE`] of the image to white.
fn write_image(
    options: &Options,
    hits: &[Option<Hit>],
    results: &[Option<ShadeResult>],
) -> std::io::Result<()> {
    let image: Vec<DVec3> = hits
        .iter()
        .zip(results)
        .map(|(hit, r)| match (hit, r) {
            (Some(h), Some(r)) => r.radiance * h.albedo.as_dvec3(),
            _ => DVec3::ZERO,
        })
        .collect();
    std::fs::create_dir_all(&options.out)?;
    let path = options.out.join("instant_radiosity_tree.png");
    write_radiance(
        &path,
        options.size(),
        &image,
        exposure(&image, EXPOSURE_PERCENTILE),
    )?;
    println!("wrote {}", path.display());
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(100_000, (240, 135));
    let size = options.size();
    let room = Room::new();
    let emitters = room.emitters(options.lights, SEED);
    let primaries = room.primary_lights().len();
    let (tree, build_time) = timed(|| LightTree::build_emitters(&emitters));
    let tree = tree?;
    let camera = Camera::new(EYE, TARGET, FOV_DEGREES, size.0, size.1);
    let (hits, trace_time) = timed(|| {
        camera.trace(|eye, dir| {
            room.hit(eye, dir).map(|(at, normal, surface)| Hit {
                point: at + normal * POINT_OFFSET,
                normal,
                albedo: surface.albedo,
            })
        })
    });

    let threshold = Threshold::relative(options.threshold);
    let (shaded, tree_time) = timed(|| shade(&tree, &room, &hits, size, threshold));
    let (results, batch, answers) = shaded?;

    let sampled = samples(&hits, size);
    let (exact, exact_time) = timed(|| exact_sums(&tree, &room, &hits, &sampled));
    let exact = exact?;
    let checked: Vec<Option<ShadeResult>> = sampled.iter().map(|&i| results[i]).collect();
    let stats = ErrorStats::new(
        &checked,
        &exact.iter().copied().map(Some).collect::<Vec<_>>(),
    );

    let pixels = results.iter().flatten().count();
    let per_pixel = |time: Duration, n: usize| time.as_secs_f64() * 1e6 / n.max(1) as f64;
    let (tree_us, exact_us) = (
        per_pixel(tree_time, pixels),
        per_pixel(exact_time, sampled.len()),
    );
    println!(
        "instant radiosity in a furnished room, Lambert, with shadows, through the batch call"
    );
    print_row(
        "lights",
        format!(
            "{} ({primaries} primary lights + {} VPLs)",
            tree.len(),
            tree.len() - primaries
        ),
    );
    print_row("boxes", room.surfaces.len());
    print_row("image", format!("{}x{}", size.0, size.1));
    print_row("shaded pixels", pixels);
    print_row("threshold (relative)", options.threshold);
    print_row("primary rays", format!("{:.3} s", trace_time.as_secs_f64()));
    print_row("tree build", format!("{:.3} s", build_time.as_secs_f64()));
    print_row(
        "tree render",
        format!("{:.3} s ({tree_us:.0} us/pixel)", tree_time.as_secs_f64()),
    );
    print_row(
        "exact render, sampled pixels",
        format!(
            "{:.3} s ({exact_us:.0} us/pixel) on {} pixels, the centres of a {}x{} grid",
            exact_time.as_secs_f64(),
            sampled.len(),
            SAMPLE_GRID.0,
            SAMPLE_GRID.1
        ),
    );
    print_row(
        "exact render, whole image",
        format!("{:.0} s (extrapolated)", exact_us * pixels as f64 * 1e-6),
    );
    print_row("speed-up per pixel", format!("{:.1}x", exact_us / tree_us));
    // On the sampled pixels, measured as the threshold measures the bound
    // (largest channel over largest channel), then each channel against
    // itself.
    print_row(
        "mean relative error, sampled",
        format!("{:.3e}", stats.mean_relative),
    );
    print_row(
        "max relative error, sampled",
        format!("{:.3e}", stats.max_relative),
    );
    print_row(
        "max relative error per channel",
        format!("{:.3e}", stats.max_relative_per_channel),
    );
    print_row(
        "mean certified bound / value",
        format!("{:.3e}", stats.mean_bound_relative),
    );
    print_work(&results, &batch, answers, tree.len());
    print_row("sampled pixels violating bound", stats.violations);

    write_image(&options, &hits, &results)?;
    stats.ensure_certified()
}
