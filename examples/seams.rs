//! Seams from the discrete cut, and interpolation across levels.
//!
//! Along a dense scanline across the ground of a street-light city, measures
//! the largest jump of the relative error `(estimate - exact) / exact`
//! between neighbouring shading points, with and without
//! [`Threshold::with_interpolation`], at three thresholds, with the cost of
//! each. Then renders the paper's pair (an image and its enhanced-contrast
//! difference against the exact sum) from above, with and without
//! interpolation.
//!
//! ```text
//! cargo run --release --example seams [-- --band 2 --points 100000 --out DIR]
//! ```

use std::path::PathBuf;
use std::time::Instant;

#[path = "common/mod.rs"]
mod common;

use common::{exposure, write_difference_linear, write_radiance};
use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, PointLight, Shading, Threshold};
use rayon::prelude::*;

/// Streets every this many units, lamps every `LAMP_SPACING` along them.
const BLOCK: f32 = 40.0;
const LAMP_SPACING: f32 = 4.0;
const BLOCKS: usize = 40;
const LAMP_HEIGHT: f32 = 6.0;
/// Points along the scanline (`--points`). Dense enough that the error's
/// smooth variation between neighbours (about 3e-5 at 1% and 10,000 points)
/// falls below the jumps being measured; the jumps of the discrete cut do
/// not shrink with the spacing, those of a continuous estimate do.
const SCANLINE_POINTS: usize = 100_000;
/// Relative thresholds compared.
const THRESHOLDS: [f64; 3] = [0.01, 0.05, 0.2];
/// Interpolation band (see `Threshold::with_interpolation`).
const BAND_DEFAULT: f64 = 2.0;
/// Image side in pixels, and the threshold the images use (coarse, so that
/// seams are visible).
const IMAGE_SIZE: u32 = 256;
const IMAGE_THRESHOLD: f64 = 0.2;
/// The difference images map this relative error to white.
const DIFF_FULL_SCALE: f64 = 0.02;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.999;

fn city() -> Vec<PointLight> {
    let extent = BLOCK * BLOCKS as f32;
    let mut lights = Vec::new();
    let mut seed = 0x2545F4914F6CDD1Du64;
    let mut jitter = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    for street in 0..=BLOCKS {
        let s = street as f32 * BLOCK;
        let mut t = 0.0;
        while t <= extent {
            let warm = Vec3::new(1.0, 0.8 + 0.1 * jitter(), 0.5 + 0.2 * jitter()) * 100.0;
            lights.push(PointLight::new(Vec3::new(s, t, LAMP_HEIGHT), warm));
            lights.push(PointLight::new(Vec3::new(t, s + 1.5, LAMP_HEIGHT), warm));
            t += LAMP_SPACING;
        }
    }
    lights
}

struct Row {
    threshold: f64,
    interpolated: bool,
    max_jump: f64,
    max_error: f64,
    mean_cost: f64,
    micros: f64,
}

fn scanline(
    shading: &mut Shading<'_, Lambert>,
    exact: &[DVec3],
    points: &[Vec3],
    t: Threshold,
) -> (f64, f64, f64, f64) {
    let start = Instant::now();
    let results: Vec<_> = points
        .iter()
        .map(|&p| shading.shade(p, Vec3::Z, t).unwrap())
        .collect();
    let micros = start.elapsed().as_secs_f64() * 1e6 / points.len() as f64;
    let rel: Vec<f64> = results
        .iter()
        .zip(exact)
        .map(|(r, e)| ((r.radiance - *e) / *e).max_element())
        .collect();
    let max_jump = rel
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    let max_error = rel.iter().map(|r| r.abs()).fold(0.0, f64::max);
    let mean_cost = results.iter().map(|r| f64::from(r.cost())).sum::<f64>() / points.len() as f64;
    (max_jump, max_error, mean_cost, micros)
}

fn main() {
    let mut out = PathBuf::from("out");
    let mut band = BAND_DEFAULT;
    let mut count = SCANLINE_POINTS;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = PathBuf::from(args.next().expect("--out DIR")),
            "--points" => {
                count = args
                    .next()
                    .and_then(|n| n.parse().ok())
                    .filter(|&n: &usize| n >= 2)
                    .expect("--points N >= 2")
            }
            "--band" => {
                band = args
                    .next()
                    .and_then(|b| b.parse().ok())
                    .expect("--band NUMBER > 1")
            }
            other => panic!("unknown argument {other}"),
        }
    }
    std::fs::create_dir_all(&out).expect("output directory");
    let lights = city();
    let tree = LightTree::build(&lights).expect("valid lights");
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));

    // A diagonal scanline across several blocks, off the lamp rows.
    let (a, b) = (Vec3::new(110.0, 93.0, 0.0), Vec3::new(700.0, 517.0, 0.0));
    let points: Vec<Vec3> = (0..count)
        .map(|i| a.lerp(b, i as f32 / (count - 1) as f32))
        .collect();
    let exact: Vec<DVec3> = points
        .par_iter()
        .map(|&p| shading_exact(&tree, p))
        .collect();

    let mut rows = Vec::new();
    for &t in &THRESHOLDS {
        for interpolated in [false, true] {
            let mut th = Threshold::relative(t);
            if interpolated {
                th = th.with_interpolation(band);
            }
            let (max_jump, max_error, mean_cost, micros) =
                scanline(&mut shading, &exact, &points, th);
            rows.push(Row {
                threshold: t,
                interpolated,
                max_jump,
                max_error,
                mean_cost,
                micros,
            });
        }
    }
    println!(
        "{} lights, {} points along a scanline, band {band}\n",
        lights.len(),
        count
    );
    println!(
        "| threshold | interpolation | largest jump of rel. error | max rel. error | cost / point | time / point |"
    );
    println!("|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {:.0}% | {} | {:.2e} | {:.2e} | {:.0} | {:.1} us |",
            r.threshold * 100.0,
            if r.interpolated { "on" } else { "off" },
            r.max_jump,
            r.max_error,
            r.mean_cost,
            r.micros
        );
    }
    println!();
    for pair in rows.chunks(2) {
        println!(
            "threshold {:.0}%: jump {:.1}x smaller, cost {:.2}x, time {:.2}x",
            pair[0].threshold * 100.0,
            pair[0].max_jump / pair[1].max_jump,
            pair[1].mean_cost / pair[0].mean_cost,
            pair[1].micros / pair[0].micros
        );
    }

    // The paper's pair, seen from above over two blocks.
    let size = IMAGE_SIZE as usize;
    let origin = Vec3::new(200.0, 200.0, 0.0);
    let span = 2.0 * BLOCK;
    let pixels: Vec<Vec3> = (0..size * size)
        .map(|i| {
            let (x, y) = ((i % size) as f32 + 0.5, (i / size) as f32 + 0.5);
            origin + Vec3::new(x, y, 0.0) * (span / IMAGE_SIZE as f32)
        })
        .collect();
    let exact_img: Vec<DVec3> = pixels
        .par_iter()
        .map(|&p| shading_exact(&tree, p))
        .collect();
    let exp = exposure(&exact_img, EXPOSURE_PERCENTILE);
    write_radiance(
        &out.join("seams_exact.png"),
        IMAGE_SIZE,
        IMAGE_SIZE,
        &exact_img,
        exp,
    )
    .expect("write image");
    for interpolated in [false, true] {
        let mut th = Threshold::relative(IMAGE_THRESHOLD);
        if interpolated {
            th = th.with_interpolation(band);
        }
        let img: Vec<DVec3> = pixels
            .par_iter()
            .map_init(
                || tree.shading(Lambert::new(Vec3::splat(0.7))),
                |s, &p| s.shade(p, Vec3::Z, th).unwrap().radiance,
            )
            .collect();
        let name = if interpolated {
            "interpolated"
        } else {
            "discrete"
        };
        write_radiance(
            &out.join(format!("seams_{name}.png")),
            IMAGE_SIZE,
            IMAGE_SIZE,
            &img,
            exp,
        )
        .expect("write image");
        // Enhanced contrast: the relative error, DIFF_FULL_SCALE at white.
        let diff = out.join(format!("seams_{name}_diff.png"));
        write_difference_linear(
            &diff,
            IMAGE_SIZE,
            IMAGE_SIZE,
            &img,
            &exact_img,
            DIFF_FULL_SCALE,
        )
        .expect("write image");
    }
    println!(
        "\nimages ({IMAGE_SIZE}x{IMAGE_SIZE}, threshold {:.0}%, difference: white = {:.0}% relative error): {}/seams_{{exact,discrete,interpolated,discrete_diff,interpolated_diff}}.png",
        IMAGE_THRESHOLD * 100.0,
        DIFF_FULL_SCALE * 100.0,
        out.display()
    );
}

fn shading_exact(tree: &LightTree, p: Vec3) -> DVec3 {
    tree.shading(Lambert::new(Vec3::splat(0.7)))
        .shade_exact(p, Vec3::Z)
        .unwrap()
}
