//! A path tracer's direct lighting: the night city of the `city` example,
//! each pixel shaded by a few lights sampled one at a time, `f / pmf`
//! averaged, as a path tracer's next-event estimation does.
//!
//! Two samplers render the same view at equal time: the crate's
//! [`LightSampler`](manylights::LightSampler) (children chosen by
//! estimates of their contributions clamped into their certified bounds)
//! and pbrt-v4's `BVHLightSampler`
//! importance (its `LightBounds::Importance` descent, written from its
//! public description in the report's `sampling` module) on the same tree.
//! The crate's sampler gets `--spp` samples per pixel; pbrt-v4's the
//! number of samples that takes the same time (measured). Both images are
//! written beside the exact sum, with their relative-error images, and the
//! example prints the times and the mean squared relative errors.
//!
//! ```text
//! cargo run --release --example sampling
//! cargo run --release --example sampling -- --lights 1000000 --spp 8 --out out
//! ```
//!
//! Output: `out/sampling_{exact,crate,pbrt,crate_err,pbrt_err}.png`. The
//! error images show `|estimate - exact| / exact` (largest channel) on a
//! logarithmic grey scale: 100% or more white, `10^-4` black.

use std::error::Error;
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3};
use manylights::query::WithView;
use manylights::shader::Shader;
use manylights::{Lambert, PointLight, Query};
use manylights_report::compare::print_row;
use manylights_report::image::{exposure, write_difference, write_radiance};
use manylights_report::options::Options;
use manylights_report::raycast::{CityView, Hit, Shot};
use manylights_report::sampling::{CratePick, OneSample, PbrtPick};
use manylights_report::scenes::rng;
use rand::RngExt;
use rayon::prelude::*;

/// The city and the shot of the `city` example.
const BLOCKS: u32 = 50;
const SEED: u64 = 1998;
const SHOT: Shot = (
    Vec3::new(760.0, 120.0, 160.0),
    Vec3::new(870.0, 640.0, 0.0),
    45.0,
);
/// Samples per pixel of the crate's sampler by default.
const DEFAULT_SPP: usize = 4;
/// Percentile of the exact image mapped to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;
/// The relative error drawn white in the error images.
const ERROR_WHITE: f64 = 1.0;

/// `--spp N` taken out of the arguments (the rest go to [`Options`]).
fn spp_from_args() -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == "--spp")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .filter(|&n: &usize| n > 0)
        .unwrap_or(DEFAULT_SPP)
}

/// Options without `--spp`.
fn options() -> Options {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(i) = args.iter().position(|a| a == "--spp") {
        args.drain(i..(i + 2).min(args.len()));
    }
    Options::parse_from(100_000, (320, 180), args)
}

/// Every pixel's mean of `spp` one-sample estimates by `method` (unit
/// albedo, then times the hit's albedo), in parallel; and the time taken.
fn render(
    hits: &[Option<Hit>],
    lights: &[PointLight],
    eye: Vec3,
    method: &(impl OneSample + Sync),
    spp: usize,
    seed: u64,
) -> Result<(Vec<DVec3>, Duration), Box<dyn Error + Send + Sync>> {
    let lambert = Lambert::new(Vec3::ONE);
    let started = Instant::now();
    let pixels = hits
        .par_iter()
        .enumerate()
        .map(|(i, hit)| {
            let Some(hit) = hit else {
                return Ok(DVec3::ZERO);
            };
            let query: Query<WithView> =
                Query::new(hit.point, hit.normal)?.with_view(eye - hit.point)?;
            let mut rng = rng(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let mut sum = DVec3::ZERO;
            for _ in 0..spp {
                if let Some((light, pmf)) = method.pick(&query, rng.random::<f64>()) {
                    let light = &lights[light];
                    let f = lambert.eval(
                        &(),
                        query.surface(),
                        light.position.as_dvec3(),
                        light.intensity.as_dvec3(),
                    );
                    sum += f / pmf;
                }
            }
            Ok(sum / spp as f64 * hit.albedo.as_dvec3())
        })
        .collect::<Result<Vec<_>, Box<dyn Error + Send + Sync>>>()?;
    Ok((pixels, started.elapsed()))
}

/// Mean and median over the lit pixels of the squared relative error
/// (channels summed): the mean is what equal time compares, the median
/// shows whether a few pixels carry it.
fn relative_mse(image: &[DVec3], exact: &[DVec3]) -> (f64, f64) {
    let mut squared: Vec<f64> = image
        .iter()
        .zip(exact)
        .filter(|(_, e)| e.element_sum() > 0.0)
        .map(|(x, e)| {
            let r = (x.element_sum() - e.element_sum()) / e.element_sum();
            r * r
        })
        .collect();
    if squared.is_empty() {
        return (0.0, 0.0);
    }
    let mean = squared.iter().sum::<f64>() / squared.len() as f64;
    squared.sort_by(f64::total_cmp);
    (mean, squared[squared.len() / 2])
}

fn main() -> Result<(), Box<dyn Error + Send + Sync>> {
    let options = options();
    let spp = spp_from_args();
    let view = CityView::new(BLOCKS, SEED, &options, SHOT).map_err(|e| e.to_string())?;
    let lights = &view.city.lights;
    let eye = SHOT.0;

    let (exact, exact_time) = view.shade(|s, hit| s.exact(hit.point, hit.normal))?;
    let exact: Vec<DVec3> = view
        .hits
        .iter()
        .zip(&exact)
        .map(|(h, e)| match (h, e) {
            (Some(h), Some(e)) => *e * h.albedo.as_dvec3(),
            _ => DVec3::ZERO,
        })
        .collect();

    let ours = CratePick {
        sampler: view.tree.sampler(Lambert::new(Vec3::ONE)),
    };
    let pbrt = PbrtPick::new(&view.tree, None);
    // Warm both (caches, thread pool), then time the crate's sampler at
    // `spp` and pbrt-v4's at `spp` to set its equal-time count.
    render(&view.hits, lights, eye, &ours, 1, 1)?;
    render(&view.hits, lights, eye, &pbrt, 1, 1)?;
    let (crate_image, crate_time) = render(&view.hits, lights, eye, &ours, spp, 2)?;
    let (_, pbrt_probe) = render(&view.hits, lights, eye, &pbrt, spp, 3)?;
    let ratio = crate_time.as_secs_f64() / pbrt_probe.as_secs_f64();
    let pbrt_spp = ((spp as f64 * ratio).round() as usize).max(1);
    let (pbrt_image, pbrt_time) = render(&view.hits, lights, eye, &pbrt, pbrt_spp, 4)?;

    println!("night city, Lambert, direct light by sampling one light at a time, no shadows");
    print_row("lights", view.tree.len());
    print_row("image", format!("{}x{}", options.width, options.height));
    print_row("shaded pixels", view.hits.iter().flatten().count());
    print_row("exact sum", format!("{:.3} s", exact_time.as_secs_f64()));
    print_row(
        "crate's sampler",
        format!("{spp} spp, {:.3} s", crate_time.as_secs_f64()),
    );
    print_row(
        "pbrt-v4's importance",
        format!("{pbrt_spp} spp, {:.3} s", pbrt_time.as_secs_f64()),
    );
    let (ours_mse, pbrt_mse) = (
        relative_mse(&crate_image, &exact),
        relative_mse(&pbrt_image, &exact),
    );
    print_row(
        "sq. rel. error, crate",
        format!("mean {:.4e}, median {:.4e}", ours_mse.0, ours_mse.1),
    );
    print_row(
        "sq. rel. error, pbrt-v4",
        format!("mean {:.4e}, median {:.4e}", pbrt_mse.0, pbrt_mse.1),
    );
    print_row(
        "pbrt-v4 / crate at equal time",
        format!(
            "{:.2}x (mean), {:.2}x (median)",
            pbrt_mse.0 / ours_mse.0,
            pbrt_mse.1 / ours_mse.1
        ),
    );

    let out = &options.out;
    std::fs::create_dir_all(out)?;
    let size = options.size();
    let exposure = exposure(&exact, EXPOSURE_PERCENTILE);
    write_radiance(&out.join("sampling_exact.png"), size, &exact, exposure)?;
    for (name, image) in [("crate", &crate_image), ("pbrt", &pbrt_image)] {
        let path = out.join(format!("sampling_{name}.png"));
        write_radiance(&path, size, image, exposure)?;
        let err = out.join(format!("sampling_{name}_err.png"));
        write_difference(&err, size, image, &exact, ERROR_WHITE)?;
        println!("wrote {} and {}", path.display(), err.display());
    }
    Ok(())
}
