//! The night city with shadows: the buildings occlude the street lamps and
//! the lit windows.
//!
//! The host side of the crate's Warnock-style visibility: a ray-casting
//! hierarchy over the building boxes answers, for each node of the light
//! tree, whether the shaft from the shading point to the node's box is
//! certainly unoccluded, certainly blocked, or neither, and for single lights
//! casts one shadow ray. Every visible pixel is shaded by the tree
//! (`shade_occluded`) and by the exact shadowed sum (`shade_exact_occluded`,
//! one shadow ray per light per pixel, which is what limits the default size
//! below). The example prints times, errors against the certified bound, and
//! the visibility queries the tree asked per pixel against the one shadow ray
//! per light of the exact sum.
//!
//! ```text
//! cargo run --release --example shadows
//! cargo run --release --example shadows -- --lights 50000 --width 320 --height 180
//! ```
//!
//! Output: `out/shadows_tree.png`, `out/shadows_exact.png`,
//! `out/shadows_diff.png`.

#[path = "common/city.rs"]
mod city;
#[path = "common/mod.rs"]
mod common;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use city::{City, Hit, slab, union};
use common::{Camera, ErrorStats, Options, exposure, mean_per_pixel};
use glam::{DVec3, Vec3};
use manylights::{
    Aabb, Coverage, Lambert, LightTree, NodeBounds, ShadeError, ShadeResult, Threshold, Visibility,
};
use rayon::prelude::*;

/// Blocks along each side of the city: a smaller city than `city`'s, since
/// the exact shadowed sum casts a shadow ray per light and pixel.
const BLOCKS: u32 = 16;
/// Default number of lights and image size: the exact render (lights x
/// pixels shadow rays) takes about a minute on two cores.
const DEFAULT_LIGHTS: usize = 20_000;
const DEFAULT_WIDTH: u32 = 256;
const DEFAULT_HEIGHT: u32 = 144;
/// Default relative threshold of the certified bound (1%).
const DEFAULT_THRESHOLD: f64 = 0.01;
/// Default output directory.
const DEFAULT_OUT: &str = "out";

/// The camera looks down into the streets from above one edge of the city.
const CAMERA_EYE: Vec3 = Vec3::new(250.0, -60.0, 160.0);
const CAMERA_TARGET: Vec3 = Vec3::new(330.0, 260.0, 0.0);
const CAMERA_FOV_DEGREES: f32 = 50.0;
/// Percentile of the exact image that the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

/// Shadow rays start this far off the surface along its normal, so that a
/// point on a wall is not occluded by its own building. It is part of the
/// host's definition of visibility, used alike by the tree's queries and by
/// the exact sum.
const SHADOW_OFFSET: f32 = 0.05;
/// Safety margin of the classifier, in scene units. Coordinates stay below
/// 1,000, where an `f32` ulp is at most `6.1e-5`; the slab tests and the
/// shaft slices' corners err by a few ulps. Occluders are inflated by the
/// margin before a shaft is declared `Visible` and shrunk by it before it is
/// declared `Occluded`, so rounding cannot turn a conservative answer into a
/// wrong one.
const MARGIN: f32 = 0.01;

/// Slices of a shaft whose bounding boxes the classifier tests.
const SHAFT_PIECES: usize = 8;

/// Occlusion by the city's buildings, for one shading point.
struct Shadows<'c> {
    city: &'c City,
    /// `SHADOW_OFFSET` times the surface normal: queries start at the shading
    /// point plus this.
    lift: Vec3,
    /// Classifications answered: visible, occluded, partial.
    answers: [u32; 3],
}

impl Shadows<'_> {
    /// Counts and returns `coverage`.
    fn answer(&mut self, coverage: Coverage) -> Coverage {
        let slot = match coverage {
            Coverage::Visible => 0,
            Coverage::Occluded => 1,
            Coverage::Partial => 2,
        };
        self.answers[slot] += 1;
        coverage
    }
}

/// A closed segment, set up for slab tests.
struct Segment {
    from: Vec3,
    /// `1 / (to - from)`.
    inv_dir: Vec3,
}

impl Segment {
    fn new(from: Vec3, to: Vec3) -> Self {
        Self {
            from,
            inv_dir: (to - from).recip(),
        }
    }

    /// Whether the segment meets the closed box `b`.
    fn hits(&self, b: &Aabb) -> bool {
        let (near, far) = slab(self.from, self.inv_dir, b);
        near <= far && far >= 0.0 && near <= 1.0
    }
}

/// Whether two closed boxes meet.
fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    a.min.cmple(b.max).all() && b.min.cmple(a.max).all()
}

/// `b` grown (or, for negative `by`, shrunk) by `by` on every side.
fn grown(b: &Aabb, by: f32) -> Aabb {
    Aabb {
        min: b.min - by,
        max: b.max + by,
    }
}

/// The eight corners of a box.
fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

impl Visibility for Shadows<'_> {
    /// With the shaft the convex hull of the (lifted) point `p` and the
    /// node's box `N`:
    ///
    /// * `Visible` when no building, grown by [`MARGIN`], meets the bounding
    ///   box of any of [`SHAFT_PIECES`] slices of the shaft. The points
    ///   `(1 - t) p + t q` (`q` in `N`) with `t` in `[a, b]` lie in the
    ///   bounding box of the two boxes `(1 - a) p + a N` and `(1 - b) p + b N`
    ///   (each coordinate is linear in `t`), so the slices' boxes cover the
    ///   shaft, much more tightly than one box when it runs diagonally.
    /// * `Occluded` when the segments to all eight corners of `N` meet one
    ///   building shrunk by [`MARGIN`]. For a convex occluder `B` the set
    ///   `{q : [p, q] meets B} = {p + s (b - p) : b in B, s >= 1}` is convex,
    ///   so it then holds the corners' convex hull, `N`: every light's shadow
    ///   ray is blocked. Only buildings on the segment to the centre of `N`
    ///   can qualify, so only those are tried.
    /// * `Partial` otherwise.
    fn classify(&mut self, point: Vec3, node: &NodeBounds) -> Coverage {
        let apex = point + self.lift;
        let bvh = &self.city.bvh;
        let buildings = &self.city.buildings;
        let slice = |t: f32| Aabb {
            min: apex.lerp(node.aabb.min, t),
            max: apex.lerp(node.aabb.max, t),
        };
        let pieces: [Aabb; SHAFT_PIECES] = std::array::from_fn(|k| {
            let a = slice(k as f32 / SHAFT_PIECES as f32);
            let b = slice((k + 1) as f32 / SHAFT_PIECES as f32);
            grown(&union(a, b), MARGIN)
        });
        let shaft = pieces[1..].iter().fold(pieces[0], |a, &b| union(a, b));
        let near = |b: &Aabb| overlaps(b, &shaft) && pieces.iter().any(|piece| overlaps(b, piece));
        if !bvh.any(near, |i| near(&buildings[i].bounds)) {
            return self.answer(Coverage::Visible);
        }
        let to_centre = Segment::new(apex, 0.5 * (node.aabb.min + node.aabb.max));
        let to_corners = corners(&node.aabb).map(|c| Segment::new(apex, c));
        let blocks_all = |i: usize| {
            let core = grown(&buildings[i].bounds, -MARGIN);
            core.min.cmple(core.max).all()
                && to_centre.hits(&core)
                && to_corners.iter().all(|s| s.hits(&core))
        };
        self.answer(if bvh.any(|b| to_centre.hits(b), blocks_all) {
            Coverage::Occluded
        } else {
            Coverage::Partial
        })
    }

    /// One shadow ray: the segment from the lifted point to the light.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        let ray = Segment::new(point + self.lift, light);
        let buildings = &self.city.buildings;
        !self
            .city
            .bvh
            .any(|b| ray.hits(b), |i| ray.hits(&buildings[i].bounds))
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let options = Options::parse(Options {
        lights: DEFAULT_LIGHTS,
        width: DEFAULT_WIDTH,
        height: DEFAULT_HEIGHT,
        threshold: DEFAULT_THRESHOLD,
        out: PathBuf::from(DEFAULT_OUT),
    });
    let city = City::new(BLOCKS, options.lights);

    let start = Instant::now();
    let tree = LightTree::build(&city.lights)?;
    let build_time = start.elapsed();

    let camera = Camera::new(
        CAMERA_EYE,
        CAMERA_TARGET,
        CAMERA_FOV_DEGREES,
        options.width,
        options.height,
    );
    let hits = city.trace(&camera);
    let shadows = |h: &Hit| Shadows {
        city: &city,
        lift: h.normal * SHADOW_OFFSET,
        answers: [0; 3],
    };

    // Unit albedo: Lambert is linear in kd, so each pixel's albedo multiplies
    // the radiance (and its bound) afterwards.
    let shader = Lambert::new(Vec3::ONE);
    let threshold = Threshold::relative(options.threshold);
    let row = options.width as usize;

    let start = Instant::now();
    let mut tree_results: Vec<Option<ShadeResult>> = vec![None; hits.len()];
    let mut answers = vec![[0u32; 3]; hits.len()];
    tree_results
        .par_chunks_mut(row)
        .zip(answers.par_chunks_mut(row))
        .zip(hits.par_chunks(row))
        .try_for_each_init(
            || tree.shading(shader),
            |shading, ((results, answers), hits)| -> Result<(), ShadeError> {
                for ((result, answer), hit) in results.iter_mut().zip(answers).zip(hits) {
                    if let Some(h) = hit {
                        let mut host = shadows(h);
                        *result =
                            Some(shading.shade_occluded(h.point, h.normal, threshold, &mut host)?);
                        *answer = host.answers;
                    }
                }
                Ok(())
            },
        )?;
    let tree_time = start.elapsed();

    let start = Instant::now();
    let exact_shading = tree.shading(shader);
    let exact: Vec<Option<DVec3>> = hits
        .par_chunks(row)
        .flat_map_iter(|hits| {
            hits.iter()
                .map(|hit| {
                    hit.map(|h| {
                        exact_shading.shade_exact_occluded(h.point, h.normal, &mut shadows(&h))
                    })
                    .transpose()
                })
                .collect::<Vec<_>>()
        })
        .collect::<Result<_, _>>()?;
    let exact_time = start.elapsed();

    let stats = ErrorStats::new(&tree_results, &exact);
    let pixels = hits.iter().flatten().count();
    println!("city at night with shadows, Lambert");
    println!("  lights                        {:>12}", tree.len());
    println!(
        "  buildings                     {:>12}",
        city.buildings.len()
    );
    println!(
        "  image                         {:>12}",
        format!("{}x{}", options.width, options.height)
    );
    println!("  shaded pixels                 {pixels:>12}");
    println!("  threshold (relative)          {:>12}", options.threshold);
    println!(
        "  tree build                    {:>10.3} s",
        build_time.as_secs_f64()
    );
    println!(
        "  tree render                   {:>10.3} s",
        tree_time.as_secs_f64()
    );
    println!(
        "  exact render                  {:>10.3} s",
        exact_time.as_secs_f64()
    );
    println!(
        "  speed-up                      {:>11.2}x",
        exact_time.as_secs_f64() / tree_time.as_secs_f64()
    );
    println!(
        "  mean relative error           {:>12.3e}",
        stats.mean_relative
    );
    println!(
        "  max relative error            {:>12.3e}",
        stats.max_relative
    );
    println!(
        "  mean certified bound / value  {:>12.3e}",
        stats.mean_bound_relative
    );
    println!(
        "  nodes evaluated per pixel     {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.nodes_evaluated)
    );
    println!(
        "  lights evaluated per pixel    {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.lights_evaluated)
    );
    println!(
        "  classify queries per pixel    {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.classify_queries)
    );
    let pixel_count = pixels.max(1) as f64;
    for (slot, name) in ["visible", "occluded", "partial"].iter().enumerate() {
        let total: u64 = answers.iter().map(|a| u64::from(a[slot])).sum();
        println!(
            "    answered {name:<9} per pixel {:>12.1}",
            total as f64 / pixel_count
        );
    }
    println!(
        "  shadow rays per pixel, tree   {:>12.1}",
        mean_per_pixel(&tree_results, |r| r.point_queries)
    );
    println!("  shadow rays per pixel, exact  {:>12}", tree.len());
    println!("  pixels violating the bound    {:>12}", stats.violations);

    let albedo = |hit: &Option<Hit>| hit.map_or(DVec3::ZERO, |h| h.albedo.as_dvec3());
    let tree_image: Vec<DVec3> = tree_results
        .iter()
        .zip(&hits)
        .map(|(r, h)| r.map_or(DVec3::ZERO, |r| r.radiance) * albedo(h))
        .collect();
    let exact_image: Vec<DVec3> = exact
        .iter()
        .zip(&hits)
        .map(|(e, h)| e.unwrap_or(DVec3::ZERO) * albedo(h))
        .collect();
    let exposure = exposure(&exact_image, EXPOSURE_PERCENTILE);
    std::fs::create_dir_all(&options.out)?;
    let (w, h) = (options.width, options.height);
    let paths =
        ["shadows_tree.png", "shadows_exact.png", "shadows_diff.png"].map(|f| options.out.join(f));
    common::write_radiance(&paths[0], w, h, &tree_image, exposure)?;
    common::write_radiance(&paths[1], w, h, &exact_image, exposure)?;
    common::write_difference(
        &paths[2],
        w,
        h,
        &tree_image,
        &exact_image,
        options.threshold,
    )?;
    for path in &paths {
        println!("wrote {}", path.display());
    }
    if stats.violations > 0 {
        return Err(format!("{} pixels violate the certified bound", stats.violations).into());
    }
    Ok(())
}
