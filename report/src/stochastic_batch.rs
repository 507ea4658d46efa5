//! The `stochastic-batch` part: the stochastic cut over a camera's image,
//! each pixel by its own cut ([`Shading::shade_stochastic`]) against the
//! batch call that shares one cut per group of neighbouring pixels
//! ([`Shading::shade_stochastic_batch`]).
//!
//! ```text
//! cargo run --release -p manylights-report -- stochastic-batch
//! ```
//!
//! The view is the batch part's: the street city (10^6 lights; `--quick`
//! 10^5) seen from 30 units above its streets, 320x180 pixels, the ground
//! pixels shaded (Lambert, albedo 1). For each threshold: time per pixel
//! of each way (median of alternating rounds), the mean relative variance
//! of one estimate (each pixel's reported variance averaged over the
//! rounds, over its mean radiance squared, averaged over the pixels), the
//! work per pixel, and the ratio of efficiencies (time times variance:
//! how much less time the batch call needs for the same noise).
//!
//! [`Shading::shade_stochastic`]: manylights::Shading::shade_stochastic
//! [`Shading::shade_stochastic_batch`]: manylights::Shading::shade_stochastic_batch

use std::error::Error;

use glam::{DVec3, Vec3};
use manylights::{BatchStats, Lambert, LightTree, Query, Stochastic, Threshold, Unoccluded};
use rand::RngExt;

use crate::batch::{BLOCK, EYE, FOV_DEGREES, TARGET, ground_hits, paired};
use crate::camera::Camera;
use crate::config::SEED;
use crate::scenes::{city_lights, rng};

/// The part's name on the command line.
pub const STOCHASTIC_BATCH: &str = "stochastic-batch";

/// The image.
const SIZE: (u32, u32) = (320, 180);
/// Alternating rounds of the two ways.
const ROUNDS: usize = 3;
/// The thresholds of the cut that chooses the nodes.
const THRESHOLDS: [f64; 2] = [0.3, 0.1];

/// One way's figures at one threshold.
struct Way {
    /// Per pixel: sum of the estimates, of the reported variances.
    radiance: Vec<DVec3>,
    variance: Vec<DVec3>,
    /// Work summed over the rounds.
    nodes_sampled: u64,
    nodes_evaluated: u64,
    lights: u64,
    stats: BatchStats,
}

impl Way {
    fn new(n: usize) -> Self {
        Self {
            radiance: vec![DVec3::ZERO; n],
            variance: vec![DVec3::ZERO; n],
            nodes_sampled: 0,
            nodes_evaluated: 0,
            lights: 0,
            stats: BatchStats::default(),
        }
    }

    fn add(&mut self, results: &[Stochastic]) {
        for (k, r) in results.iter().enumerate() {
            self.radiance[k] += r.radiance;
            self.variance[k] += r.variance;
            self.nodes_sampled += u64::from(r.nodes_sampled);
            self.nodes_evaluated += u64::from(r.nodes_evaluated);
            self.lights += u64::from(r.lights_evaluated);
        }
    }

    /// Mean over the pixels of the relative variance of one estimate
    /// (channels summed).
    fn relative_variance(&self) -> f64 {
        let n = self.radiance.len() as f64;
        let sum: f64 = self
            .radiance
            .iter()
            .zip(&self.variance)
            .map(|(r, v)| {
                let mean = r.element_sum() / ROUNDS as f64;
                let var = v.element_sum() / ROUNDS as f64;
                if mean > 0.0 { var / (mean * mean) } else { 0.0 }
            })
            .sum();
        sum / n
    }
}

/// Runs the part.
pub fn run_stochastic_batch(quick: bool) -> Result<(), Box<dyn Error>> {
    let count = if quick { 100_000 } else { 1_000_000 };
    let lights = city_lights(count, SEED);
    let tree = LightTree::build(&lights)?;
    let (lo, hi) = lights.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
    );
    let corner = (((lo + hi) * 0.5) / BLOCK).floor().with_z(0.0) * BLOCK;
    let camera = Camera::new(corner + EYE, corner + TARGET, FOV_DEGREES, SIZE.0, SIZE.1);
    let queries: Vec<Query> = ground_hits(&camera)
        .into_iter()
        .flatten()
        .map(|p| Query::new(p, Vec3::Z))
        .collect::<Result<_, _>>()?;
    let n = queries.len();
    println!(
        "## The stochastic cut over an image: street city, {} lights, {}x{} camera view \
         ({n} ground pixels), one core\n",
        tree.len(),
        SIZE.0,
        SIZE.1
    );
    println!("`cargo run --release -p manylights-report -- {STOCHASTIC_BATCH}`\n");
    println!(
        "| threshold | way | us / pixel | relative variance | nodes sampled / pixel | \
         node bounds / pixel | lights / pixel | pixels shared | efficiency, batch / alone |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut random = rng(SEED ^ 0x5B);
    for t in THRESHOLDS {
        let threshold = Threshold::relative(t);
        let (mut alone, mut batch) = (Way::new(n), Way::new(n));
        let mut results = vec![Stochastic::default(); n];
        // The shading session, the generator and the first error are
        // shared by both ways, which alternate; each borrows them in turn.
        let failure: Option<String> = None;
        let cell = std::cell::RefCell::new((&mut shading, &mut random, &mut results, failure));
        let timing = paired(
            ROUNDS,
            (n, n),
            || {
                let (shading, random, results, failure) = &mut *cell.borrow_mut();
                match shading.shade_stochastic_batch(
                    &queries,
                    threshold,
                    Unoccluded,
                    || random.random::<f64>(),
                    results,
                ) {
                    Ok(stats) => {
                        batch.stats += stats;
                        batch.add(results);
                    }
                    Err(e) => *failure = Some(e.to_string()),
                }
            },
            || {
                let (shading, random, results, failure) = &mut *cell.borrow_mut();
                for (q, r) in queries.iter().zip(results.iter_mut()) {
                    match shading
                        .shade_stochastic(q, threshold, Unoccluded, || random.random::<f64>())
                    {
                        Ok(x) => *r = x,
                        Err(e) => *failure = Some(e.to_string()),
                    }
                }
                alone.add(results);
            },
        );
        if let Some(e) = cell.into_inner().3 {
            return Err(e.into());
        }
        let per_pixel = |x: u64| x as f64 / (n * ROUNDS) as f64;
        let (va, vb) = (alone.relative_variance(), batch.relative_variance());
        let efficiency = (timing.exact_us * va) / (timing.us * vb);
        println!(
            "| {:.0}% | own cut | {:.1} | {va:.3e} | {:.1} | {:.1} | {:.0} | - | |",
            t * 100.0,
            timing.exact_us,
            per_pixel(alone.nodes_sampled),
            per_pixel(alone.nodes_evaluated),
            per_pixel(alone.lights),
        );
        println!(
            "| {:.0}% | batch | {:.1} | {vb:.3e} | {:.1} | {:.1} | {:.0} | {:.0}% | **{efficiency:.2}x** |",
            t * 100.0,
            timing.us,
            per_pixel(batch.nodes_sampled),
            per_pixel(batch.stats.shared_evaluations + batch.nodes_evaluated),
            per_pixel(batch.lights),
            100.0 * f64::from(batch.stats.shared_points)
                / f64::from(batch.stats.shared_points + batch.stats.points_alone),
        );
    }
    println!(
        "\nRelative variance: of one estimate, from the variances each call reports (unbiased), \
         averaged over the {ROUNDS} rounds and over the pixels. Efficiency: the own cut's time \
         times variance over the batch call's (above 1: the batch call reaches the same noise \
         sooner). Node bounds of the batch call: its shared cuts' and the pixels shaded alone.\n"
    );
    Ok(())
}
