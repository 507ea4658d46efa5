//! The brief's prototype measurement, reproduced: lights 4 to 6 units above
//! a 1000 x 1000 ground, shading points on the ground, a certified threshold
//! of 1% of the pixel's value on the summed node errors; evaluations per
//! shading point (averaged over 20 points) for the paper's first-order bound
//! and this crate's tight bound, with the actual errors against the exact
//! sum.
//!
//! The prototype (octree, one light per leaf) needed 6,339 / 28,257 /
//! 134,364 nodes with the paper's bound and 5,141 / 14,595 / 26,664 with a
//! second-order bound at 10^4 / 10^5 / 10^6 lights, and a Lightcuts-style
//! per-node criterion (not certified) 361-383 / 451-547 / 603-872.
//!
//! ```text
//! cargo run --release --example prototype
//! ```

use std::time::Instant;

use glam::Vec3;
use manylights::{BoundKind, Lambert, LightTree, PointLight, ROUNDING_ALLOWANCE, Threshold};

const POINTS: usize = 20;
const GROUND: f32 = 1000.0;
const THRESHOLD: f64 = 0.01;

/// xorshift64, mapped to `[0, 1)`.
fn uniform(state: &mut u64) -> f32 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

fn main() {
    println!(
        "| lights | bound | evaluations / point | max actual rel. error | time / point | exact sum / point |"
    );
    println!("|---|---|---|---|---|---|");
    for count in [10_000usize, 100_000, 1_000_000] {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let lights: Vec<PointLight> = (0..count)
            .map(|_| {
                let p = Vec3::new(
                    uniform(&mut s) * GROUND,
                    uniform(&mut s) * GROUND,
                    4.0 + 2.0 * uniform(&mut s),
                );
                PointLight::new(p, Vec3::ONE)
            })
            .collect();
        let tree = LightTree::build(&lights).expect("valid lights");
        let points: Vec<Vec3> = (0..POINTS)
            .map(|_| Vec3::new(uniform(&mut s) * GROUND, uniform(&mut s) * GROUND, 0.0))
            .collect();
        let rows = [
            (
                "paper bound, certified 1%",
                BoundKind::Paper,
                Threshold::relative(THRESHOLD),
            ),
            (
                "tight bound, certified 1%",
                BoundKind::Tight,
                Threshold::relative(THRESHOLD),
            ),
            (
                "tight bound, per-node 1% (Lightcuts)",
                BoundKind::Tight,
                Threshold::per_node(THRESHOLD),
            ),
        ];
        for (name, kind, threshold) in rows {
            let mut shading = tree.shading(Lambert::new(Vec3::ONE).with_bound(kind));
            let (mut cost, mut max_rel, mut time, mut exact_time) = (0u64, 0.0f64, 0.0, 0.0);
            for &p in &points {
                let start = Instant::now();
                let r = shading.shade(p, Vec3::Z, threshold).expect("valid point");
                time += start.elapsed().as_secs_f64();
                let start = Instant::now();
                let exact = shading.shade_exact(p, Vec3::Z).expect("valid point");
                exact_time += start.elapsed().as_secs_f64();
                let diff = (r.radiance - exact).abs();
                assert!(
                    diff.cmple(r.error_bound + exact * ROUNDING_ALLOWANCE).all(),
                    "bound violated at {p}"
                );
                cost += u64::from(r.cost());
                max_rel = max_rel.max((diff / exact).max_element());
            }
            println!(
                "| {count} | {name} | {} | {max_rel:.1e} | {:.0} us | {:.0} us |",
                cost / POINTS as u64,
                time / POINTS as f64 * 1e6,
                exact_time / POINTS as f64 * 1e6
            );
        }
    }
}
