//! Phong highlights from strings of lights: a few thousand bulbs on strings
//! hung in arcs above a glossy floor with glossy spheres, shaded with
//! `Combined::new(Lambert, Phong)` seen from a camera (the view direction
//! matters), by the light tree and by the exact sum.
//!
//! Prints the same table as the `city` example (times, speed-up, mean and
//! maximum relative error, nodes per pixel) and writes
//! `out/glossy_tree.png`, `out/glossy_exact.png`, `out/glossy_diff.png`.
//!
//! ```text
//! cargo run --release --example glossy
//! cargo run --release --example glossy -- --lights 100000 --threshold 0.02
//! ```

#[path = "common/mod.rs"]
mod common;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use common::{
    Camera, ErrorStats, Options, exposure, print_comparison, print_row, write_difference,
    write_radiance,
};
use glam::{DVec3, Vec3};
use manylights::{Combined, Lambert, LightTree, Phong, PointLight, ShadeResult, Threshold};
use rayon::prelude::*;

const DEFAULT_LIGHTS: usize = 20_000;
const DEFAULT_WIDTH: u32 = 320;
const DEFAULT_HEIGHT: u32 = 200;
const DEFAULT_THRESHOLD: f64 = 0.01;
/// Strings hang between posts along x, one every `STRING_GAP` in y.
const STRINGS: usize = 8;
const STRING_GAP: f32 = 3.0;
const STRING_SPAN: f32 = 24.0;
const STRING_HEIGHT: f32 = 4.5;
const STRING_SAG: f32 = 1.2;
/// Materials: a dark glossy floor and glossy spheres.
const FLOOR_KD: f32 = 0.02;
const FLOOR_KS: f32 = 0.6;
const SPHERE_KD: f32 = 0.04;
const SPHERE_KS: f32 = 0.8;
const EXPONENT: f32 = 300.0;
/// Spheres resting on the floor: centre (x, y) and radius.
const SPHERES: [(f32, f32, f32); 3] = [(-4.0, 6.0, 1.2), (3.0, 9.0, 1.6), (7.5, 4.0, 0.9)];
const CAMERA_EYE: Vec3 = Vec3::new(0.0, -9.0, 3.0);
const CAMERA_TARGET: Vec3 = Vec3::new(0.0, 8.0, 0.6);
const CAMERA_FOV_DEGREES: f32 = 60.0;
const EXPOSURE_PERCENTILE: f64 = 0.995;

/// A surface hit: point, normal, which material.
#[derive(Clone, Copy)]
struct Hit {
    point: Vec3,
    normal: Vec3,
    sphere: bool,
}

/// Bulbs along sagging strings, one colour per string.
fn strings(count: usize) -> Vec<PointLight> {
    let palette = [
        Vec3::new(1.0, 0.25, 0.15),
        Vec3::new(1.0, 0.75, 0.2),
        Vec3::new(0.3, 1.0, 0.35),
        Vec3::new(0.3, 0.5, 1.0),
    ];
    let per_string = count.div_ceil(STRINGS);
    (0..count)
        .map(|i| {
            let (s, k) = (i / per_string, i % per_string);
            let u = k as f32 / (per_string - 1).max(1) as f32; // 0..1 along the string
            let x = (u - 0.5) * STRING_SPAN;
            let y = s as f32 * STRING_GAP;
            let z = STRING_HEIGHT - STRING_SAG * (1.0 - (2.0 * u - 1.0).powi(2));
            PointLight::new(Vec3::new(x, y, z), palette[s % palette.len()] * 0.05)
        })
        .collect()
}

/// Nearest hit of the ray with the floor (z = 0) or a sphere.
fn intersect(origin: Vec3, dir: Vec3) -> Option<Hit> {
    let mut best: Option<(f32, Hit)> = None;
    if dir.z < 0.0 {
        let t = -origin.z / dir.z;
        let point = origin + t * dir;
        best = Some((
            t,
            Hit {
                point,
                normal: Vec3::Z,
                sphere: false,
            },
        ));
    }
    for &(x, y, r) in &SPHERES {
        let centre = Vec3::new(x, y, r);
        let oc = origin - centre;
        let b = oc.dot(dir);
        let disc = b * b - (oc.length_squared() - r * r);
        if disc < 0.0 {
            continue;
        }
        let t = -b - disc.sqrt();
        if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
            let point = origin + t * dir;
            best = Some((
                t,
                Hit {
                    point,
                    normal: (point - centre) / r,
                    sphere: true,
                },
            ));
        }
    }
    best.map(|(_, h)| h)
}

fn material(hit: &Hit) -> Combined<Lambert, Phong> {
    let (kd, ks) = if hit.sphere {
        (SPHERE_KD, SPHERE_KS)
    } else {
        (FLOOR_KD, FLOOR_KS)
    };
    Combined::new(
        Lambert::new(Vec3::splat(kd)),
        Phong::new(Vec3::splat(ks), EXPONENT),
    )
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(Options {
        lights: DEFAULT_LIGHTS,
        width: DEFAULT_WIDTH,
        height: DEFAULT_HEIGHT,
        threshold: DEFAULT_THRESHOLD,
        out: PathBuf::from("out"),
        shadows: false,
    });
    let lights = strings(options.lights);
    let start = Instant::now();
    let tree = LightTree::build(&lights)?;
    let build_time = start.elapsed();
    let camera = Camera::new(
        CAMERA_EYE,
        CAMERA_TARGET,
        CAMERA_FOV_DEGREES,
        options.width,
        options.height,
    );
    let rays: Vec<(Vec3, Option<Hit>)> = (0..options.height)
        .flat_map(|y| (0..options.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let dir = camera.ray(x, y);
            (dir, intersect(CAMERA_EYE, dir))
        })
        .collect();
    let threshold = Threshold::relative(options.threshold);

    let start = Instant::now();
    let tree_results: Vec<Option<ShadeResult>> = rays
        .par_iter()
        .map(|(dir, hit)| {
            hit.map(|h| {
                tree.shading(material(&h))
                    .shade_view(h.point, h.normal, -*dir, threshold)
            })
            .transpose()
        })
        .collect::<Result<_, _>>()?;
    let tree_time = start.elapsed();

    let start = Instant::now();
    let exact: Vec<Option<DVec3>> = rays
        .par_iter()
        .map(|(dir, hit)| {
            hit.map(|h| {
                tree.shading(material(&h))
                    .shade_exact_view(h.point, h.normal, -*dir)
            })
            .transpose()
        })
        .collect::<Result<_, _>>()?;
    let exact_time = start.elapsed();

    let stats = ErrorStats::new(&tree_results, &exact);
    println!("light strings over a glossy floor and spheres, Lambert + Phong (e = {EXPONENT})");
    print_row("lights", tree.len());
    print_row("image", format!("{}x{}", options.width, options.height));
    print_row("threshold (relative)", options.threshold);
    print_comparison(build_time, tree_time, exact_time, &tree_results, &stats);

    let black = |v: Option<DVec3>| v.unwrap_or(DVec3::ZERO);
    let tree_img: Vec<DVec3> = tree_results
        .iter()
        .map(|r| black(r.map(|r| r.radiance)))
        .collect();
    let exact_img: Vec<DVec3> = exact.iter().map(|&e| black(e)).collect();
    let exp = exposure(&exact_img, EXPOSURE_PERCENTILE);
    std::fs::create_dir_all(&options.out)?;
    let (w, h) = (options.width, options.height);
    write_radiance(&options.out.join("glossy_tree.png"), w, h, &tree_img, exp)?;
    write_radiance(&options.out.join("glossy_exact.png"), w, h, &exact_img, exp)?;
    write_difference(
        &options.out.join("glossy_diff.png"),
        w,
        h,
        &tree_img,
        &exact_img,
        options.threshold,
    )?;
    println!(
        "  images: {}/glossy_{{tree,exact,diff}}.png",
        options.out.display()
    );
    if stats.violations > 0 {
        return Err(format!("{} pixels violate the certified bound", stats.violations).into());
    }
    Ok(())
}
