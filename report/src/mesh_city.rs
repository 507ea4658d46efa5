//! The occluded city with its buildings as triangles (twelve a building,
//! all of them one solid: boxes are found inside them), shadowed by
//! `manylights-mesh`'s host: per shading point, the tree at a
//! certified 1% against the exact shadowed sum (one shadow ray per light
//! above the tangent plane), one core, with the rays and classifications
//! each takes; then the same through the batch call, per pixel of a camera
//! view.
//!
//! ```text
//! cargo run --release -p manylights-report -- city-mesh
//! ```

use std::error::Error;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{Lambert, Query, ShadeResult, Threshold};
use manylights_mesh::{Occluders, box_mesh};

use crate::camera::Camera;
use crate::config::{Config, SEED};
use crate::measure::{Sample, paired};
use crate::raycast::{CHUNK_TILES, Hit, TILE};
use crate::scenes::{City, city_shadows};
use crate::shadowed::ShadowLights;
use crate::shadows::SHADOW_OFFSET;
use crate::sweep::{build_tree, print_tree, query, references};

/// The part's name.
pub const CITY_MESH: &str = "city-mesh";
/// The certified threshold of the comparison.
const THRESHOLD: f64 = 0.01;
/// Rounds of alternating passes (one of each method) per point.
const ROUNDS: usize = 5;
/// Passes of each method over the batch comparison's view (the fastest
/// counts): every pass of the exact sum casts a ray per light and pixel.
const BATCH_ROUNDS: usize = 2;
/// The camera of the batch comparison (eye, target, vertical field of view
/// in degrees; that of the `shadows` example) and its image size.
const SHOT: (Vec3, Vec3, f32) = (
    Vec3::new(250.0, -60.0, 160.0),
    Vec3::new(330.0, 260.0, 0.0),
    50.0,
);
const SIZE: (u32, u32) = (96, 54);
const QUICK_SIZE: (u32, u32) = (64, 36);

/// The buildings of `city` as one closed triangle mesh, a solid (with boxes
/// found inside each building), in the mesh host's BVH, with the box host's
/// offset.
pub fn building_occluders(city: &City) -> Result<Occluders, Box<dyn Error>> {
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    for b in &city.buildings {
        let (corners, triangles) = box_mesh(&b.bounds);
        let base = positions.len() as u32;
        positions.extend(corners);
        indices.extend(triangles.iter().map(|i| i + base));
    }
    Ok(Occluders::builder()
        .solid(&positions, &indices)?
        .offset(SHADOW_OFFSET)?
        .build())
}

/// Runs the part: prints the per-point table and the batch table.
pub fn run_city_mesh(cfg: &Config, quick: bool) -> Result<(), Box<dyn Error>> {
    let (scene, city) = city_shadows(cfg.shadow_lights, cfg.points, SEED);
    let occluders = building_occluders(&city)?;
    let (tree, build) = build_tree(&scene)?;
    println!(
        "## Scene `{CITY_MESH}`: `{}` with its buildings as triangles under \
         `manylights-mesh`'s host: {}",
        scene.name, scene.description
    );
    print_tree(&tree, build);
    println!(
        "  {} triangles ({} quads), {} boxes found inside the buildings, offset {}",
        occluders.triangles(),
        occluders.quads(),
        occluders.solid_boxes().len(),
        occluders.offset()
    );
    let shader = Lambert::new(scene.material.kd);
    let (points, refs) = references(&tree, shader, &scene.points, |_| occluders.host());
    let light_count = scene.lights.len() as u32;
    let threshold = Threshold::relative(THRESHOLD);
    let mut soa = ShadowLights::new(&scene.lights, scene.material.kd);
    let mut shading = tree.shading(shader);
    let (mut rays, mut classified, mut worst, mut certified) = (0u64, 0u64, 0.0f64, true);
    let target = paired(
        points.len(),
        ROUNDS,
        |i| {
            let pt = &points[i];
            let (radiance, rays) = soa.exact(pt.point, pt.normal, &mut occluders.host());
            Sample::estimate(radiance, light_count, Some(rays))
        },
        |i| {
            let pt = &points[i];
            let mut host = occluders.host();
            let r = shading
                .shade_query(&query(pt), threshold, &mut host)
                .expect("valid threshold");
            rays += host.rays;
            classified += host.classifications();
            worst = worst.max(relative(r.radiance, refs[i]));
            certified &= r.certifies(refs[i]);
            Sample::cut(r, None)
        },
    );
    let per_point = (ROUNDS * points.len()) as f64;
    let exact_rays: u64 = points
        .iter()
        .map(|pt| u64::from(soa.exact(pt.point, pt.normal, &mut occluders.host()).1))
        .sum();
    println!(
        "  {} points; one core; `cargo run --release -p manylights-report -- {CITY_MESH}`",
        points.len()
    );
    println!("| per point | us/pt | speed-up | shadow rays/pt | classifications/pt | max error |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| exact shadowed sum | {:.1} | 1x | {:.0} | 0 | 0 |",
        target.first * 1e6,
        exact_rays as f64 / points.len() as f64
    );
    println!(
        "| tree, certified {}% | {:.1} | {:.1}x | {:.0} | {:.0} | {worst:.2e} |",
        THRESHOLD * 100.0,
        target.second * 1e6,
        1.0 / target.ratio,
        rays as f64 / per_point,
        classified as f64 / per_point,
    );
    if !certified {
        return Err("the certified bound failed at a point".into());
    }

    let (width, height) = if quick { QUICK_SIZE } else { SIZE };
    let camera = Camera::new(SHOT.0, SHOT.1, SHOT.2, width, height);
    let hits = city.trace(&camera);
    run_batch(
        &tree,
        shader,
        &occluders,
        &mut soa,
        &hits,
        (width, height),
        threshold,
    )
}

/// Relative error of `value` against `exact` (largest channels).
fn relative(value: DVec3, exact: DVec3) -> f64 {
    (value - exact).abs().max_element() / exact.max_element().max(f64::MIN_POSITIVE)
}

/// The batch table: the view's hit pixels shaded by one `shade_batch` call
/// per chunk of tiles (every normal in one call: the host needs none),
/// against the exact shadowed sum per pixel, both on one core.
fn run_batch(
    tree: &manylights::LightTree,
    shader: Lambert,
    occluders: &Occluders,
    soa: &mut ShadowLights,
    hits: &[Option<Hit>],
    (width, height): (u32, u32),
    threshold: Threshold,
) -> Result<(), Box<dyn Error>> {
    let mut tiles: Vec<Vec<Hit>> = Vec::new();
    for ty in (0..height).step_by(TILE as usize) {
        for tx in (0..width).step_by(TILE as usize) {
            let mut tile = Vec::new();
            for y in ty..(ty + TILE).min(height) {
                for x in tx..(tx + TILE).min(width) {
                    if let Some(h) = hits[(y * width + x) as usize] {
                        tile.push(h);
                    }
                }
            }
            tiles.push(tile);
        }
    }
    let chunk_hits: Vec<Vec<Hit>> = tiles.chunks(CHUNK_TILES).map(|g| g.concat()).collect();
    let chunks = chunk_hits
        .iter()
        .map(|c| c.iter().map(|h| Query::new(h.point, h.normal)).collect())
        .collect::<Result<Vec<Vec<Query>>, _>>()?;
    let pixels: usize = chunks.iter().map(Vec::len).sum();
    let mut shading = tree.shading(shader);
    // The reference: the crate's f64 exact sum with the host's rays.
    let exact: Vec<Vec<DVec3>> = chunks
        .iter()
        .map(|c| {
            c.iter()
                .map(|q| shading.exact_query(q, occluders.host()))
                .collect()
        })
        .collect();
    // The baseline: the exact shadowed sum written to vectorize, one ray
    // per light above the tangent plane, fastest of the passes.
    let (mut exact_time, mut exact_rays) = (f64::INFINITY, 0);
    for _ in 0..BATCH_ROUNDS {
        let started = Instant::now();
        let mut r = 0;
        for h in chunk_hits.iter().flatten() {
            let (radiance, n) = soa.exact(h.point, h.normal, &mut occluders.host());
            std::hint::black_box(radiance);
            r += u64::from(n);
        }
        exact_time = exact_time.min(started.elapsed().as_secs_f64());
        exact_rays = r;
    }
    let (mut best, mut rays, mut classified, mut worst) = (f64::INFINITY, 0, 0, 0.0f64);
    for _ in 0..BATCH_ROUNDS {
        let started = Instant::now();
        let (mut r, mut c) = (0, 0);
        for (queries, exact) in chunks.iter().zip(&exact) {
            let mut results = vec![ShadeResult::default(); queries.len()];
            let mut host = occluders.host();
            shading.shade_batch(queries, threshold, &mut host, &mut results)?;
            r += host.rays;
            c += host.classifications();
            for (result, e) in results.iter().zip(exact) {
                if !result.certifies(*e) {
                    return Err(format!("batch: {result:?} does not certify {e}").into());
                }
                worst = worst.max(relative(result.radiance, *e));
            }
        }
        best = best.min(started.elapsed().as_secs_f64());
        (rays, classified) = (r, c);
    }
    let per = |x: f64| x / pixels.max(1) as f64;
    println!(
        "\n  batch call: {width}x{height} view, {pixels} shaded pixels, {} calls of up to {} \
         tiles of {TILE}x{TILE}; one core; fastest of {BATCH_ROUNDS} passes",
        chunks.len(),
        CHUNK_TILES
    );
    println!("| per pixel | us/px | speed-up | shadow rays/px | classifications/px | max error |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| exact shadowed sum | {:.1} | 1x | {:.0} | 0 | 0 |",
        per(exact_time) * 1e6,
        per(exact_rays as f64)
    );
    println!(
        "| shade_batch, certified {}% | {:.1} | {:.1}x | {:.0} | {:.0} | {worst:.2e} |",
        THRESHOLD * 100.0,
        per(best) * 1e6,
        exact_time / best,
        per(rays as f64),
        per(classified as f64),
    );
    Ok(())
}
