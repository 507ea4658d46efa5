//! A glTF 2.0 scene in, a picture out: meshes occlude and receive light,
//! `KHR_lights_punctual` point and spot lights emit (spots through their
//! cones, the Khronos falloff, as `manylights::Emission::spot`), shaded through
//! `Shading::shade_batch` with shadows from `manylights-mesh`'s host at a
//! certified threshold, from the scene's camera (or a default one).
//!
//! ```text
//! cargo run --release -p manylights-mesh --example gltf -- scene.glb   # your scene
//! cargo run --release -p manylights-mesh --example gltf                # a built-in street, 700 lights
//! cargo run --release -p manylights-mesh --example gltf -- scene.glb --size 640x360 --threshold 0.02 --out out
//! cargo run --release -p manylights-mesh --example gltf -- scene.glb --solids
//! ```
//!
//! With `--solids` (the default for the built-in street, whose buildings
//! are closed boxes; `--surfaces` turns it off), every closed mesh is an
//! opaque solid (`OccludersBuilder::solid`): boxes found inside it let the
//! host prove that it hides a node as a whole. Leave it off for a scene
//! seen from inside a closed mesh (a room).
//!
//! Writes `<out>/gltf_tree.png` (the certified render) and
//! `<out>/gltf_diff.png` (its error against the exact shadowed sum, one
//! shadow ray per light and pixel: `log10` of the relative error, black at
//! `1e-4` of the threshold, white at the threshold), checks the certified
//! bound at every pixel, and fails if it breaks.

mod scene;

use std::error::Error;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, Query, ShadeResult, Threshold};
use manylights_mesh::{Occluders, box_mesh, open_edges};
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use rayon::prelude::*;
use scene::{LightSpec, MeshSpec, Scene, View};

/// Pixels per batch call: a square tile, whose neighbouring pixels share
/// cuts.
const TILE: u32 = 16;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let (mut path, mut size, mut threshold, mut out, mut solids) =
        (None, (320, 180), 0.01, PathBuf::from("out"), None);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--size" => {
                let s = args.next().ok_or("--size needs WxH")?;
                let (w, h) = s.split_once('x').ok_or("--size needs WxH")?;
                size = (w.parse()?, h.parse()?);
            }
            "--threshold" => {
                threshold = args.next().ok_or("--threshold needs a number")?.parse()?
            }
            "--out" => out = args.next().ok_or("--out needs a folder")?.into(),
            "--solids" => solids = Some(true),
            "--surfaces" => solids = Some(false),
            _ => path = Some(PathBuf::from(arg)),
        }
    }
    if size.0 == 0 || size.1 == 0 {
        return Err("--size needs a width and a height of at least 1".into());
    }
    if !(threshold > 0.0 && threshold < 1.0) {
        return Err(
            format!("--threshold {threshold}: a relative error in (0, 1) is needed").into(),
        );
    }
    let scene = match &path {
        Some(path) => {
            let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            scene::load(&bytes, path.parent()).map_err(|e| format!("{}: {e}", path.display()))?
        }
        None => {
            println!("no scene given: rendering the built-in street (written as glTF in memory)");
            scene::load(&builtin(), None)?
        }
    };
    if scene.directional > 0 {
        println!("note: {} directional lights skipped", scene.directional);
    }
    // Solids by default only for the built-in street.
    let solids = solids.unwrap_or(path.is_none());
    render(&scene, size, threshold, &out, solids)
}

/// The scene's triangles as occluders: with `solids`, each closed mesh as a
/// solid and the others as loose triangles.
fn occluders(scene: &Scene, solids: bool) -> Result<Occluders, Box<dyn Error>> {
    let mut builder = Occluders::builder();
    let mut loose = Vec::new();
    for range in &scene.meshes {
        let triangles = &scene.triangles[range.clone()];
        if solids && open_edges(triangles) == 0 {
            let positions: Vec<Vec3> = triangles.iter().flatten().copied().collect();
            let indices: Vec<u32> = (0..positions.len() as u32).collect();
            builder = builder.solid(&positions, &indices)?;
        } else {
            loose.extend_from_slice(triangles);
        }
    }
    if !loose.is_empty() {
        builder = builder.triangles(&loose)?;
    }
    Ok(builder.build())
}

/// The built-in scene: a street of box buildings on a ground, lit windows
/// on the façades, lamps along both kerbs (every fourth a spot light) and
/// strings of small lights across the street, with a camera above it.
fn builtin() -> Vec<u8> {
    let mut meshes = vec![MeshSpec {
        positions: vec![
            Vec3::new(-30.0, -10.0, 0.0),
            Vec3::new(130.0, -10.0, 0.0),
            Vec3::new(130.0, 40.0, 0.0),
            Vec3::new(-30.0, 40.0, 0.0),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
        colour: Vec3::new(0.4, 0.4, 0.42),
    }];
    let mut lights = Vec::new();
    // A small deterministic generator: the scene is the same every run.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    // The street runs along x between y = 10 and y = 20.
    for side in [false, true] {
        for k in 0..8 {
            let x = k as f32 * 12.5;
            let (w, d, h) = (9.0 + 2.0 * next(), 6.0 + 4.0 * next(), 8.0 + 22.0 * next());
            let y = if side { 20.0 } else { 10.0 - d };
            let b = manylights::Aabb {
                min: Vec3::new(x, y, 0.0),
                max: Vec3::new(x + w, y + d, h),
            };
            let (corners, indices) = box_mesh(&b);
            let tint = 0.3 + 0.4 * next();
            meshes.push(MeshSpec {
                positions: corners.to_vec(),
                indices: indices.to_vec(),
                colour: Vec3::new(tint, tint * 0.95, tint * 0.9),
            });
            // Lit windows just off the façade facing the street.
            let face = if side { b.min.y - 0.3 } else { b.max.y + 0.3 };
            let mut z = 2.0;
            while z < h - 1.0 {
                let mut wx = x + 1.0;
                while wx < x + w - 0.5 {
                    if next() < 0.45 {
                        let warm = Vec3::new(1.0, 0.75 + 0.1 * next(), 0.45 + 0.1 * next());
                        lights.push(LightSpec {
                            position: Vec3::new(wx, face, z),
                            colour: warm,
                            intensity: 0.8 + next(),
                            spot: false,
                        });
                    }
                    wx += 1.5;
                }
                z += 3.0;
            }
        }
    }
    // Street lamps along both kerbs, every fourth a spot light.
    for k in 0..40 {
        for y in [11.0, 19.0] {
            lights.push(LightSpec {
                position: Vec3::new(k as f32 * 2.5, y, 4.5 + next()),
                colour: Vec3::new(1.0, 0.55, 0.2),
                intensity: 12.0,
                spot: k % 4 == 0,
            });
        }
    }
    // Strings of small lights across the street, sagging in the middle.
    for k in 0..20 {
        for j in 0..=16 {
            let y = 10.5 + 9.0 * j as f32 / 16.0;
            let sag = 1.5 * (1.0 - ((y - 15.0) / 4.5).powi(2));
            let hue = [
                Vec3::new(1.0, 0.3, 0.2),
                Vec3::new(0.3, 1.0, 0.4),
                Vec3::new(0.3, 0.5, 1.0),
            ];
            lights.push(LightSpec {
                position: Vec3::new(2.5 + k as f32 * 5.0, y, 8.0 - sag),
                colour: hue[(j + k) % 3],
                intensity: 0.6,
                spot: false,
            });
        }
    }
    let view = View {
        eye: Vec3::new(-14.0, 15.0, 16.0),
        target: Vec3::new(50.0, 15.0, 0.0),
        up: Vec3::Z,
        yfov: 50f32.to_radians(),
    };
    scene::write_glb(&meshes, &lights, Some(view))
}

/// A primary-ray hit: point, normal facing the eye, albedo.
#[derive(Clone, Copy, Debug)]
struct Hit {
    point: Vec3,
    normal: Vec3,
    albedo: Vec3,
}

/// Renders `scene`, writes the images and checks the bound.
fn render(
    scene: &Scene,
    (width, height): (u32, u32),
    threshold: f64,
    out: &Path,
    solids: bool,
) -> Result<(), Box<dyn Error>> {
    let occluders = occluders(scene, solids)?;
    let tree = LightTree::build_emitters(&scene.lights)?;
    let view = scene.view.unwrap_or_else(|| default_view(scene));
    println!(
        "{} triangles ({} dropped as degenerate; {} boxes found inside closed meshes), \
         {} lights ({} spots), {width}x{height}, certified {}%",
        occluders.triangles(),
        scene.degenerate,
        occluders.solid_boxes().len(),
        scene.lights.len(),
        scene.spots,
        threshold * 100.0
    );
    let hits = trace(scene, view, width, height);
    let tiles = tiles(&hits, width, height);
    let certified = Threshold::relative(threshold);
    let session = || tree.shading(Lambert::new(Vec3::ONE));

    let started = Instant::now();
    let shaded: Vec<(Vec<ShadeResult>, u64, u64)> = tiles
        .par_iter()
        .map_init(
            || (session(), occluders.host()),
            |(shading, host), pixels| {
                let queries: Vec<Query> = pixels
                    .iter()
                    .map(|&i| {
                        let h = hits[i].expect("only hit pixels are tiled");
                        Query::new(h.point, h.normal).expect("finite hits")
                    })
                    .collect();
                let mut results = vec![ShadeResult::default(); queries.len()];
                let (rays, classified) = (host.rays, host.classifications());
                shading
                    .shade_batch(&queries, certified, &mut *host, &mut results)
                    .expect("valid threshold and lengths");
                (
                    results,
                    host.rays - rays,
                    host.classifications() - classified,
                )
            },
        )
        .collect();
    let tree_time = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let exact: Vec<Vec<DVec3>> = tiles
        .par_iter()
        .map_init(session, |shading, pixels| {
            pixels
                .iter()
                .map(|&i| {
                    let h = hits[i].expect("hit");
                    let q = Query::new(h.point, h.normal).expect("finite hits");
                    shading.exact_query(&q, occluders.host())
                })
                .collect()
        })
        .collect();
    let exact_time = started.elapsed().as_secs_f64();

    let mut image = vec![DVec3::ZERO; (width * height) as usize];
    let mut error = vec![0.0f64; image.len()];
    let (mut broken, mut worst, mut rays, mut classified, mut pixels) = (0, 0.0f64, 0, 0, 0);
    for ((tile, (results, r, c)), exact) in tiles.iter().zip(&shaded).zip(&exact) {
        rays += r;
        classified += c;
        for ((&i, result), &e) in tile.iter().zip(results).zip(exact) {
            pixels += 1;
            broken += usize::from(!result.certifies(e));
            let albedo = hits[i].expect("hit").albedo.as_dvec3();
            image[i] = result.radiance * albedo;
            let relative = (result.radiance - e).abs().max_element() / e.max_element().max(1e-300);
            worst = worst.max(relative);
            error[i] = relative;
        }
    }
    let per = |x: u64| x as f64 / f64::from(pixels.max(1));
    println!(
        "shade_batch: {:.2} s ({:.1} shadow rays and {:.1} classifications per pixel); exact \
         shadowed sum: {:.2} s ({} rays per pixel); {:.1}x",
        tree_time,
        per(rays),
        per(classified),
        exact_time,
        scene.lights.len(),
        exact_time / tree_time
    );
    println!("largest relative error {worst:.2e} (threshold {threshold})");
    std::fs::create_dir_all(out)?;
    write_png(&out.join("gltf_tree.png"), width, height, &tone(&image))?;
    write_png(
        &out.join("gltf_diff.png"),
        width,
        height,
        &error_image(&error, threshold),
    )?;
    println!(
        "wrote {} and {}",
        out.join("gltf_tree.png").display(),
        out.join("gltf_diff.png").display()
    );
    if broken > 0 {
        return Err(format!("the certified bound broke at {broken} pixels").into());
    }
    Ok(())
}

/// A camera looking at the middle of the scene's box from above one corner.
fn default_view(scene: &Scene) -> View {
    let (lo, hi) = scene
        .triangles
        .iter()
        .flatten()
        .chain(scene.lights.iter().map(|l| &l.light.position))
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let (centre, size) = (0.5 * (lo + hi), (hi - lo).max_element().max(1e-3));
    View {
        eye: centre + Vec3::new(-0.9, -0.9, 0.7) * size,
        target: centre,
        up: if (hi - lo).z <= (hi - lo).y {
            Vec3::Z
        } else {
            Vec3::Y
        },
        yfov: 45f32.to_radians(),
    }
}

/// The nearest triangle along each pixel's ray (through a BVH of `obvhs`,
/// its Möller-Trumbore test), row-major, `None` for the sky.
fn trace(scene: &Scene, view: View, width: u32, height: u32) -> Vec<Option<Hit>> {
    let triangles: Vec<Triangle> = scene
        .triangles
        .iter()
        .map(|t| Triangle {
            v0: t[0].into(),
            v1: t[1].into(),
            v2: t[2].into(),
        })
        .collect();
    let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(
        &triangles,
        obvhs::BvhBuildParams::medium_build(),
        &mut std::time::Duration::default(),
    );
    let forward = (view.target - view.eye).normalize();
    let right = forward.cross(view.up).normalize();
    let up = right.cross(forward);
    let half = (0.5 * view.yfov).tan();
    let aspect = width as f32 / height as f32;
    (0..width * height)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % width, i / width);
            let sx = (2.0 * (x as f32 + 0.5) / width as f32 - 1.0) * half * aspect;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / height as f32) * half;
            let dir = (forward + right * sx + up * sy).normalize();
            let ray = Ray::new_inf(view.eye.into(), dir.into());
            let mut hit = RayHit::none();
            let found = bvh.ray_traverse(ray, &mut hit, |ray, id| {
                triangles[bvh.primitive_indices[id] as usize].intersect(ray)
            });
            if !found {
                return None;
            }
            let k = bvh.primitive_indices[hit.primitive_id as usize] as usize;
            let t = &scene.triangles[k];
            let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
            let normal = if normal.dot(dir) > 0.0 {
                -normal
            } else {
                normal
            };
            let point = view.eye + dir * hit.t;
            (normal != Vec3::ZERO).then_some(Hit {
                point,
                normal,
                albedo: scene.albedo[k],
            })
        })
        .collect()
}

/// The hit pixels in square tiles, row-major (and row-major in a tile).
fn tiles(hits: &[Option<Hit>], width: u32, height: u32) -> Vec<Vec<usize>> {
    let mut tiles = Vec::new();
    for ty in (0..height).step_by(TILE as usize) {
        for tx in (0..width).step_by(TILE as usize) {
            let tile: Vec<usize> = (ty..(ty + TILE).min(height))
                .flat_map(|y| (tx..(tx + TILE).min(width)).map(move |x| (y * width + x) as usize))
                .filter(|&i| hits[i].is_some())
                .collect();
            if !tile.is_empty() {
                tiles.push(tile);
            }
        }
    }
    tiles
}

/// 8-bit sRGB of a linear image exposed so that its 98th percentile is
/// white.
fn tone(image: &[DVec3]) -> Vec<u8> {
    let mut levels: Vec<f64> = image
        .iter()
        .map(|c| c.max_element())
        .filter(|&v| v > 0.0)
        .collect();
    levels.sort_by(f64::total_cmp);
    let white = levels
        .get(levels.len() * 980 / 1000)
        .copied()
        .unwrap_or(1.0)
        .max(1e-300);
    image
        .iter()
        .flat_map(|c| (*c / white).to_array())
        .map(|v| {
            let v = v.clamp(0.0, 1.0);
            let s = if v <= 0.003_130_8 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0).round() as u8
        })
        .collect()
}

/// Grey levels of `log10(error / threshold)` from -4 (black) to 0 (white).
fn error_image(error: &[f64], threshold: f64) -> Vec<u8> {
    error
        .iter()
        .flat_map(|&e| {
            let level = ((e / threshold).max(1e-300).log10() + 4.0) / 4.0;
            let g = (level.clamp(0.0, 1.0) * 255.0).round() as u8;
            [g, g, g]
        })
        .collect()
}

fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), Box<dyn Error>> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(rgb)?;
    Ok(())
}
