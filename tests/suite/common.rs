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
use manylights::{PointLight, ShadeResult, Threshold};
use proptest::prelude::*;

/// A proptest configuration of `default` cases per property, which the
/// `PROPTEST_CASES` environment variable overrides for long runs.
pub fn cases(default: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(default);
    ProptestConfig {
        cases,
        ..ProptestConfig::default()
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
