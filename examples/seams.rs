//! Seams from the discrete cut, and interpolation across levels.
//!
//! Along a dense scanline across the ground of a grid of street lamps,
//! measures the largest jump of the relative error `(estimate - exact) /
//! exact` between neighbouring shading points, with and without
//! [`Threshold::with_interpolation`], at three thresholds, with the cost of
//! each. Then the same near the horizon: lights over a sphere, seen by
//! panels in orbit whose tangent plane cuts through it, so that many nodes
//! straddle the plane; there each scanline is sampled at two densities, so
//! that real jumps (which do not shrink when the points are 10x closer) are
//! told apart from the error's smooth variation (which does). Then a
//! scanline that crosses just inside a shell of lights, where the balls of
//! ever smaller nodes reach the points (such a node has no finite bound
//! and must be refined), shaded point by point and by the batch call, with
//! the evaluations each costs. Last, renders
//! the paper's pair (an image and its enhanced-contrast difference against
//! the exact sum) from above, with and without interpolation.
//!
//! ```text
//! cargo run --release --example seams
//! ```
//!
//! Output: `out/seams_{exact,discrete,interpolated,discrete_diff,interpolated_diff}.png`.

use std::error::Error;
use std::path::Path;

use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, Query, ShadeResult, Shading, Threshold, Unoccluded};
use manylights_report::compare::timed;
use manylights_report::image::{exposure, write_difference_linear, write_radiance};
use manylights_report::scenes::{GRID_BLOCK, SPHERE_RADIUS, lamp_grid, sphere_lights};
use rayon::prelude::*;

const BLOCKS: usize = 40;
const SEED: u64 = 1998;
/// Points along the scanline. Dense enough that the error's
/// smooth variation between neighbours (about 3e-5 at 1% and 10,000 points)
/// falls below the jumps being measured; the jumps of the discrete cut do
/// not shrink with the spacing, those of a continuous estimate do.
const SCANLINE_POINTS: usize = 100_000;
/// A diagonal scanline across several blocks, off the lamp rows.
const SCANLINE: (Vec3, Vec3) = (Vec3::new(110.0, 93.0, 0.0), Vec3::new(700.0, 517.0, 0.0));
/// Relative thresholds compared.
const THRESHOLDS: [f64; 3] = [0.01, 0.05, 0.2];
/// Interpolation band (see `Threshold::with_interpolation`).
const BAND: f64 = 2.0;
/// Image side in pixels, its corner on the ground, and the threshold the
/// images use (coarse, so that seams are visible).
const IMAGE_SIZE: u32 = 256;
const IMAGE_ORIGIN: Vec3 = Vec3::new(200.0, 200.0, 0.0);
const IMAGE_THRESHOLD: f64 = 0.2;
/// The difference images map this relative error to white.
const DIFF_FULL_SCALE: f64 = 0.02;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.999;
const ALBEDO: f32 = 0.7;
/// Lights on the sphere of the horizon scanlines.
const SPHERE_LIGHTS: usize = 20_000;
/// Points along each horizon scanline: the coarse and the dense sampling.
const HORIZON_POINTS: [usize; 2] = [10_000, 100_000];
/// Lights on the sphere of the shell scanline.
const SHELL_LIGHTS: usize = 100_000;
/// The shell scanline: a chord 0.99 radii from the sphere's centre, which
/// crosses just inside the shell and out again, and its points' normal,
/// whose tangent plane cuts the sphere.
const SHELL: (Vec3, Vec3, Vec3) = (
    Vec3::new(
        -0.25 * SPHERE_RADIUS,
        0.05 * SPHERE_RADIUS,
        0.99 * SPHERE_RADIUS,
    ),
    Vec3::new(
        0.25 * SPHERE_RADIUS,
        0.05 * SPHERE_RADIUS,
        0.99 * SPHERE_RADIUS,
    ),
    Vec3::new(0.6, 0.3, 1.0),
);

/// The horizon scanlines: name, ends, normal. Both run 300 units above the
/// sphere's centre across its width; the plane through a point sweeps
/// across the sphere with the point.
const HORIZON: [(&str, Vec3, Vec3, Vec3); 2] = [
    (
        "sweeping",
        Vec3::new(-0.9 * SPHERE_RADIUS, 10.0, 3.0 * SPHERE_RADIUS),
        Vec3::new(0.9 * SPHERE_RADIUS, 10.0, 3.0 * SPHERE_RADIUS),
        Vec3::X,
    ),
    (
        "tilted",
        Vec3::new(-1.5 * SPHERE_RADIUS, 10.0, 3.0 * SPHERE_RADIUS),
        Vec3::new(1.5 * SPHERE_RADIUS, 10.0, 3.0 * SPHERE_RADIUS),
        Vec3::new(1.0, 0.0, -0.5),
    ),
];

/// The radiance at `points` (normal `+z`), in parallel: the tree at
/// `threshold`, or the exact sum with `None`.
fn shade(tree: &LightTree, points: &[Vec3], threshold: Option<Threshold>) -> Vec<DVec3> {
    shade_facing(tree, points, Vec3::Z, threshold)
}

/// [`shade`] with the points facing `normal`.
fn shade_facing(
    tree: &LightTree,
    points: &[Vec3],
    normal: Vec3,
    threshold: Option<Threshold>,
) -> Vec<DVec3> {
    let session = || tree.shading(Lambert::new(Vec3::splat(ALBEDO)));
    let shade = |s: &mut Shading<'_, Lambert>, &p: &Vec3| match threshold {
        Some(t) => s.shade(p, normal, t).map(|r| r.radiance),
        None => s.exact(p, normal),
    };
    let shaded = points.par_iter().map_init(session, shade);
    shaded
        .collect::<Result<_, _>>()
        .expect("the scanlines' points and normals are valid")
}

/// The largest jump of the relative error (largest channel) between
/// neighbours of a scanline.
fn largest_jump(results: &[DVec3], exact: &[DVec3]) -> f64 {
    let rel: Vec<f64> = results
        .iter()
        .zip(exact)
        .map(|(r, e)| ((*r - *e) / *e).max_element())
        .collect();
    rel.windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max)
}

/// `count` points evenly along the segment `a`-`b`.
fn along(a: Vec3, b: Vec3, count: usize) -> Vec<Vec3> {
    (0..count)
        .map(|i| a.lerp(b, i as f32 / (count - 1) as f32))
        .collect()
}

/// The horizon table: per scanline, threshold and density, the largest
/// jump without and with interpolation.
fn horizon(band: f64) -> Result<(), Box<dyn Error>> {
    let tree = LightTree::build(&sphere_lights(SPHERE_LIGHTS, SEED))?;
    println!(
        "\nHorizon: {} lights over a sphere of radius {SPHERE_RADIUS}, panels {} units above its \
         centre whose tangent plane cuts it; largest jump of the relative error\n",
        tree.len(),
        3.0 * SPHERE_RADIUS
    );
    println!("| scanline | threshold | points | interpolation off | on | smaller by |");
    println!("|---|---|---|---|---|---|");
    for (name, a, b, normal) in HORIZON {
        let normal = normal.normalize();
        for count in HORIZON_POINTS {
            let points = along(a, b, count);
            let exact = shade_facing(&tree, &points, normal, None);
            for t in THRESHOLDS {
                let discrete = Threshold::relative(t);
                let [off, on] = [discrete, discrete.with_interpolation(band)].map(|th| {
                    largest_jump(&shade_facing(&tree, &points, normal, Some(th)), &exact)
                });
                println!(
                    "| {name} | {:.0}% | {count} | {off:.2e} | {on:.2e} | {:.1}x |",
                    t * 100.0,
                    off / on
                );
            }
        }
    }
    Ok(())
}

/// The points facing `normal` shaded by one batch call at `threshold` (on
/// one thread, the points in scanline order).
fn shade_batch(
    tree: &LightTree,
    points: &[Vec3],
    normal: Vec3,
    threshold: Threshold,
) -> Vec<ShadeResult> {
    let mut shading = tree.shading(Lambert::new(Vec3::splat(ALBEDO)));
    let queries: Vec<Query> = points
        .iter()
        .map(|&p| Query::new(p, normal))
        .collect::<Result<_, _>>()
        .expect("the scanline's points and normals are valid");
    let mut results = vec![ShadeResult::default(); queries.len()];
    shading
        .shade_batch(&queries, threshold, Unoccluded, &mut results)
        .expect("as many results as queries");
    results
}

/// The shell table: per density, threshold and way of shading (point by
/// point, or by the batch call), the largest jump without and with
/// interpolation and the evaluations per point of each.
fn shell(band: f64) -> Result<(), Box<dyn Error>> {
    let tree = LightTree::build(&sphere_lights(SHELL_LIGHTS, SEED))?;
    let (a, b, normal) = SHELL;
    let normal = normal.normalize();
    println!(
        "\nShell: {} lights over a sphere of radius {SPHERE_RADIUS}, points along a chord {} \
         units from its centre (crossing just inside the shell); largest jump of the relative \
         error, and evaluations per point\n",
        tree.len(),
        0.99 * SPHERE_RADIUS
    );
    println!(
        "| threshold | points | call | interpolation off | on | smaller by | evaluations off | on |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut shading = tree.shading(Lambert::new(Vec3::splat(ALBEDO)));
    for count in HORIZON_POINTS {
        let points = along(a, b, count);
        let exact = shade_facing(&tree, &points, normal, None);
        for t in THRESHOLDS {
            let discrete = Threshold::relative(t);
            for call in ["shade", "shade_batch"] {
                let [off, on] = [discrete, discrete.with_interpolation(band)].map(|th| {
                    let results: Vec<ShadeResult> = if call == "shade" {
                        let shade = |&p: &Vec3| shading.shade(p, normal, th).expect("valid point");
                        points.iter().map(shade).collect()
                    } else {
                        shade_batch(&tree, &points, normal, th)
                    };
                    let radiance: Vec<DVec3> = results.iter().map(|r| r.radiance).collect();
                    let cost = results.iter().map(|r| f64::from(r.cost())).sum::<f64>();
                    (largest_jump(&radiance, &exact), cost / count as f64)
                });
                println!(
                    "| {:.0}% | {count} | {call} | {:.2e} | {:.2e} | {:.1}x | {:.0} | {:.0} |",
                    t * 100.0,
                    off.0,
                    on.0,
                    off.0 / on.0,
                    off.1,
                    on.1
                );
            }
        }
    }
    Ok(())
}

/// One row of the table: the largest jump of the relative error between
/// neighbours, the largest relative error, the mean cost and the time per
/// point (one thread).
fn scanline(tree: &LightTree, points: &[Vec3], exact: &[DVec3], t: Threshold) -> [f64; 4] {
    let mut shading = tree.shading(Lambert::new(Vec3::splat(ALBEDO)));
    let (results, time) = timed(|| {
        let shade = |&p: &Vec3| shading.shade(p, Vec3::Z, t).expect("valid point");
        points.iter().map(shade).collect::<Vec<_>>()
    });
    let radiance: Vec<DVec3> = results.iter().map(|r| r.radiance).collect();
    let largest_error = radiance
        .iter()
        .zip(exact)
        .map(|(r, e)| ((*r - *e) / *e).abs().max_element())
        .fold(0.0, f64::max);
    let n = points.len() as f64;
    [
        largest_jump(&radiance, exact),
        largest_error,
        results.iter().map(|r| f64::from(r.cost())).sum::<f64>() / n,
        time.as_secs_f64() * 1e6 / n,
    ]
}

fn main() -> Result<(), Box<dyn Error>> {
    let (out, band, count) = (Path::new("out"), BAND, SCANLINE_POINTS);
    let tree = LightTree::build(&lamp_grid(BLOCKS, SEED))?;
    let (a, b) = SCANLINE;
    let points = along(a, b, count);
    let exact = shade(&tree, &points, None);

    println!(
        "{} lights, {count} points along a scanline, band {band}\n",
        tree.len()
    );
    println!(
        "| threshold | interpolation | largest jump of rel. error | max rel. error | cost / point \
         | time / point |"
    );
    println!("|---|---|---|---|---|---|");
    let mut ratios = Vec::new();
    for t in THRESHOLDS {
        let discrete = Threshold::relative(t);
        let rows = [discrete, discrete.with_interpolation(band)]
            .map(|th| scanline(&tree, &points, &exact, th));
        for ([jump, max_error, cost, micros], on) in rows.iter().zip(["off", "on"]) {
            println!(
                "| {:.0}% | {on} | {jump:.2e} | {max_error:.2e} | {cost:.0} | {micros:.1} us |",
                t * 100.0
            );
        }
        let [off, on] = rows;
        ratios.push((t, off[0] / on[0], on[2] / off[2], on[3] / off[3]));
    }
    println!();
    for (t, jump, cost, time) in ratios {
        println!(
            "threshold {:.0}%: jump {jump:.1}x smaller, cost {cost:.2}x, time {time:.2}x",
            t * 100.0
        );
    }
    horizon(band)?;
    shell(band)?;

    // The paper's pair, seen from above over two blocks.
    let side = IMAGE_SIZE as usize;
    let pixel = 2.0 * GRID_BLOCK / IMAGE_SIZE as f32;
    let pixels: Vec<Vec3> = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32 + 0.5, (i / side) as f32 + 0.5);
            IMAGE_ORIGIN + Vec3::new(x, y, 0.0) * pixel
        })
        .collect();
    std::fs::create_dir_all(out)?;
    let exact_img = shade(&tree, &pixels, None);
    let exp = exposure(&exact_img, EXPOSURE_PERCENTILE);
    let size = (IMAGE_SIZE, IMAGE_SIZE);
    write_radiance(&out.join("seams_exact.png"), size, &exact_img, exp)?;
    for (name, th) in [
        ("discrete", Threshold::relative(IMAGE_THRESHOLD)),
        (
            "interpolated",
            Threshold::relative(IMAGE_THRESHOLD).with_interpolation(band),
        ),
    ] {
        let img = shade(&tree, &pixels, Some(th));
        let path = out.join(format!("seams_{name}.png"));
        write_radiance(&path, size, &img, exp)?;
        // Enhanced contrast: the relative error, DIFF_FULL_SCALE at white.
        let diff = out.join(format!("seams_{name}_diff.png"));
        write_difference_linear(&diff, size, &img, &exact_img, DIFF_FULL_SCALE)?;
    }
    println!(
        "\nimages ({IMAGE_SIZE}x{IMAGE_SIZE}, threshold {:.0}%, difference: white = {:.0}% \
         relative error): {}/seams_{{exact,discrete,interpolated,discrete_diff,interpolated_diff}}.png",
        IMAGE_THRESHOLD * 100.0,
        DIFF_FULL_SCALE * 100.0,
        out.display()
    );
    Ok(())
}
