//! The roofs part: where a certified cut costs most on the street city.
//! Shading points on the ground, on façades below the lamps, and on roofs
//! inside the layer of lamps, at a certified 1%, one core, against the
//! vectorized exact sum ([`SoaLights`]) timed in the same run.
//!
//! ```text
//! cargo run --release -p manylights-report -- roofs
//! cargo run --release -p manylights-report -- roofs --roof-lights 100000
//! ```
//!
//! The street city ([`city_lights`](crate::scenes::city_lights)) holds its
//! lamps 5.5 to 6.5 units above the ground. A roof point at those heights, normal up, has its tangent
//! plane running through the layer of lamps: every node near it straddles
//! the plane, and the cut's work there is what this part measures, beside
//! points on the ground (normal up) and on façades (heights
//! [`FACADE_HEIGHTS`], normals horizontal in a random direction), where the
//! lamps are all above the plane or split along a vertical one. Roof
//! heights are drawn over the lamps' own height range, read from the
//! generated lights.
//!
//! Per set and number of lights: evaluations per point (node bounds plus
//! lights, [`ShadeResult::cost`]), the median time per point of the cut and
//! of the exact sum over [`ROUNDS`] alternating passes ([`paired`]), and
//! the speed-up as the ratio of those medians. Every
//! result is checked against the crate's `f64` exact sum
//! (`Shading::exact_query`), and the vectorized sum against it too; the
//! part prints the number of results breaking their bound and fails if
//! there is one.

use std::error::Error;
use std::f32::consts::TAU;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{Lambert, LightTree, ShadeResult, Threshold, Unoccluded};
use rand::RngExt;

use crate::config::SEED;
use crate::exact::SoaLights;
use crate::measure::{Sample, paired};
use crate::scenes::{self, Scene, ShadingPoint, rng};
use crate::sweep::{check_soa, median, query, soa_sample};

/// The part's name.
pub const ROOFS: &str = "roofs";
/// Numbers of lights measured by default.
pub const SIZES: [usize; 2] = [100_000, 1_000_000];
/// Numbers of lights measured with `--quick`.
pub const QUICK_SIZES: [usize; 1] = [100_000];
/// Shading points drawn per set (points no lamp lights are dropped).
const POINTS: usize = 100;
/// The certified relative target.
const TARGET: f64 = 0.01;
/// Alternating rounds (one pass of the exact sum, one of the cut) per set;
/// odd, so that the median is one round's time.
pub const ROUNDS: usize = 15;
/// Rounds with `--quick`.
const QUICK_ROUNDS: usize = 5;
/// Heights of the façade points: the ground floors, below the lamps.
pub const FACADE_HEIGHTS: (f32, f32) = (0.5, 3.5);
/// Seed offset of the shading points (the lights use [`SEED`]); each set
/// adds its index.
const POINTS_SEED: u64 = 0x2005;

/// The three sets of shading points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Set {
    /// On the ground, normal up.
    Ground,
    /// On façades: heights [`FACADE_HEIGHTS`], normal horizontal.
    Facades,
    /// On roofs inside the lamps' layer, normal up.
    Roofs,
}

impl Set {
    const ALL: [Set; 3] = [Set::Ground, Set::Facades, Set::Roofs];

    /// The row's label.
    fn label(self, lamps: (f32, f32)) -> String {
        match self {
            Set::Ground => "ground, z = 0, normal up".into(),
            Set::Facades => format!(
                "façades, z {}-{}, normal horizontal",
                FACADE_HEIGHTS.0, FACADE_HEIGHTS.1
            ),
            Set::Roofs => format!("roofs, z {:.2}-{:.2}, normal up", lamps.0, lamps.1),
        }
    }

    /// [`POINTS`] points of this set over the rectangle `[min, max]` of the
    /// ground, roofs at heights `lamps`.
    fn points(self, min: Vec3, max: Vec3, lamps: (f32, f32)) -> Vec<ShadingPoint> {
        let mut rng = rng(SEED ^ POINTS_SEED ^ self as u64);
        (0..POINTS)
            .map(|_| {
                let x = rng.random_range(min.x..=max.x);
                let y = rng.random_range(min.y..=max.y);
                let (z, normal) = match self {
                    Set::Ground => (0.0, Vec3::Z),
                    Set::Facades => {
                        let z = rng.random_range(FACADE_HEIGHTS.0..=FACADE_HEIGHTS.1);
                        let azimuth = rng.random_range(0.0..TAU);
                        (z, Vec3::new(azimuth.cos(), azimuth.sin(), 0.0))
                    }
                    Set::Roofs => (rng.random_range(lamps.0..=lamps.1), Vec3::Z),
                };
                // Lambert ignores the view; the query wants a valid one.
                ShadingPoint {
                    point: Vec3::new(x, y, z),
                    normal,
                    view: normal,
                }
            })
            .collect()
    }
}

/// One set's figures at one number of lights.
struct Row {
    /// Points measured (those some lamp lights).
    points: usize,
    /// Evaluations per point: mean, median, largest.
    evaluations: (f64, f64, u32),
    /// Median seconds per point of the cut and of the exact sum.
    cut: f64,
    exact: f64,
    /// Results breaking their certified bound.
    violations: usize,
}

/// Runs the part on `sizes` lights (both of [`SIZES`] unless asked
/// otherwise); an error if a result breaks its certified bound.
pub fn run_roofs(sizes: &[usize], quick: bool) -> Result<(), Box<dyn Error>> {
    let started = Instant::now();
    let rounds = if quick { QUICK_ROUNDS } else { ROUNDS };
    let mut command = format!("cargo run --release -p manylights-report -- {ROOFS}");
    if quick {
        command.push_str(" --quick");
    }
    if sizes != if quick { &QUICK_SIZES[..] } else { &SIZES[..] } {
        for n in sizes {
            command.push_str(&format!(" --roof-lights {n}"));
        }
    }
    println!("## Roofs: points inside the layer of lamps, street city, certified {TARGET}\n");
    println!(
        "  `{command}`; Lambert, the city's grey; one core; up to {POINTS} points per set \
         (points no lamp lights dropped); evaluations = node bounds + lights; times are medians \
         over {rounds} alternating passes (exact sum, then cut) of the time per point, the \
         speed-up the ratio of the medians; exact = the vectorized f32 sum\n"
    );
    println!(
        "| lights | set | points | evals mean | median | max | cut us/pt | exact us/pt | speed-up \
         | violations |"
    );
    println!("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut violations = 0;
    let mut ratios = Vec::new();
    for &n in sizes {
        // The city's lamps (`city_lights`) and grey; its points are not used.
        let scene = scenes::city(n, 0, SEED);
        let t = Instant::now();
        let tree = LightTree::build(&scene.lights)?;
        let build = t.elapsed();
        let soa = SoaLights::new(&scene.lights);
        let (min, max) = scene.lights.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
        );
        let lamps = (min.z, max.z);
        let mut rows = Vec::new();
        for set in Set::ALL {
            let row = measure_set(&tree, &soa, &scene, set.points(min, max, lamps), rounds)?;
            println!(
                "| {n} | {} | {} | {:.0} | {:.0} | {} | {:.2} | {:.1} | {:.1}x | {} |",
                set.label(lamps),
                row.points,
                row.evaluations.0,
                row.evaluations.1,
                row.evaluations.2,
                row.cut * 1e6,
                row.exact * 1e6,
                row.exact / row.cut,
                row.violations
            );
            violations += row.violations;
            rows.push((set, row));
        }
        let evaluations = |s: Set| {
            rows.iter()
                .find(|(set, _)| *set == s)
                .map(|(_, r)| r.evaluations)
                .expect("every set measured")
        };
        let (roof, ground) = (evaluations(Set::Roofs), evaluations(Set::Ground));
        ratios.push((n, build, roof.0 / ground.0, roof.1 / ground.1));
    }
    println!();
    for (n, build, mean, median) in ratios {
        println!(
            "  {n} lights (tree built in {:.2} s, one thread): roof evaluations / ground \
             evaluations = {mean:.1} (means), {median:.1} (medians)",
            build.as_secs_f64()
        );
    }
    println!(
        "  results breaking their certified bound (every point, against exact_query): \
         {violations}; part run time {:.0} s\n",
        started.elapsed().as_secs_f64()
    );
    if violations > 0 {
        return Err(format!("{violations} roofs results break their certified bound").into());
    }
    Ok(())
}

/// One set of points on one tree: references, the certificate check, the
/// evaluations and the paired timing.
fn measure_set(
    tree: &LightTree,
    soa: &SoaLights,
    scene: &Scene,
    points: Vec<ShadingPoint>,
    rounds: usize,
) -> Result<Row, Box<dyn Error>> {
    let mut shading = tree.shading(Lambert::new(scene.material.kd));
    let threshold = Threshold::relative(TARGET);
    // The f64 references, one thread; points no lamp lights are dropped
    // (a relative target means nothing there).
    let (points, refs): (Vec<ShadingPoint>, Vec<DVec3>) = points
        .into_iter()
        .map(|pt| (pt, shading.exact_query(&query(&pt), Unoccluded)))
        .filter(|(_, e)| e.max_element() > 0.0)
        .unzip();
    if points.is_empty() {
        return Err("no shading point of the set is lit".into());
    }
    check_soa(soa, scene, &points, &refs)?;
    let results: Vec<ShadeResult> = points
        .iter()
        .map(|pt| shading.shade_query(&query(pt), threshold, Unoccluded))
        .collect::<Result<_, _>>()?;
    let violations = results
        .iter()
        .zip(&refs)
        .filter(|(r, e)| !r.certifies(**e))
        .count();
    let costs: Vec<f64> = results.iter().map(|r| f64::from(r.cost())).collect();
    let evaluations = (
        costs.iter().sum::<f64>() / costs.len().max(1) as f64,
        median(costs.clone()),
        results.iter().map(ShadeResult::cost).max().unwrap_or(0),
    );
    let timing = paired(
        points.len(),
        rounds,
        |i| soa_sample(soa, scene, &points[i]),
        |i| {
            let r = shading.shade_query(&query(&points[i]), threshold, Unoccluded);
            Sample::cut(r.expect("the threshold is valid"), None)
        },
    );
    Ok(Row {
        points: points.len(),
        evaluations,
        cut: timing.second,
        exact: timing.first,
        violations,
    })
}
