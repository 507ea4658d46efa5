//! The tree against the exact sum, pixel by pixel: the certified-bound
//! check, error statistics, timing, and the table the examples print.

use std::error::Error;
use std::time::{Duration, Instant};

use glam::DVec3;
use manylights::{ShadeError, ShadeResult};
use rayon::prelude::*;

/// Runs `f` and returns its value with the wall time it took.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, Duration) {
    let start = Instant::now();
    let value = f();
    (value, start.elapsed())
}

/// Shades every hit pixel in parallel with `shade(session, hit)`, each
/// thread with its own session from `session()`; `None` where the pixel has
/// no hit.
pub fn shade_pixels<H: Sync, S, T: Send>(
    hits: &[Option<H>],
    session: impl Fn() -> S + Sync + Send,
    shade: impl Fn(&mut S, &H) -> Result<T, ShadeError> + Sync + Send,
) -> Result<Vec<Option<T>>, ShadeError> {
    hits.par_iter()
        .map_init(session, |s, hit| {
            hit.as_ref().map(|h| shade(s, h)).transpose()
        })
        .collect()
}

/// How the tree's image compares with the exact one, over the pixels whose
/// exact value is positive.
#[derive(Clone, Copy, Debug, Default)]
pub struct ErrorStats {
    /// Pixels with a positive exact value.
    pub lit_pixels: usize,
    /// Mean relative error, measured as a relative threshold measures the
    /// certified bound: per pixel the largest channel of `|tree - exact|`
    /// over the largest channel of `exact`.
    pub mean_relative: f64,
    /// Largest relative error, as [`ErrorStats::mean_relative`].
    pub max_relative: f64,
    /// Largest relative error of a single channel against itself,
    /// `|tree_k - exact_k| / exact_k`: a dim channel of a pixel can exceed
    /// the threshold while the pixel meets it.
    pub max_relative_per_channel: f64,
    /// Mean certified bound relative to the tree's radiance, measured as the
    /// relative threshold measures it: largest channel of the bound over
    /// largest channel of the radiance.
    pub mean_bound_relative: f64,
    /// Pixels (of all shaded ones) breaking the certified-bound contract
    /// ([`ShadeResult::certifies`]).
    pub violations: usize,
}

/// `max_k a_k / b_k` over the channels with `b_k > 0`.
pub(crate) fn max_ratio(a: DVec3, b: DVec3) -> f64 {
    (0..3)
        .filter(|&k| b[k] > 0.0)
        .map(|k| a[k] / b[k])
        .fold(0.0, f64::max)
}

impl ErrorStats {
    /// Compares per-pixel tree results with exact values (`None` = sky).
    pub fn new(tree: &[Option<ShadeResult>], exact: &[Option<DVec3>]) -> ErrorStats {
        let mut stats = ErrorStats::default();
        let (mut sum_relative, mut sum_bound) = (0.0, 0.0);
        for (r, e) in tree.iter().zip(exact) {
            let (Some(r), Some(e)) = (r, e) else {
                continue;
            };
            if !r.certifies(*e) {
                stats.violations += 1;
            }
            let diff = (r.radiance - *e).abs();
            if e.max_element() > 0.0 {
                stats.lit_pixels += 1;
                let relative = diff.max_element() / e.max_element();
                sum_relative += relative;
                stats.max_relative = stats.max_relative.max(relative);
                stats.max_relative_per_channel =
                    stats.max_relative_per_channel.max(max_ratio(diff, *e));
                sum_bound += r.error_bound.max_element() / r.radiance.max_element();
            }
        }
        let lit = stats.lit_pixels.max(1) as f64;
        stats.mean_relative = sum_relative / lit;
        stats.mean_bound_relative = sum_bound / lit;
        stats
    }

    /// An error naming the pixels that break the certified bound, if any.
    pub fn ensure_certified(&self) -> Result<(), Box<dyn Error>> {
        match self.violations {
            0 => Ok(()),
            n => Err(format!("{n} pixels violate the certified bound").into()),
        }
    }
}

/// Largest relative difference of `values` from `exact` over the pixels
/// whose exact value is positive, measured as [`ErrorStats::max_relative`]
/// (largest channel over largest channel); NaN if a difference is NaN.
pub fn max_relative(values: &[Option<DVec3>], exact: &[Option<DVec3>]) -> f64 {
    values
        .iter()
        .zip(exact)
        .filter_map(|(v, e)| Some(((*v)?, (*e)?)))
        .filter(|(_, e)| e.max_element() > 0.0)
        .map(|(v, e)| (v - e).abs().max_element() / e.max_element())
        // A NaN anywhere makes the result NaN (f64::max would skip it).
        .fold(0.0, |a: f64, d| if d.is_nan() || d > a { d } else { a })
}

/// Mean of `f` over the shaded (non-sky) pixels.
pub fn mean_per_pixel(tree: &[Option<ShadeResult>], f: impl Fn(&ShadeResult) -> u32) -> f64 {
    let (sum, count) = tree
        .iter()
        .flatten()
        .fold((0u64, 0u64), |(s, c), r| (s + u64::from(f(r)), c + 1));
    sum as f64 / count.max(1) as f64
}

/// Prints one row of a table: a label and a right-aligned value.
pub fn print_row(label: &str, value: impl std::fmt::Display) {
    println!("  {label:<30}{value:>12}");
}

/// Prints the rows the rendering examples share: build and render times, the
/// speed-up, the errors made against the exact sum, the certified bound, the
/// work per pixel, and the pixels breaking the bound (there should be none).
pub fn print_comparison(
    build: Duration,
    tree: Duration,
    exact: Duration,
    results: &[Option<ShadeResult>],
    stats: &ErrorStats,
) {
    print_times(build, tree, &[("exact render", "speed-up", exact)]);
    print_errors(results, stats);
}

/// Prints the build and render times, then for each reference `(render
/// label, speed-up label, time)` its render time and the tree's speed-up
/// over it.
pub fn print_times(build: Duration, tree: Duration, references: &[(&str, &str, Duration)]) {
    print_row("tree build", format!("{:.3} s", build.as_secs_f64()));
    print_row("tree render", format!("{:.3} s", tree.as_secs_f64()));
    for (label, _, time) in references {
        print_row(label, format!("{:.3} s", time.as_secs_f64()));
    }
    for (_, label, time) in references {
        print_row(
            label,
            format!("{:.2}x", time.as_secs_f64() / tree.as_secs_f64()),
        );
    }
}

/// Prints the errors made against the exact sum, the certified bound, the
/// work per pixel, and the pixels breaking the bound (there should be
/// none).
pub fn print_errors(results: &[Option<ShadeResult>], stats: &ErrorStats) {
    // Measured as the threshold measures the bound (largest channel over
    // largest channel), then each channel against itself.
    print_row(
        "mean relative error",
        format!("{:.3e}", stats.mean_relative),
    );
    print_row("max relative error", format!("{:.3e}", stats.max_relative));
    print_row(
        "max relative error per channel",
        format!("{:.3e}", stats.max_relative_per_channel),
    );
    print_row(
        "mean certified bound / value",
        format!("{:.3e}", stats.mean_bound_relative),
    );
    let per_pixel = |f: fn(&ShadeResult) -> u32| format!("{:.1}", mean_per_pixel(results, f));
    print_row(
        "nodes evaluated per pixel",
        per_pixel(|r| r.nodes_evaluated),
    );
    print_row(
        "lights evaluated per pixel",
        per_pixel(|r| r.lights_evaluated),
    );
    print_row("pixels violating the bound", stats.violations);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(radiance: DVec3, error_bound: DVec3) -> ShadeResult {
        let mut r = ShadeResult::default();
        r.radiance = radiance;
        r.error_bound = error_bound;
        r
    }

    #[test]
    fn errors_are_measured_as_the_threshold_measures_the_bound() {
        // A bright red channel within 0.5% and a dim green one off by 2%
        // of itself: the pixel meets a relative 1%, its green channel alone
        // would not.
        let exact = DVec3::new(1.0, 0.01, 0.0);
        let tree = result(DVec3::new(1.005, 0.0102, 0.0), DVec3::splat(0.006));
        // A sky pixel and a dark one count in neither mean.
        let dark = result(DVec3::ZERO, DVec3::ZERO);
        let stats = ErrorStats::new(
            &[Some(tree), None, Some(dark)],
            &[Some(exact), None, Some(DVec3::ZERO)],
        );
        assert_eq!(stats.lit_pixels, 1);
        assert!((stats.max_relative - 0.005).abs() < 1e-12);
        assert!((stats.mean_relative - 0.005).abs() < 1e-12);
        assert!((stats.max_relative_per_channel - 0.02).abs() < 1e-12);
        assert!((stats.mean_bound_relative - 0.006 / 1.005).abs() < 1e-12);
        assert_eq!(stats.violations, 0);
    }
}
