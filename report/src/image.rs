//! Images a person can look at: tone-mapped radiance and enhanced-contrast
//! difference images against the exact sum, as 8-bit PNG.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use glam::DVec3;

use crate::compare::max_ratio;

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
    (width, height): (u32, u32),
    pixels: &[DVec3],
    exposure: f64,
) -> std::io::Result<()> {
    let rgb: Vec<u8> = pixels.iter().flat_map(|&p| tone_map(p, exposure)).collect();
    write_png(path, width, height, &rgb)
}

/// Writes a grey image of the relative error `|tree - exact| / exact`
/// (largest over the channels) of each pixel, mapped to `[0, 1]` by `level`
/// (clamped).
fn write_error(
    path: &Path,
    (width, height): (u32, u32),
    tree: &[DVec3],
    exact: &[DVec3],
    level: impl Fn(f64) -> f64,
) -> std::io::Result<()> {
    let rgb: Vec<u8> = tree
        .iter()
        .zip(exact)
        .flat_map(|(&t, &e)| {
            let grey = level(max_ratio((t - e).abs(), e)).clamp(0.0, 1.0);
            [(grey * 255.0).round() as u8; 3]
        })
        .collect();
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
    size: (u32, u32),
    tree: &[DVec3],
    exact: &[DVec3],
    threshold: f64,
) -> std::io::Result<()> {
    write_error(path, size, tree, exact, |e| {
        1.0 + (e / threshold).log10() / DIFF_DECADES
    })
}

/// Writes a linear enhanced-contrast difference image (the paper's): per
/// pixel the relative error `|tree - exact| / exact` (largest over the
/// channels) divided by `full_scale` and clamped to `[0, 1]`, so seams where
/// the error jumps show as edges.
pub fn write_difference_linear(
    path: &Path,
    size: (u32, u32),
    tree: &[DVec3],
    exact: &[DVec3],
    full_scale: f64,
) -> std::io::Result<()> {
    write_error(path, size, tree, exact, |e| e / full_scale)
}

/// Writes `<out>/<name>_tree.png`, `<name>_exact.png` (both at the exposure
/// that maps `percentile` of the exact image to white) and `<name>_diff.png`
/// (the logarithmic difference image, `threshold` at white) of two
/// `width x height` images, and prints their paths.
pub fn write_comparison(
    out: &Path,
    name: &str,
    size: (u32, u32),
    tree: &[DVec3],
    exact: &[DVec3],
    threshold: f64,
    percentile: f64,
) -> std::io::Result<()> {
    std::fs::create_dir_all(out)?;
    let exposure = exposure(exact, percentile);
    let paths = ["tree", "exact", "diff"].map(|f| out.join(format!("{name}_{f}.png")));
    write_radiance(&paths[0], size, tree, exposure)?;
    write_radiance(&paths[1], size, exact, exposure)?;
    write_difference(&paths[2], size, tree, exact, threshold)?;
    for path in &paths {
        println!("wrote {}", path.display());
    }
    Ok(())
}
