//! The Lambert node bounds compared on the street city with coloured lights
//! (the street lamps' sodium and white LED colours, each light further
//! tinted at random), certified at 1% relative: evaluations per shading
//! point, time per point, time per evaluation and the tree's size, at
//! 10^4, 10^5 and 10^6 lights, against the SIMD exact sum in the same run;
//! and the build's time and memory per light from 10^4 to 10^7 lights, on
//! one thread and on rayon's pool.
//!
//! Bounds: the paper's (Paquette et al. 1998), the second-order Taylor
//! bound, and the dipole multipole series (the default), all on the same
//! tree. One core.

use std::error::Error;
use std::time::Instant;

use glam::Vec3;
use manylights::shader::Node;
use manylights::{BoundKind, Lambert, LightTree, PointLight, Threshold};
use rand::RngExt;

use crate::config::{SEED, build_repeats};
use crate::exact::SoaLights;
use crate::measure::minor_faults;
use crate::scenes::{city, rng};
use crate::sweep::median;

/// Numbers of lights.
const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];
/// Ground points per size.
const POINTS: usize = 100;
/// The certified relative threshold.
const THRESHOLD: f64 = 0.01;
/// Range of the random tint of each channel.
const TINT: (f32, f32) = (0.5, 1.0);

const BOUNDS: [(&str, BoundKind); 3] = [
    ("paper", BoundKind::Paper),
    ("second-order Taylor", BoundKind::Taylor),
    ("multipole series (default)", BoundKind::Series),
];

/// Street lamps of the city scene, each tinted at random.
fn coloured(lights: &[PointLight], seed: u64) -> Vec<PointLight> {
    let mut r = rng(seed);
    lights
        .iter()
        .map(|l| {
            let tint = Vec3::new(
                r.random_range(TINT.0..TINT.1),
                r.random_range(TINT.0..TINT.1),
                r.random_range(TINT.0..TINT.1),
            );
            PointLight::new(l.position, l.intensity * tint)
        })
        .collect()
}

/// Prints the tables as Markdown; an error if a point breaks its bound.
pub fn print_bounds_table() -> Result<(), Box<dyn Error>> {
    println!("## Lambert bounds: street city with coloured lights, certified 1%\n");
    println!(
        "| lights | bound | evaluations / point | time / point | ns / evaluation | SIMD exact sum / point | speed-up |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut builds = Vec::new();
    for count in SIZES {
        let scene = city(count, POINTS, SEED);
        let lights = coloured(&scene.lights, SEED ^ 0x7147);
        let start = Instant::now();
        let tree = LightTree::build(&lights)?;
        let build = start.elapsed().as_secs_f64();
        builds.push(build);
        let exact = SoaLights::new(&lights);
        let start = Instant::now();
        for p in &scene.points {
            std::hint::black_box(exact.shade(&scene.material, p.point, p.normal, p.view));
        }
        let exact_time = start.elapsed().as_secs_f64() / POINTS as f64;
        for (name, kind) in BOUNDS {
            let mut shading = tree.shading(Lambert::new(scene.material.kd).with_bound(kind));
            let mut cost = 0u64;
            let start = Instant::now();
            let mut results = Vec::with_capacity(POINTS);
            for p in &scene.points {
                let r = shading.shade(p.point, p.normal, Threshold::relative(THRESHOLD))?;
                cost += u64::from(r.cost());
                results.push(r);
            }
            let time = start.elapsed().as_secs_f64() / POINTS as f64;
            for (p, r) in scene.points.iter().zip(&results) {
                if !r.certifies(shading.exact(p.point, p.normal)?) {
                    return Err(format!("{name}: bound broken at {:?}", p.point).into());
                }
            }
            let evaluations = cost as f64 / POINTS as f64;
            println!(
                "| {count} | {name} | {evaluations:.0} | {:.1} us | {:.0} | {:.0} us | {:.1}x |",
                time * 1e6,
                time * 1e9 / evaluations,
                exact_time * 1e6,
                exact_time / time
            );
        }
    }
    println!(
        "\nEvery bound reads the same tree: {} bytes per node.\n",
        size_of::<Node>()
    );
    print_build_table(&builds)?;
    println!();
    Ok(())
}

/// Sizes of the build table.
const BUILD_SIZES: [usize; 4] = [10_000, 100_000, 1_000_000, 10_000_000];

/// The build table: per size, the first build in the process (from the
/// bounds table above, up to 10^6 lights), then the median of
/// [`build_repeats`] builds on one thread alternating with as many on
/// rayon's pool
/// (`build_parallel`, the same tree; not timed when the pool has one
/// thread) and as many rebuilds on
/// one thread of a tree of the same lights in the memory it holds
/// (`rebuild`, the same tree again), the memory and the nodes per light,
/// and the page faults the process took per 1,000 lights in the one-thread
/// builds and the rebuilds (medians; `-` outside Linux): a build in memory
/// the allocator hands back to the system pays for first touches of fresh
/// pages, which a rebuild in place does not.
fn print_build_table(first: &[f64]) -> Result<(), Box<dyn Error>> {
    // With one thread in rayon's pool (a process pinned to one core) the
    // pool's builds are those of one thread again: not timed.
    let threads = rayon::current_num_threads();
    let pooled = threads > 1;
    let pool_column = if pooled {
        format!("build / light, {threads} threads | one / {threads} threads")
    } else {
        "build / light, pool (one thread here: not timed) | one / pool".to_string()
    };
    println!(
        "| lights | first build / light | build / light, one thread | {pool_column} | rebuild in place / light, one thread | build / rebuild | page faults / 1000 lights, build / rebuild | memory / light (lights included) | nodes / light |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (k, count) in BUILD_SIZES.into_iter().enumerate() {
        let lights = coloured(&crate::scenes::city_lights(count, SEED), SEED ^ 0x7147);
        let (mut one, mut pool, mut again) = (Vec::new(), Vec::new(), Vec::new());
        let (mut one_faults, mut again_faults) = (Vec::new(), Vec::new());
        let faults_since =
            |before: Option<u64>| Some(minor_faults()?.saturating_sub(before?) as f64);
        let mut size = (0, 0);
        // Rebuilt over and over, as a renderer would each frame.
        let mut kept = LightTree::build(&lights)?;
        for _ in 0..build_repeats(count) {
            let before = minor_faults();
            let start = Instant::now();
            let tree = LightTree::build(&lights)?;
            one.push(start.elapsed().as_secs_f64());
            one_faults.extend(faults_since(before));
            size = (tree.memory_bytes(), tree.nodes().len());
            drop(tree);
            if pooled {
                let start = Instant::now();
                let tree = LightTree::builder().build_parallel(&lights)?;
                pool.push(start.elapsed().as_secs_f64());
                drop(tree);
            }
            let before = minor_faults();
            let start = Instant::now();
            kept.rebuild(&lights)?;
            again.push(start.elapsed().as_secs_f64());
            again_faults.extend(faults_since(before));
        }
        drop(kept);
        let (one, again) = (median(one), median(again));
        let per_light = |t: f64| t * 1e9 / count as f64;
        let first = first
            .get(k)
            .map_or("-".to_string(), |&t| format!("{:.0} ns", per_light(t)));
        let pool = if pooled {
            let pool = median(pool);
            format!("{:.0} ns | {:.2}x", per_light(pool), one / pool)
        } else {
            "- | -".to_string()
        };
        let faults = if one_faults.is_empty() || again_faults.is_empty() {
            "- / -".to_string()
        } else {
            let per_thousand = |f: Vec<f64>| median(f) * 1e3 / count as f64;
            format!(
                "{:.1} / {:.1}",
                per_thousand(one_faults),
                per_thousand(again_faults)
            )
        };
        println!(
            "| {count} | {first} | {:.0} ns | {pool} | {:.0} ns | {:.2}x | {faults} | {:.0} B | {:.2} |",
            per_light(one),
            per_light(again),
            one / again,
            size.0 as f64 / count as f64,
            size.1 as f64 / count as f64
        );
    }
    Ok(())
}
