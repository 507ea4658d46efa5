//! Property-test generators shared by the integration tests, with their
//! documented ranges.
//!
//! * Light sets: 1 to 2,000 lights, either uniform in a cube of half-size 10
//!   about the origin or clustered (1 to 8 clusters of spread 0.01 to 2).
//! * Intensities: per light a colour with channels in `[0, 1]` (a channel
//!   is exactly 0 with probability 1/8) times a magnitude `10^u`, `u` uniform
//!   in `[-3, 3]`: six decades.
//! * Shading points: uniform in a cube of half-size 12 (so some lie inside
//!   the light sets' balls and some outside); normals and views uniform on
//!   the sphere, then scaled by a length in `[0.1, 10]` (the crate
//!   normalizes).
//! * Thresholds: absolute `10^u` with `u` in `[-6, 3]`, relative in
//!   `[1e-4, 0.5]`, per-node (Lightcuts) in `[1e-4, 0.5]`, exactly 0, infinite, budgets of 1 to 5,000, and
//!   interpolation bands of 1.1 to 8.
#![allow(dead_code)]

use glam::Vec3;
use manylights::{
    Coverage, NodeRegion, PointGroup, PointLight, ShadeResult, Threshold, Visibility,
};
use proptest::prelude::*;
use proptest::test_runner::FileFailurePersistence;

/// Where the suite's failing cases are kept, as a proptest
/// `SourceParallel` directory: proptest climbs from a module's file
/// (`tests/suite/batch.rs`) to the directory holding `main.rs`
/// (`tests/suite`), takes its parent (`tests`), and joins this and the
/// file's path below `tests/suite` with `.txt`, so the seeds of
/// `tests/suite/batch.rs` are in `proptest-regressions/suite/batch.txt` at
/// the crate root: the directory where the unit tests of `src/` keep theirs
/// by proptest's default (`src/phong.rs` in
/// `proptest-regressions/phong.txt`).
pub const REGRESSIONS: &str = "../proptest-regressions/suite";

/// A proptest configuration of `default` cases per property, which the
/// `PROPTEST_CASES` environment variable overrides for long runs, keeping
/// its failing cases under [`REGRESSIONS`] (and replaying those first).
///
/// A property that draws a case with nothing to check rejects it
/// (`prop_assume!`) and draws another; it may reject as many cases as it
/// runs, at least proptest's default of 1,024 (a fixed number, which a long
/// run of a property that rejects a share of its draws would exceed).
pub fn cases(default: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(default);
    let defaults = ProptestConfig::default();
    ProptestConfig {
        cases,
        max_global_rejects: defaults.max_global_rejects.max(cases),
        failure_persistence: Some(Box::new(FileFailurePersistence::SourceParallel(
            REGRESSIONS,
        ))),
        ..defaults
    }
}

/// Seed lines (`cc <seed>`) of a proptest regression file.
fn seed_lines(file: &std::path::Path) -> usize {
    std::fs::read_to_string(file)
        .unwrap_or_else(|e| panic!("{}: {e}", file.display()))
        .lines()
        .filter(|line| line.starts_with("cc "))
        .count()
}

/// The regression files under `dir`, recursively, their paths below it
/// without `.txt`.
fn regression_files(dir: &std::path::Path, below: &str, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap();
        let relative = format!("{below}{name}");
        if path.is_dir() {
            regression_files(&path, &format!("{relative}/"), out);
        } else if let Some(stem) = relative.strip_suffix(".txt") {
            out.push(stem.to_owned());
        }
    }
}

/// Every seed of `proptest-regressions/` is replayed: proptest, handed a
/// test's source file as its `proptest!` block hands it (`file!()`, a path
/// from the crate root), reads each file with all its seeds, the suite's
/// through [`cases`] and the unit tests' through proptest's default.
#[test]
fn every_saved_seed_is_read_back() {
    use proptest::test_runner::FailurePersistence;
    let regressions = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("proptest-regressions");
    let mut files = Vec::new();
    regression_files(&regressions, "", &mut files);
    assert!(!files.is_empty(), "no regression files");
    for file in &files {
        let (persistence, source) = match file.strip_prefix("suite/") {
            Some(module) => (
                cases(1).failure_persistence.unwrap(),
                format!("tests/suite/{module}.rs"),
            ),
            None => (
                Box::new(FileFailurePersistence::default()) as Box<dyn FailurePersistence>,
                format!("src/{file}.rs"),
            ),
        };
        let source: &'static str = Box::leak(source.into_boxed_str());
        let seeds = seed_lines(&regressions.join(format!("{file}.txt")));
        let read = persistence.load_persisted_failures2(Some(source)).len();
        assert!(seeds > 0, "{file}.txt holds no seed");
        assert_eq!(read, seeds, "seeds of {file}.txt read for {source}");
    }
}

/// A finite `Vec3` with each coordinate uniform in `[-h, h]`.
pub fn vec_in(h: f32) -> impl Strategy<Value = Vec3> {
    (-h..=h, -h..=h, -h..=h).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A unit vector (uniform on the sphere) scaled by a length in `[0.1, 10]`.
pub fn direction() -> impl Strategy<Value = Vec3> {
    (-1.0f32..=1.0, 0.0f32..std::f32::consts::TAU, 0.1f32..=10.0).prop_map(|(z, phi, len)| {
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z) * len
    })
}

/// An RGB intensity spanning six decades, channels sometimes exactly 0.
pub fn intensity() -> impl Strategy<Value = Vec3> {
    let channel = prop_oneof![1 => Just(0.0f32), 7 => 0.0f32..=1.0];
    (channel.clone(), channel.clone(), channel, -3.0f32..=3.0)
        .prop_map(|(r, g, b, e)| Vec3::new(r, g, b) * 10f32.powf(e))
}

/// Lights uniform in a cube of half-size 10.
pub fn uniform_lights(max: usize) -> impl Strategy<Value = Vec<PointLight>> {
    prop::collection::vec(
        (vec_in(10.0), intensity()).prop_map(|(p, i)| PointLight::new(p, i)),
        1..=max,
    )
}

/// Lights in 1 to 8 clusters of spread 0.01 to 2 about centres in a cube of
/// half-size 8.
pub fn clustered_lights(max: usize) -> impl Strategy<Value = Vec<PointLight>> {
    (
        prop::collection::vec((vec_in(8.0), 0.01f32..=2.0), 1..=8),
        prop::collection::vec(
            (any::<prop::sample::Index>(), vec_in(1.0), intensity()),
            1..=max,
        ),
    )
        .prop_map(|(clusters, members)| {
            members
                .into_iter()
                .map(|(which, offset, i)| {
                    let (c, spread) = clusters[which.index(clusters.len())];
                    PointLight::new(c + offset * spread, i)
                })
                .collect()
        })
}

/// Lights of either layout, all of one colour (white, or with channels
/// sometimes exactly 0) scaled by factors spanning six decades: the tree
/// keeps one channel's moments for them.
pub fn one_colour_lights(max: usize) -> impl Strategy<Value = Vec<PointLight>> {
    let colour = prop_oneof![1 => Just(Vec3::ONE), 3 => intensity().prop_map(|i| i / i.max_element().max(1e-30))];
    (
        prop_oneof![uniform_lights(max), clustered_lights(max)],
        colour,
    )
        .prop_map(|(lights, colour)| {
            lights
                .into_iter()
                .map(|l| PointLight::new(l.position, colour * l.intensity.max_element()))
                .collect()
        })
}

/// Either layout, with lights of many colours or of one.
pub fn lights(max: usize) -> impl Strategy<Value = Vec<PointLight>> {
    prop_oneof![
        2 => uniform_lights(max),
        2 => clustered_lights(max),
        1 => one_colour_lights(max)
    ]
}

/// A threshold of each kind.
pub fn threshold() -> impl Strategy<Value = Threshold> {
    prop_oneof![
        (-6.0f64..=3.0).prop_map(|u| Threshold::absolute(10f64.powf(u))),
        (1e-4f64..=0.5).prop_map(Threshold::relative),
        (1e-4f64..=0.5).prop_map(Threshold::per_node),
        Just(Threshold::zero()),
        Just(Threshold::absolute(f64::INFINITY)),
        (1u32..=5000, 1e-4f64..=0.5).prop_map(|(b, t)| Threshold::relative(t).with_budget(b)),
        (1e-4f64..=0.5, 1.1f64..=8.0)
            .prop_map(|(t, band)| Threshold::relative(t).with_interpolation(band)),
        (-6.0f64..=3.0, 1.1f64..=8.0)
            .prop_map(|(u, band)| Threshold::absolute(10f64.powf(u)).with_interpolation(band)),
    ]
}

/// The certified-bound contract ([`ShadeResult::certifies`]), a finite
/// radiance and a bound that is not NaN.
pub fn check_bound(r: &ShadeResult, exact: glam::DVec3) -> Result<(), TestCaseError> {
    prop_assert!(
        r.certifies(exact),
        "|{} - {}| = {} exceeds the bound {} (+ allowance)",
        r.radiance,
        exact,
        (r.radiance - exact).abs(),
        r.error_bound
    );
    check_finite(r)
}

/// A finite radiance and a bound that is not NaN.
pub fn check_finite(r: &ShadeResult) -> Result<(), TestCaseError> {
    prop_assert!(
        r.radiance.is_finite(),
        "radiance not finite: {}",
        r.radiance
    );
    prop_assert!(!r.error_bound.is_nan(), "bound is NaN");
    Ok(())
}

/// When the result says the threshold was met, its bound satisfies it
/// exactly as reported (no rounding slack).
pub fn check_threshold(r: &ShadeResult, t: &Threshold) -> Result<(), TestCaseError> {
    if r.stop != manylights::Stop::ThresholdMet {
        prop_assert!(t.budget().is_some(), "stopped by budget without one");
        return Ok(());
    }
    let err = r.error_bound.max_element();
    match t.target() {
        manylights::Target::Absolute(a) => prop_assert!(err <= a, "{err} > {a}"),
        // Lightcuts' criterion holds single nodes, not the sum, to `q`.
        manylights::Target::PerNode(_) => {}
        manylights::Target::Relative(q) => prop_assert!(
            err <= q * r.radiance.max_element(),
            "{err} > {q} * {}",
            r.radiance.max_element()
        ),
    }
    if let Some(m) = t.budget() {
        prop_assert!(
            r.cost() <= m.max(1) || r.cost() == r.lights_evaluated,
            "cost {} > budget {m}",
            r.cost()
        );
    }
    Ok(())
}

/// A host with an infinite wall in the plane `x = self.x`: a light is
/// hidden when the segment to it crosses the plane; nodes and groups of
/// points are classified by their boxes.
#[derive(Clone, Copy, Debug)]
pub struct Wall {
    pub x: f32,
}

impl Wall {
    fn side(&self, p: Vec3) -> bool {
        p.x < self.x
    }
}

impl Visibility for Wall {
    const CLASSIFIES_GROUPS: bool = true;

    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        let here = self.side(group.aabb.min);
        if self.side(group.aabb.max) != here {
            return Coverage::Partial;
        }
        self.classify(group.aabb.min, node)
    }

    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let (lo, hi) = (self.side(node.aabb.min), self.side(node.aabb.max));
        let here = self.side(point);
        if lo == here && hi == here {
            Coverage::Visible
        } else if lo != here && hi != here {
            Coverage::Occluded
        } else {
            Coverage::Partial
        }
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.side(point) == self.side(light)
    }
}
