//! Timing and error statistics of one configuration over a scene's shading
//! points, and the rows the report writes.

use std::hint::black_box;
use std::time::{Duration, Instant};

use glam::DVec3;
use manylights::{ShadeResult, Unoccluded, Visibility};

/// At most this many timed passes over the shading points per
/// configuration; the fastest is kept.
pub const MAX_PASSES: usize = 7;

/// What one method returns for one shading point.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sample {
    /// The estimated radiance.
    pub radiance: DVec3,
    /// The tree's whole result, with its certified bound, for the crate's
    /// cuts.
    pub result: Option<ShadeResult>,
    /// Work done, in the method's own unit (node bounds plus light
    /// evaluations for cuts, samples for Monte Carlo, lights for the exact
    /// sum).
    pub cost: u32,
    /// Visibility work in an occluded scene: shadow rays (point-to-point
    /// queries) and node classifications.
    pub queries: Option<Queries>,
}

impl Sample {
    /// A baseline's estimate: `cost` in its own unit, with the shadow rays
    /// it cast in an occluded scene.
    pub fn estimate(radiance: DVec3, cost: u32, shadow_rays: Option<u32>) -> Self {
        Self {
            radiance,
            result: None,
            cost,
            queries: shadow_rays.map(|shadow_rays| Queries {
                shadow_rays,
                classify: 0,
            }),
        }
    }

    /// A cut of the crate's tree, with the visibility work its host
    /// counted in an occluded scene.
    pub fn cut(r: ShadeResult, queries: Option<Queries>) -> Self {
        Self {
            radiance: r.radiance,
            result: Some(r),
            cost: r.cost(),
            queries,
        }
    }
}

/// Visibility queries of one shading point.
#[derive(Clone, Copy, Debug, Default)]
pub struct Queries {
    /// Shadow rays: point-to-point queries, and any other ray the host cast
    /// (e.g. for a visible fraction).
    pub shadow_rays: u32,
    /// Warnock-style classifications of a node's box.
    pub classify: u32,
}

/// A visibility host that counts what it does: every classification and
/// every shadow ray, including those the crate does not see (a visible
/// fraction's rays).
pub trait Counted: Visibility {
    /// The work done since the host was made.
    fn queries(&self) -> Queries;
}

/// No occluders: nothing asked, nothing cast.
impl Counted for Unoccluded {
    fn queries(&self) -> Queries {
        Queries::default()
    }
}

/// Time and accuracy of one configuration over a set of shading points.
#[derive(Clone, Copy, Debug)]
pub struct Measurement {
    /// Seconds per shading point: the fastest pass's total divided by the
    /// number of points.
    pub seconds_per_point: f64,
    /// Mean over the points of the relative error (largest channel).
    pub mean_error: f64,
    /// Largest relative error over the points.
    pub max_error: f64,
    /// Mean and largest relative certified bound, for certified methods.
    pub bound: Option<(f64, f64)>,
    /// Mean cost per point.
    pub mean_cost: f64,
    /// Mean shadow rays and mean classifications per point, in occluded
    /// scenes.
    pub queries: Option<(f64, f64)>,
    /// Points where the crate's result breaks its certified bound (there
    /// should be none).
    pub violations: usize,
}

/// Relative error in the largest channel: `max_k |estimate_k - exact_k| /
/// max_k exact_k` (the normalization of the crate's relative threshold, so
/// that a dim channel of a coloured light does not blow the ratio up).
pub fn relative(difference: DVec3, exact: DVec3) -> f64 {
    difference.abs().max_element() / exact.max_element()
}

/// Runs `shade` over every point index `0..references.len()`, timing whole
/// passes: the first pass records the samples, then passes repeat while the
/// total stays within `budget` (at most [`MAX_PASSES`]); the fastest pass
/// counts. Single-threaded, so a time per point is a time per point.
pub fn measure(
    references: &[DVec3],
    budget: Duration,
    mut shade: impl FnMut(usize) -> Sample,
) -> Measurement {
    let points = references.len();
    let mut samples = vec![Sample::default(); points];
    let started = Instant::now();
    let mut fastest = Duration::MAX;
    for _ in 0..MAX_PASSES {
        let t = Instant::now();
        for (i, sample) in samples.iter_mut().enumerate() {
            *sample = black_box(shade(black_box(i)));
        }
        let elapsed = t.elapsed();
        fastest = fastest.min(elapsed);
        if started.elapsed() + fastest > budget {
            break;
        }
    }
    let n = points as f64;
    let errors: Vec<f64> = samples
        .iter()
        .zip(references)
        .map(|(s, &exact)| relative(s.radiance - exact, exact))
        .collect();
    let bounds: Option<Vec<f64>> = samples
        .iter()
        .zip(references)
        .map(|(s, &exact)| s.result.map(|r| relative(r.error_bound, exact)))
        .collect();
    Measurement {
        seconds_per_point: fastest.as_secs_f64() / n,
        mean_error: errors.iter().sum::<f64>() / n,
        max_error: errors.iter().copied().fold(0.0, f64::max),
        bound: bounds.map(|b| {
            (
                b.iter().sum::<f64>() / n,
                b.iter().copied().fold(0.0, f64::max),
            )
        }),
        mean_cost: samples.iter().map(|s| f64::from(s.cost)).sum::<f64>() / n,
        queries: samples
            .iter()
            .map(|s| s.queries)
            .collect::<Option<Vec<Queries>>>()
            .map(|q| {
                let mean =
                    |f: fn(&Queries) -> u32| q.iter().map(|x| f64::from(f(x))).sum::<f64>() / n;
                (mean(|x| x.shadow_rays), mean(|x| x.classify))
            }),
        violations: samples
            .iter()
            .zip(references)
            .filter(|(s, exact)| s.result.is_some_and(|r| !r.certifies(**exact)))
            .count(),
    }
}

/// Two methods timed in alternating passes over the same points: robust to
/// a machine whose load drifts during the run.
#[derive(Clone, Copy, Debug)]
pub struct Paired {
    /// Median over the passes of the first method's seconds per point.
    pub first: f64,
    /// Median over the passes of the second method's seconds per point.
    pub second: f64,
    /// Median over the rounds of the second's pass time over the first's.
    pub ratio: f64,
    /// Rounds (one pass of each).
    pub rounds: usize,
}

/// Times `rounds` rounds of one pass of `first` and one of `second` over
/// every point index `0..points`, single-threaded.
pub fn paired(
    points: usize,
    rounds: usize,
    mut first: impl FnMut(usize) -> Sample,
    mut second: impl FnMut(usize) -> Sample,
) -> Paired {
    let pass = |shade: &mut dyn FnMut(usize) -> Sample| {
        let t = Instant::now();
        for i in 0..points {
            black_box(shade(black_box(i)));
        }
        t.elapsed().as_secs_f64() / points as f64
    };
    let (mut a, mut b, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..rounds {
        let (x, y) = (pass(&mut first), pass(&mut second));
        a.push(x);
        b.push(y);
        ratios.push(y / x);
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Paired {
        first: median(a),
        second: median(b),
        ratio: median(ratios),
        rounds,
    }
}

/// The methods compared by the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// (a) The exact sum, vectorized `f32` structure-of-arrays (unoccluded
    /// scenes).
    ExactSoa,
    /// (a) The exact shadowed sum: one shadow ray per light above the
    /// tangent plane (occluded scenes).
    ExactShadowed,
    /// (b) The crate's cut with the paper's first-order bound, relative
    /// thresholds.
    TreePaper,
    /// (c) The crate's cut with its tightest bound, relative thresholds.
    TreeRelative,
    /// (c) The crate's cut with its tightest bound, absolute thresholds.
    TreeAbsolute,
    /// (d) The crate's cut with Lightcuts' per-node criterion
    /// (`Threshold::per_node`): bound reported, not held to the threshold.
    PerNode,
    /// (e) Monte Carlo light sampling proportional to power.
    PowerSampling,
    /// (f) Importance sampling down the light tree.
    TreeSampling,
    /// (g) Ward 1991 adaptive shadow testing (occluded scenes).
    Ward,
}

impl Method {
    /// Every method, in plotting order.
    pub const ALL: [Method; 9] = [
        Method::ExactSoa,
        Method::ExactShadowed,
        Method::TreePaper,
        Method::TreeRelative,
        Method::TreeAbsolute,
        Method::PerNode,
        Method::PowerSampling,
        Method::TreeSampling,
        Method::Ward,
    ];

    /// Identifier used in the CSV files.
    pub fn id(self) -> &'static str {
        match self {
            Method::ExactSoa => "exact-soa",
            Method::ExactShadowed => "exact-shadowed",
            Method::TreePaper => "tree-paper-bound",
            Method::TreeRelative => "tree-tight-relative",
            Method::TreeAbsolute => "tree-tight-absolute",
            Method::PerNode => "tree-per-node",
            Method::PowerSampling => "mc-power",
            Method::TreeSampling => "mc-tree",
            Method::Ward => "ward-adaptive",
        }
    }

    /// Legend text.
    pub fn label(self) -> &'static str {
        match self {
            Method::ExactSoa => "(a) exact sum, f32 SIMD",
            Method::ExactShadowed => "(a) exact shadowed sum, 1 ray per light",
            Method::TreePaper => "(b) tree, paper's bound, relative t",
            Method::TreeRelative => "(c) tree, tight bound, relative t",
            Method::TreeAbsolute => "(c) tree, tight bound, absolute t",
            Method::PerNode => "(d) tree, per-node t (Lightcuts)",
            Method::PowerSampling => "(e) MC, power sampling",
            Method::TreeSampling => "(f) MC, light-tree sampling",
            Method::Ward => "(g) Ward 1991 adaptive shadow testing",
        }
    }

    /// The reference-quality baseline speed-ups are measured against.
    pub fn is_exact(self) -> bool {
        matches!(self, Method::ExactSoa | Method::ExactShadowed)
    }

    /// The crate's certified configurations with the best bound: what
    /// "the tree" means when a baseline is compared with it.
    pub fn is_best_tree(self) -> bool {
        matches!(self, Method::TreeRelative | Method::TreeAbsolute)
    }
}

/// One configuration's result on one scene: a row of `errors.csv`.
#[derive(Clone, Debug)]
pub struct Record {
    /// Scene name.
    pub scene: String,
    /// Number of lights in the scene.
    pub lights: usize,
    /// The method.
    pub method: Method,
    /// The method's parameter, as written (`t=0.01`, `abs=0.02`, `n=64`).
    pub parameter: String,
    /// Time and accuracy.
    pub measurement: Measurement,
}

/// The page faults this process has taken that the kernel served without
/// reading a file (first touches of fresh memory, mostly), from field 10
/// of `/proc/self/stat`; `None` where there is no such file (outside
/// Linux) or it does not parse.
pub fn minor_faults() -> Option<u64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may hold spaces:
    // the fields after its closing parenthesis start at field 3.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(10 - 3)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(target_os = "linux")]
    fn touching_fresh_memory_counts_minor_faults() {
        let before = minor_faults().expect("Linux has /proc/self/stat");
        // 64 MiB, far above the allocator's mapping threshold: fresh pages
        // from the kernel, each faulted in as it is first written.
        let pages = 16_384;
        let mut memory = vec![0u8; pages * 4096];
        for page in memory.chunks_mut(4096) {
            page[0] = 1;
        }
        std::hint::black_box(&memory);
        let after = minor_faults().expect("Linux has /proc/self/stat");
        // At least one fault per 2 MiB even with huge pages. (Other tests'
        // threads may add theirs: the count is the whole process's.)
        assert!(after >= before + pages as u64 / 512, "{before} -> {after}");
    }
}
