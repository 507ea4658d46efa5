//! What one run of the report measures: the seed, the threshold sweeps of
//! every method, and the scene sizes of the full and the quick run.

use std::time::Duration;

use crate::scenes::{self, Scene};

/// Seed of every scene and sampler.
pub const SEED: u64 = 1998;

/// Relative thresholds of the crate's cut with its tight bound (from 0.3:
/// a met relative threshold t certifies t / (1 - t), nothing for t >= 1).
pub const TREE_RELATIVE: [f64; 8] = [0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4];
/// Relative thresholds with the paper's bound (it pays far more nodes for
/// the same threshold, so the sweep stops earlier).
pub const PAPER_RELATIVE: [f64; 5] = [0.3, 0.1, 0.03, 0.01, 3e-3];
/// Absolute thresholds, as fractions of the scene's median exact radiance
/// (largest channel); 0 refines to the exact sum.
pub const TREE_ABSOLUTE: [f64; 6] = [0.1, 0.01, 1e-3, 1e-4, 1e-5, 0.0];
/// Lightcuts' relative per-node thresholds: 0.5% to 5% around Walter et
/// al.'s 2%, extended to 0.1% so that the curve reaches 1%
/// max error.
pub const PER_NODE: [f64; 6] = [0.05, 0.02, 0.01, 0.005, 0.002, 0.001];
/// Per-node thresholds in the occluded scene: partially occluded nodes
/// keep the middle of `[0, upper]` as their estimate, so the per-node rule
/// needs smaller `t` there to reach 1% max error.
pub const SHADOW_PER_NODE: [f64; 7] = [0.02, 0.01, 0.005, 0.002, 0.001, 3e-4, 1e-4];
/// Relative thresholds of the tight-bound cut in the occluded scene.
pub const SHADOW_RELATIVE: [f64; 8] = [0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4];
/// Ward's thresholds: the fraction of the visible sum so far below which
/// the untested remainder is estimated (Radiance's `-dt`, default 0.03 to
/// 0.05).
pub const WARD: [f64; 7] = [0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 1e-4];
/// Monte Carlo sample counts per shading point.
pub const SAMPLE_COUNTS: [u32; 7] = [1, 4, 16, 64, 256, 1024, 4096];

/// What the report runs on one occluded scene, besides the exact shadowed
/// sum.
#[derive(Clone, Copy, Debug)]
pub struct OccludedSweeps {
    /// Relative thresholds of the tight-bound cut.
    pub relative: &'static [f64],
    /// Absolute thresholds, as fractions of the median exact radiance.
    pub absolute: &'static [f64],
    /// Per-node (Lightcuts) thresholds.
    pub per_node: &'static [f64],
    /// Monte Carlo sample counts (both samplers).
    pub samples: &'static [u32],
    /// Ward's thresholds.
    pub ward: &'static [f64],
    /// Time budget of a configuration's repeated passes, in units of
    /// [`Config::budget`].
    pub budget_factor: u32,
}

/// The night city with shadows: every method.
pub const CITY_SHADOWS_SWEEPS: OccludedSweeps = OccludedSweeps {
    relative: &SHADOW_RELATIVE,
    absolute: &TREE_ABSOLUTE,
    per_node: &SHADOW_PER_NODE,
    samples: &SAMPLE_COUNTS,
    ward: &WARD,
    budget_factor: 1,
};

/// The canopy: every shadow ray costs a traversal of a deep BVH, so only
/// the configurations around 1% are run (Monte Carlo does not reach 1% in
/// the city either), each with three times the budget so that a pass over
/// the points (about a third of a second) is repeated.
pub const CANOPY_SWEEPS: OccludedSweeps = OccludedSweeps {
    relative: &[0.03, 0.01],
    absolute: &[],
    per_node: &[],
    samples: &[],
    ward: &[0.03, 0.01],
    budget_factor: 3,
};

/// The error level the summary compares methods at.
pub const TARGET_ERROR: f64 = 0.01;
/// Baselines are said to beat the tree only at errors up to this (at larger
/// errors any method "wins" by doing almost nothing).
pub const USEFUL_ERROR: f64 = 0.1;
/// Largest relative difference allowed between the vectorized `f32` exact
/// sum and the crate's `f64` reference.
pub const SOA_TOLERANCE: f64 = 1e-5;

/// Fixed relative threshold of the scaling part.
pub const SCALING_RELATIVE: f64 = 0.01;
/// Fixed absolute threshold of the scaling part, in radiance units: 1% of
/// the city's median radiance (0.75-0.81 from 10^4 lights up; the fixed
/// lamp density keeps it nearly the same at every size).
pub const SCALING_ABSOLUTE: f64 = 0.008;
/// The relative sweep run at every size for the summary's speed-up.
pub const SCALING_SWEEP: [f64; 4] = [0.3, 0.1, 0.03, 0.01];
/// Trees of more lights than this are built [`BUILD_REPEATS_LARGE`] times
/// when timed, smaller ones [`BUILD_REPEATS`] times (see
/// [`build_repeats`]).
pub const BUILD_LARGE_ABOVE: usize = 1_000_000;
/// Timed builds of a tree of at most [`BUILD_LARGE_ABOVE`] lights: the
/// median of five is steadier than of three on a shared machine.
pub const BUILD_REPEATS: usize = 5;
/// Timed builds of a larger tree (a build of 10^7 lights takes seconds).
pub const BUILD_REPEATS_LARGE: usize = 3;

/// How many times a tree of `lights` lights is built when its build is
/// timed (the median kept), by every part of the report.
pub const fn build_repeats(lights: usize) -> usize {
    if lights > BUILD_LARGE_ABOVE {
        BUILD_REPEATS_LARGE
    } else {
        BUILD_REPEATS
    }
}

/// Sizes and budgets of one run.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Shading points per scene.
    pub points: usize,
    /// Lights of each unoccluded scene.
    pub city_lights: usize,
    /// Lights of the chandelier.
    pub chandelier_lights: usize,
    /// Lights of the strings scene.
    pub strings_lights: usize,
    /// Lights of the glossy scene.
    pub specular_lights: usize,
    /// Lights of the occluded city (its reference casts a shadow ray per
    /// light and point).
    pub shadow_lights: usize,
    /// Lights of the canopy.
    pub canopy_lights: usize,
    /// Shading points of the canopy.
    pub canopy_points: usize,
    /// Numbers of lights of the scaling part.
    pub scaling_sizes: &'static [usize],
    /// Shading points per size of the scaling part.
    pub scaling_points: usize,
    /// Time budget of the repeated timing passes of one configuration.
    pub budget: Duration,
}

/// The full run (about a minute on two cores).
pub const FULL: Config = Config {
    points: 256,
    city_lights: 100_000,
    chandelier_lights: 50_000,
    strings_lights: 20_000,
    specular_lights: 20_000,
    shadow_lights: 20_000,
    canopy_lights: 5_000,
    canopy_points: 64,
    scaling_sizes: &[100, 1_000, 10_000, 100_000, 1_000_000],
    scaling_points: 128,
    budget: Duration::from_millis(400),
};

/// The smoke run (`--quick`, seconds).
pub const QUICK: Config = Config {
    points: 32,
    city_lights: 10_000,
    chandelier_lights: 5_000,
    strings_lights: 2_000,
    specular_lights: 2_000,
    shadow_lights: 2_000,
    canopy_lights: 1_000,
    canopy_points: 16,
    scaling_sizes: &[100, 1_000, 10_000],
    scaling_points: 32,
    budget: Duration::from_millis(20),
};

/// The unoccluded scenes, by name.
pub const SCENE_NAMES: [&str; 4] = ["city", "chandelier", "strings", "specular"];
/// The occluded city's name.
pub const OCCLUDED: &str = "city-shadows";
/// The canopy's name.
pub const CANOPY: &str = "canopy";
/// The occluded scenes, by name.
pub const OCCLUDED_NAMES: [&str; 2] = [OCCLUDED, CANOPY];
/// The part that runs every occluded scene.
pub const SHADOWS: &str = "shadows";
/// The scaling part's name.
pub const SCALING: &str = "scaling";

/// The unoccluded scene `name` (one of [`SCENE_NAMES`]) at the sizes of
/// `cfg`.
pub fn make_scene(name: &str, cfg: &Config) -> Scene {
    match name {
        "city" => scenes::city(cfg.city_lights, cfg.points, SEED),
        "chandelier" => scenes::chandelier(cfg.chandelier_lights, cfg.points, SEED),
        "strings" => scenes::strings(cfg.strings_lights, cfg.points, SEED),
        "specular" => scenes::specular(cfg.specular_lights, cfg.points, SEED),
        _ => unreachable!("scene names are checked when parsing"),
    }
}
