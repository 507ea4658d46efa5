//! What the examples share: command-line options, a pinhole camera, error
//! statistics against the exact sum, tone mapping and PNG output.
//!
//! Included from each example with `#[path = "common/mod.rs"] mod common;`;
//! the night-city scene that `city` renders is in `city.rs`
//! beside it.

// Shared by several examples, each of which uses a part.
#![allow(dead_code)]

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use manylights::{ROUNDING_ALLOWANCE, ShadeResult};

// ---------------------------------------------------------------------------
// Command line
// ---------------------------------------------------------------------------

/// The flags every example takes.
#[derive(Clone, Debug)]
pub struct Options {
    /// `--lights N`: number of point lights.
    pub lights: usize,
    /// `--width W`: image width in pixels.
    pub width: u32,
    /// `--height H`: image height in pixels.
    pub height: u32,
    /// `--threshold T`: relative threshold of the tree's certified bound.
    pub threshold: f64,
    /// `--out DIR`: where the PNG images go.
    pub out: PathBuf,
    /// `--shadows` (no value): render with occluders, where an example
    /// offers it.
    pub shadows: bool,
}

impl Options {
    /// Parses the process arguments over `defaults`; prints the usage and
    /// exits on a malformed or unknown flag.
    pub fn parse(defaults: Options) -> Options {
        let mut options = defaults;
        let mut args = std::env::args().skip(1);
        while let Some(flag) = args.next() {
            if flag == "--shadows" {
                options.shadows = true;
                continue;
            }
            let value = args.next().unwrap_or_default();
            let ok = match flag.as_str() {
                "--lights" => value.parse().map(|v| options.lights = v).is_ok(),
                "--width" => value.parse().map(|v| options.width = v).is_ok(),
                "--height" => value.parse().map(|v| options.height = v).is_ok(),
                "--threshold" => value.parse().map(|v| options.threshold = v).is_ok(),
                "--out" => {
                    options.out = PathBuf::from(&value);
                    !value.is_empty()
                }
                _ => false,
            };
            if !ok || options.width == 0 || options.height == 0 || options.threshold < 0.0 {
                eprintln!(
                    "bad argument `{flag} {value}`\n\
                     usage: [--lights N] [--width W] [--height H] [--threshold T] [--out DIR] [--shadows]"
                );
                std::process::exit(2);
            }
        }
        options
    }
}

// ---------------------------------------------------------------------------
// Camera
// ---------------------------------------------------------------------------

/// A pinhole camera.
pub struct Camera {
    /// Position of the pinhole.
    pub eye: Vec3,
    /// Direction through the image centre.
    forward: Vec3,
    /// Half the image width at unit distance, pointing right.
    right: Vec3,
    /// Half the image height at unit distance, pointing up.
    up: Vec3,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// A camera at `eye` looking at `target` (with `+z` up) with a vertical
    /// field of view of `fov_degrees`, for a `width x height` image.
    pub fn new(eye: Vec3, target: Vec3, fov_degrees: f32, width: u32, height: u32) -> Camera {
        let forward = (target - eye).normalize();
        let half_height = (0.5 * fov_degrees.to_radians()).tan();
        let half_width = half_height * width as f32 / height as f32;
        let right = forward.cross(Vec3::Z).normalize();
        let up = right.cross(forward);
        Camera {
            eye,
            forward,
            right: right * half_width,
            up: up * half_height,
            width,
            height,
        }
    }

    /// The unit direction through the centre of pixel `(x, y)`, `y` down.
    pub fn ray(&self, x: u32, y: u32) -> Vec3 {
        let u = 2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0;
        let v = 1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32;
        (self.forward + u * self.right + v * self.up).normalize()
    }
}

// ---------------------------------------------------------------------------
// Error statistics
// ---------------------------------------------------------------------------

/// How the tree's image compares with the exact one, over the pixels whose
/// exact value is positive.
#[derive(Clone, Copy, Debug, Default)]
pub struct ErrorStats {
    /// Pixels with a positive exact value.
    pub lit_pixels: usize,
    /// Mean and largest relative error `|tree - exact| / exact`, per pixel
    /// the largest over its channels.
    pub mean_relative: f64,
    pub max_relative: f64,
    /// Mean certified bound relative to the tree's radiance, measured as the
    /// relative threshold measures it: largest channel of the bound over
    /// largest channel of the radiance.
    pub mean_bound_relative: f64,
    /// Pixels (of all shaded ones) breaking the certified-bound contract
    /// `|tree - exact| <= error_bound + ROUNDING_ALLOWANCE * exact` in some
    /// channel.
    pub violations: usize,
}

/// `max_k a_k / b_k` over the channels with `b_k > 0`.
fn max_ratio(a: DVec3, b: DVec3) -> f64 {
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
            let diff = (r.radiance - *e).abs();
            if diff.cmpgt(r.error_bound + ROUNDING_ALLOWANCE * *e).any() {
                stats.violations += 1;
            }
            if e.max_element() > 0.0 {
                stats.lit_pixels += 1;
                let relative = max_ratio(diff, *e);
                sum_relative += relative;
                stats.max_relative = stats.max_relative.max(relative);
                sum_bound += r.error_bound.max_element() / r.radiance.max_element();
            }
        }
        let lit = stats.lit_pixels.max(1) as f64;
        stats.mean_relative = sum_relative / lit;
        stats.mean_bound_relative = sum_bound / lit;
        stats
    }
}

/// Mean of `f` over the shaded (non-sky) pixels.
pub fn mean_per_pixel(tree: &[Option<ShadeResult>], f: impl Fn(&ShadeResult) -> u32) -> f64 {
    let (sum, count) = tree
        .iter()
        .flatten()
        .fold((0u64, 0u64), |(s, c), r| (s + u64::from(f(r)), c + 1));
    sum as f64 / count.max(1) as f64
}

// ---------------------------------------------------------------------------
// Images
// ---------------------------------------------------------------------------

/// Display gamma of the tone map.
const GAMMA: f64 = 2.2;
/// Decades of relative error the difference image spans below the
/// threshold: `threshold` is white, `threshold / 10^DIFF_DECADES` black.
const DIFF_DECADES: f64 = 4.0;

/// Exposure that maps the given percentile (in `[0, 1]`) of the pixels'
/// largest channel, over non-black pixels, to display white.
pub fn exposure(pixels: &[DVec3], percentile: f64) -> f64 {
    let mut values: Vec<f64> = pixels
        .iter()
        .map(|p| p.max_element())
        .filter(|&v| v > 0.0)
        .collect();
    if values.is_empty() {
        return 1.0;
    }
    let k = ((values.len() - 1) as f64 * percentile).round() as usize;
    let (_, v, _) = values.select_nth_unstable_by(k, f64::total_cmp);
    1.0 / *v
}

/// Exposure times radiance, clamped to `[0, 1]`, then gamma: 8-bit sRGB-ish.
fn tone_map(radiance: DVec3, exposure: f64) -> [u8; 3] {
    let c = (radiance * exposure)
        .clamp(DVec3::ZERO, DVec3::ONE)
        .powf(1.0 / GAMMA);
    [c.x, c.y, c.z].map(|v| (v * 255.0).round() as u8)
}

/// Writes an 8-bit RGB PNG.
fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> std::io::Result<()> {
    let file = BufWriter::new(File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(std::io::Error::other)?;
    writer
        .write_image_data(rgb)
        .map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}

/// Writes a tone-mapped radiance image (row-major, `width x height`).
pub fn write_radiance(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[DVec3],
    exposure: f64,
) -> std::io::Result<()> {
    let rgb: Vec<u8> = pixels.iter().flat_map(|&p| tone_map(p, exposure)).collect();
    write_png(path, width, height, &rgb)
}

/// Writes the enhanced-contrast difference image: per pixel the relative
/// error `e = |tree - exact| / exact` (largest over the channels) on a
/// logarithmic grey scale, `1 + log10(e / threshold) / DIFF_DECADES` clamped
/// to `[0, 1]`, so an error of the threshold or more is white and one
/// `10^DIFF_DECADES` times smaller is black. (The relative threshold bounds
/// the largest channel; a weak channel may exceed it and show white.)
pub fn write_difference(
    path: &Path,
    width: u32,
    height: u32,
    tree: &[DVec3],
    exact: &[DVec3],
    threshold: f64,
) -> std::io::Result<()> {
    let rgb: Vec<u8> = tree
        .iter()
        .zip(exact)
        .flat_map(|(&t, &e)| {
            let relative = max_ratio((t - e).abs(), e);
            let level = (1.0 + (relative / threshold).log10() / DIFF_DECADES).clamp(0.0, 1.0);
            [(level * 255.0).round() as u8; 3]
        })
        .collect();
    write_png(path, width, height, &rgb)
}

/// Writes a linear enhanced-contrast difference image (the paper's): per
/// pixel the relative error `|tree - exact| / exact` (largest over the
/// channels) divided by `full_scale` and clamped to `[0, 1]`, so seams where
/// the error jumps show as edges.
pub fn write_difference_linear(
    path: &Path,
    width: u32,
    height: u32,
    tree: &[DVec3],
    exact: &[DVec3],
    full_scale: f64,
) -> std::io::Result<()> {
    let rgb: Vec<u8> = tree
        .iter()
        .zip(exact)
        .flat_map(|(&t, &e)| {
            let level = (max_ratio((t - e).abs(), e) / full_scale).clamp(0.0, 1.0);
            [(level * 255.0).round() as u8; 3]
        })
        .collect();
    write_png(path, width, height, &rgb)
}

// ---------------------------------------------------------------------------
// The printed table
// ---------------------------------------------------------------------------

/// Prints one row of an example's table: a label and a right-aligned value.
pub fn print_row(label: &str, value: impl std::fmt::Display) {
    println!("  {label:<30}{value:>12}");
}

/// Prints the rows every example shares: build and render times, the
/// speed-up, the errors made against the exact sum, the certified bound, the
/// work per pixel, and the pixels breaking the bound (there should be none).
pub fn print_comparison(
    build: std::time::Duration,
    tree: std::time::Duration,
    exact: std::time::Duration,
    results: &[Option<ShadeResult>],
    stats: &ErrorStats,
) {
    print_row("tree build", format!("{:.3} s", build.as_secs_f64()));
    print_row("tree render", format!("{:.3} s", tree.as_secs_f64()));
    print_row("exact render", format!("{:.3} s", exact.as_secs_f64()));
    print_row(
        "speed-up",
        format!("{:.2}x", exact.as_secs_f64() / tree.as_secs_f64()),
    );
    print_row(
        "mean relative error",
        format!("{:.3e}", stats.mean_relative),
    );
    print_row("max relative error", format!("{:.3e}", stats.max_relative));
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
