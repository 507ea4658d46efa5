//! Primary rays through the night city: the nearest hit on the ground or a
//! building, through the BVH over the buildings; and [`CityView`], what the
//! `city` and `shadows` examples render, pixel by pixel or in tiles through
//! the batch call.

use std::error::Error;
use std::time::Duration;

use glam::{DVec3, Vec3};
use manylights::{
    BatchStats, Lambert, LightTree, Query, ShadeError, ShadeResult, Shading, Threshold, Unoccluded,
};
use rayon::prelude::*;

use crate::bvh::entry_normal;
use crate::camera::Camera;
use crate::compare::{ErrorStats, print_row, shade_pixels, timed};
use crate::image::write_comparison;
use crate::options::Options;
use crate::scenes::{City, GROUND_ALBEDO};
use crate::shadows::Shadows;

/// A primary-ray hit: the shading point, its outward normal, its albedo.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Point on the surface.
    pub point: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    /// Diffuse albedo.
    pub albedo: Vec3,
}

impl City {
    /// The nearest surface hit by the ray `origin + t * dir`, `t > 0`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
        let ground_t = if dir.z < 0.0 {
            -origin.z / dir.z
        } else {
            f32::INFINITY
        };
        let (t, building) = match self.occluders.nearest(origin, dir) {
            Some((t, i)) if t < ground_t => (t, Some(i)),
            _ => (ground_t, None),
        };
        if !t.is_finite() {
            return None;
        }
        let point = origin + dir * t;
        Some(match building {
            None => Hit {
                point,
                normal: Vec3::Z,
                albedo: GROUND_ALBEDO,
            },
            Some(i) => {
                let b = &self.buildings[i];
                Hit {
                    point,
                    normal: entry_normal(origin, dir.recip(), &b.bounds, dir),
                    albedo: b.albedo,
                }
            }
        })
    }

    /// Casts one primary ray per pixel of `camera`'s image: the hit of each
    /// pixel in row-major order, `None` for the sky.
    pub fn trace(&self, camera: &Camera) -> Vec<Option<Hit>> {
        camera.trace(|origin, dir| self.intersect(origin, dir))
    }
}

/// An image from per-pixel unit-albedo `values` (`None` for the sky, black),
/// each times its hit's albedo: Lambert is linear in `kd`, so this equals
/// shading with the albedo.
fn albedo_image(hits: &[Option<Hit>], values: impl Iterator<Item = Option<DVec3>>) -> Vec<DVec3> {
    hits.iter()
        .zip(values)
        .map(|(hit, v)| match (hit, v) {
            (Some(h), Some(v)) => v * h.albedo.as_dvec3(),
            _ => DVec3::ZERO,
        })
        .collect()
}

/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;
/// Side of the square pixel tiles of [`CityView::shade_batch`].
pub const TILE: u32 = 16;
/// Tiles per batch call of [`CityView::shade_batch`].
pub const CHUNK_TILES: usize = 8;

/// Where a camera looks at a night city from: eye, target, vertical field
/// of view in degrees.
pub type Shot = (Vec3, Vec3, f32);

/// A night city seen by a camera: the city, its light tree, each pixel's
/// primary-ray hit, and the times the build and the rays took.
pub struct CityView {
    /// The city.
    pub city: City,
    /// The tree over its lights.
    pub tree: LightTree,
    /// Each pixel's hit, row-major, `None` for the sky.
    pub hits: Vec<Option<Hit>>,
    /// Image width and height in pixels.
    pub size: (u32, u32),
    /// Time of the tree build.
    pub build_time: Duration,
    /// Time of the primary rays.
    pub trace_time: Duration,
}

impl CityView {
    /// A city of `blocks x blocks` blocks with `options.lights` lights from
    /// `seed`, its tree, and the hits of an `options.size()` image from
    /// `shot`.
    pub fn new(
        blocks: u32,
        seed: u64,
        options: &Options,
        shot: Shot,
    ) -> Result<Self, Box<dyn Error>> {
        let city = City::new(blocks, options.lights, seed);
        let (tree, build_time) = timed(|| LightTree::build(&city.lights));
        let (eye, target, fov_degrees) = shot;
        let camera = Camera::new(eye, target, fov_degrees, options.width, options.height);
        let (hits, trace_time) = timed(|| city.trace(&camera));
        Ok(Self {
            tree: tree?,
            city,
            hits,
            size: options.size(),
            build_time,
            trace_time,
        })
    }

    /// Shades every hit pixel in parallel with `shade(session, hit)`, the
    /// sessions with unit albedo (Lambert is linear in `kd`: [`Self::finish`]
    /// multiplies each pixel by its albedo afterwards); returns the values
    /// and the time taken.
    pub fn shade<T: Send>(
        &self,
        shade: impl Fn(&mut Shading<'_, Lambert>, &Hit) -> Result<T, ShadeError> + Sync + Send,
    ) -> Result<(Vec<Option<T>>, Duration), ShadeError> {
        let session = || self.tree.shading(Lambert::new(Vec3::ONE));
        let (values, time) = timed(|| shade_pixels(&self.hits, session, shade));
        Ok((values?, time))
    }

    /// Shades every hit pixel through [`Shading::shade_batch`] at
    /// `threshold`, with unit albedo as [`Self::shade`] and no occluders:
    /// the image is cut into [`TILE`] x [`TILE`] pixel tiles (row-major, and
    /// row-major inside a tile), every [`CHUNK_TILES`] consecutive tiles
    /// make one batch call, and the calls are spread over rayon's threads,
    /// one session per thread. Returns each pixel's result (`None` for the
    /// sky), the batch calls' summed statistics, and the time taken
    /// (queries, shading and gathering the results).
    pub fn shade_batch(
        &self,
        threshold: Threshold,
    ) -> Result<(Vec<Option<ShadeResult>>, BatchStats, Duration), ShadeError> {
        let (value, time) = timed(|| self.shade_tiles(threshold, false));
        let (results, stats, _) = value?;
        Ok((results, stats, time))
    }

    /// [`Self::shade_batch`] with the buildings' shadows: in each chunk of
    /// tiles, one batch call per normal direction (the city's surfaces are
    /// axis-aligned), each with a [`Shadows`] host for that normal (the host
    /// lifts its rays along the normal), which classifies nodes for whole
    /// groups of points. Also returns the hosts' answers (visible,
    /// occluded, partial) and shadow rays, summed.
    #[allow(clippy::type_complexity)]
    pub fn shade_batch_shadowed(
        &self,
        threshold: Threshold,
    ) -> Result<(Vec<Option<ShadeResult>>, BatchStats, [u64; 4], Duration), ShadeError> {
        let (value, time) = timed(|| self.shade_tiles(threshold, true));
        let (results, stats, answers) = value?;
        Ok((results, stats, answers, time))
    }

    /// [`Self::shade_batch`] (with shadows if `shadows`), untimed.
    #[allow(clippy::type_complexity)]
    fn shade_tiles(
        &self,
        threshold: Threshold,
        shadows: bool,
    ) -> Result<(Vec<Option<ShadeResult>>, BatchStats, [u64; 4]), ShadeError> {
        let (width, height) = self.size;
        let mut tiles = Vec::new();
        for ty in (0..height).step_by(TILE as usize) {
            for tx in (0..width).step_by(TILE as usize) {
                let rows = ty..(ty + TILE).min(height);
                let columns = tx..(tx + TILE).min(width);
                let pixels: Vec<usize> = rows
                    .flat_map(|y| columns.clone().map(move |x| (y * width + x) as usize))
                    .filter(|&i| self.hits[i].is_some())
                    .collect();
                tiles.push(pixels);
            }
        }
        let chunks: Vec<Vec<usize>> = tiles.chunks(CHUNK_TILES).map(|c| c.concat()).collect();
        let session = || self.tree.shading(Lambert::new(Vec3::ONE));
        let shaded = chunks
            .par_iter()
            .map_init(session, |s, pixels| {
                let queries = pixels
                    .iter()
                    .map(|&i| {
                        let hit = self.hits[i].expect("only hit pixels are queued");
                        Query::new(hit.point, hit.normal)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                if queries.is_empty() {
                    return Ok((Vec::new(), BatchStats::default(), [0; 4]));
                }
                let mut results = vec![ShadeResult::default(); queries.len()];
                if !shadows {
                    let stats = s.shade_batch(&queries, threshold, Unoccluded, &mut results)?;
                    return Ok((results, stats, [0; 4]));
                }
                // One call per normal, each with its host.
                let (mut stats, mut answers) = (BatchStats::default(), [0u64; 4]);
                let mut normals: Vec<Vec3> = Vec::new();
                for &i in pixels {
                    let n = self.hits[i].expect("hit").normal;
                    if !normals.contains(&n) {
                        normals.push(n);
                    }
                }
                for n in normals {
                    let members: Vec<usize> = (0..pixels.len())
                        .filter(|&k| self.hits[pixels[k]].expect("hit").normal == n)
                        .collect();
                    let subset: Vec<Query> = members.iter().map(|&k| queries[k]).collect();
                    let mut out = vec![results[members[0]]; subset.len()];
                    let mut host = Shadows::new(&self.city.occluders, n);
                    stats += s.shade_batch(&subset, threshold, &mut host, &mut out)?;
                    for (&k, r) in members.iter().zip(out) {
                        results[k] = r;
                    }
                    for (a, h) in answers.iter_mut().zip(host.answers) {
                        *a += u64::from(h);
                    }
                    answers[3] += u64::from(host.rays);
                }
                Ok((results, stats, answers))
            })
            .collect::<Result<Vec<_>, ShadeError>>()?;
        let mut image = vec![None; self.hits.len()];
        let mut total = BatchStats::default();
        let mut answers = [0u64; 4];
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

    /// Prints the rows that say what was rendered: lights, buildings (if
    /// `buildings`), image, pixels, threshold, primary rays.
    pub fn print_setup(&self, options: &Options, buildings: bool) {
        print_row("lights", self.tree.len());
        if buildings {
            print_row("buildings", self.city.buildings.len());
        }
        print_row("image", format!("{}x{}", options.width, options.height));
        print_row("shaded pixels", self.hits.iter().flatten().count());
        print_row("threshold (relative)", options.threshold);
        let trace = self.trace_time.as_secs_f64();
        print_row("primary rays", format!("{trace:.3} s"));
    }

    /// Writes `<name>_{tree,exact,diff}.png` under `options.out` from the
    /// unit-albedo results, each pixel times its albedo, then fails if a
    /// pixel breaks the certified bound (`stats`).
    pub fn finish(
        &self,
        options: &Options,
        name: &str,
        results: &[Option<ShadeResult>],
        exact: &[Option<DVec3>],
        stats: &ErrorStats,
    ) -> Result<(), Box<dyn Error>> {
        let tree_image = albedo_image(&self.hits, results.iter().map(|r| r.map(|r| r.radiance)));
        write_comparison(
            &options.out,
            name,
            options.size(),
            &tree_image,
            &albedo_image(&self.hits, exact.iter().copied()),
            options.threshold,
            EXPOSURE_PERCENTILE,
        )?;
        stats.ensure_certified()
    }
}
