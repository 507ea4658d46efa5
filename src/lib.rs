//! A light hierarchy with certified error bounds, for shading scenes lit by
//! thousands to millions of point lights.
//!
//! This crate implements the light hierarchy of Paquette, Poulin and
//! Drettakis, *A Light Hierarchy for Fast Rendering of Scenes with Many
//! Lights* (Eurographics 1998), and tightens its bounds: a [`LightTree`]
//! groups point lights into an octree whose nodes are *virtual lights*
//! (summed intensity at the weight-averaged position); a [`Shader`] evaluates
//! one light exactly and bounds a whole node; a [`Shading`] session picks,
//! for each shading point, a cut through the tree with the paper's *error
//! list* until the summed certified error meets a [`Threshold`], and returns
//! the radiance, the certified error bound and the work done.
//!
//! ```
//! use manylights::{Lambert, LightTree, PointLight, Threshold};
//! use glam::Vec3;
//!
//! let lights: Vec<PointLight> = (0..10_000)
//!     .map(|i| {
//!         let (x, y) = ((i % 100) as f32, (i / 100) as f32);
//!         PointLight::new(Vec3::new(x, y, 5.0), Vec3::splat(1.0))
//!     })
//!     .collect();
//! let tree = LightTree::build(&lights)?;
//! let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
//!
//! let (p, n) = (Vec3::new(50.0, 50.0, 0.0), Vec3::Z);
//! let r = shading.shade(p, n, Threshold::relative(0.01))?;
//! let exact = shading.shade_exact(p, n)?;
//! assert!((r.radiance - exact).abs().max_element() <= r.error_bound.max_element() * (1.0 + 1e-9));
//! assert!(r.error_bound.max_element() <= 0.01 * r.radiance.max_element());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # The model
//!
//! For a shading point `p` with unit normal `n` and unit view direction `v`
//! (towards the eye), and lights `i` at `x_i` with RGB intensity `I_i >= 0`,
//! `d_i = |x_i - p|`, `w_i = (x_i - p) / d_i`:
//!
//! ```text
//! diffuse   L_d = sum_i V_i I_i kd max(0, n.w_i)   / d_i^2          (Lambert)
//! specular  L_s = sum_i V_i I_i ks max(0, r.w_i)^e / d_i^2,
//!           r = 2 (n.v) n - v                                       (Phong)
//! ```
//!
//! `V_i` is the host's point-to-point visibility (1 without a
//! [`Visibility`]). Conventions, identical in [`Shading::shade_exact`] and
//! every bound:
//!
//! * a light exactly on the shading point (`d_i = 0`) contributes 0 (its
//!   direction is undefined; the model's limit depends on the approach);
//! * `max(0, c)^e` is 0 for `c <= 0`, also when `e = 0`;
//! * normals and views need not be unit: they are normalized in `f64`; zero
//!   or non-finite ones are refused with [`ShadeError`];
//! * `n . v < 0` (the eye below the surface): the Phong formula is applied as
//!   written (see [`Phong`]); hosts flip normals for two-sided shading.
//!
//! `shade_exact` sums the model over every light in `f64` with compensated
//! summation: it is the reference, and nothing else.
//!
//! # The certified bound
//!
//! For every input in the supported range,
//!
//! ```text
//! |radiance_k - exact_k| <= error_bound_k + ROUNDING_ALLOWANCE * exact_k
//! ```
//!
//! per channel `k`, provided the host's visibility classification is
//! conservative ([`Visibility`]). Every node bound rounds its absolute
//! errors outward ([`COS_SLACK`], [`lambert::SERIES_SLACK`],
//! [`lambert::POINT_SLACK`], [`lambert::SECOND_ORDER_SLACK`], upward
//! rounding of stored radii, moments and harmonic norms), and the cut folds its own `f64`
//! summation error into the bound; [`ROUNDING_ALLOWANCE`] covers what is
//! left, the relative rounding of single terms and of the reference sum.
//! When a budget stops the cut before a node whose ball contains the shading
//! point was refined, the bound is `+inf` (nothing finite is certain there).
//!
//! # Supported range
//!
//! * Light coordinates: finite, magnitude at most [`MAX_COORDINATE`]
//!   (`1e18`); anything else is refused at build time. Shading points: any
//!   finite `f32`.
//! * Intensities: finite `f32`, `>= 0` (so up to `3.4e38`); node sums and all
//!   shading arithmetic are `f64`, so sums of many lights near `f32::MAX`
//!   neither overflow nor lose the bound.
//! * Phong exponents `0 ..= 1e6` ([`phong::MAX_EXPONENT`]).
//! * Results are `f64` ([`glam::DVec3`]). A result is infinite only where the
//!   model is: never, for finite `f32` inputs, since the closest two distinct
//!   `f32` points are `1.4e-45` apart and `f32::MAX / (1.4e-45)^2` fits in an
//!   `f64`.
//!
//! # Cost
//!
//! A scene pays for what it uses: a diffuse-only shader computes no
//! specular term; the default [`Unoccluded`] visibility compiles every
//! visibility call away; a [`Shading`] session reuses its scratch, so
//! shading allocates nothing once warmed.
//!
//! # Feature flags
//!
//! None yet: the crate depends only on `glam`, `smallvec` and `thiserror`.

#![forbid(unsafe_code)]

pub mod build;
mod cut;
mod error;
pub mod geometry;
pub mod lambert;
mod light;
pub mod phong;
mod shader;
mod tree;
mod validate;
mod visibility;

pub use build::TreeBuilder;
pub use cut::{ShadeResult, Shading, Stop, Target, Threshold};
pub use error::{BuildError, ShadeError, ValidationError};
pub use geometry::{COS_SLACK, Cone, MIN_CLEARANCE, Surface};
pub use lambert::{BoundKind, Lambert};
pub use light::PointLight;
pub use phong::Phong;
pub use shader::{Combined, NodeBound, Shader, ViewIndependent};
pub use tree::{Aabb, LightTree, Node};
pub use visibility::{Coverage, NodeBounds, Unoccluded, Visibility};

// The README's code blocks are compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

/// Largest supported magnitude of a light coordinate. It keeps squared
/// distances between lights (at most `(2e18)^2 * 3 = 1.2e37`) within `f32`,
/// where node second moments are stored.
pub const MAX_COORDINATE: f32 = 1e18;

/// Relative rounding allowance of the certified-bound contract:
/// `|radiance - exact| <= error_bound + ROUNDING_ALLOWANCE * exact` per
/// channel.
///
/// What it covers: the relative rounding of single terms (a light's `f64`
/// evaluation is within about `1e-15` relative; a Phong lobe computed as
/// `exp(e ln cos)` within `|e ln cos| * 2^-52 <= 2.5e-13`), relative rounding
/// of node interval ends computed in `f64` (likewise `<= 1e-12`), and the
/// reference sum's own error (compensated, about `2^-52`). `1e-9` leaves a
/// margin of 1000 over the largest of these.
pub const ROUNDING_ALLOWANCE: f64 = 1e-9;
