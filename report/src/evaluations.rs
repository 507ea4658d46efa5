//! The evaluations-per-point table of the ground scene: lights 4 to 6 units
//! above a 1000 x 1000 ground, shading points on the ground, a certified
//! threshold of 1% of the point's value; evaluations per shading point
//! (averaged over 20 points) for the paper's first-order bound
//! (Paquette et al. 1998) and the crate's tight bound, and Lightcuts'
//! per-node criterion (Walter et al. 2005), with the actual errors against
//! the exact sum.

use std::time::Instant;

use glam::Vec3;
use manylights::{BoundKind, Lambert, LightTree, Threshold};

use crate::config::SEED;
use crate::scenes::{ground_lights, ground_points};

/// Shading points per size.
const POINTS: usize = 20;
/// Numbers of lights.
const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];
/// The relative threshold of every row.
const THRESHOLD: f64 = 0.01;

/// The rows of each size: label, bound, threshold.
const ROWS: [(&str, BoundKind, Threshold); 3] = [
    (
        "paper bound, certified 1%",
        BoundKind::Paper,
        Threshold::relative(THRESHOLD),
    ),
    (
        "tight bound, certified 1%",
        BoundKind::Series,
        Threshold::relative(THRESHOLD),
    ),
    (
        "tight bound, per-node 1% (Lightcuts)",
        BoundKind::Series,
        Threshold::per_node(THRESHOLD),
    ),
];

/// Prints the table as Markdown; an error if a point breaks its certified
/// bound.
pub fn print_evaluations_table() -> Result<(), Box<dyn std::error::Error>> {
    println!("## Ground scene: evaluations per shading point\n");
    println!(
        "| lights | bound | evaluations / point | max actual rel. error | time / point | exact \
         sum / point |"
    );
    println!("|---|---|---|---|---|---|");
    for count in SIZES {
        let tree = LightTree::build(&ground_lights(count, SEED))?;
        let points = ground_points(POINTS, SEED);
        for (name, kind, threshold) in ROWS {
            let mut shading = tree.shading(Lambert::new(Vec3::ONE).with_bound(kind));
            let (mut cost, mut max_rel, mut time, mut exact_time) = (0u64, 0.0f64, 0.0, 0.0);
            for &p in &points {
                let start = Instant::now();
                let r = shading.shade(p, Vec3::Z, threshold)?;
                time += start.elapsed().as_secs_f64();
                let start = Instant::now();
                let exact = shading.exact(p, Vec3::Z)?;
                exact_time += start.elapsed().as_secs_f64();
                if !r.certifies(exact) {
                    return Err(format!("bound violated at {p}").into());
                }
                cost += u64::from(r.cost());
                max_rel = max_rel.max(((r.radiance - exact).abs() / exact).max_element());
            }
            println!(
                "| {count} | {name} | {} | {max_rel:.1e} | {:.0} us | {:.0} us |",
                cost / POINTS as u64,
                time / POINTS as f64 * 1e6,
                exact_time / POINTS as f64 * 1e6
            );
        }
    }
    println!();
    Ok(())
}
