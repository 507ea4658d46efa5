//! A light hierarchy with certified error bounds, for shading scenes lit by
//! thousands to millions of point lights.
//!
//! This crate implements the light hierarchy of Paquette, Poulin and
//! Drettakis, *A Light Hierarchy for Fast Rendering of Scenes with Many
//! Lights* (Eurographics 1998), and tightens its bounds: a [`LightTree`]
//! groups point lights into an octree whose nodes are *virtual lights*
//! (summed intensity at the weight-averaged position); a [`Shader`](shader::Shader) evaluates
//! one light exactly and bounds a whole node; a [`Shading`] session picks,
//! for each shading point, a cut through the tree with the paper's *error
//! list* until the summed certified error meets a [`Threshold`], and returns
//! the radiance, the certified error bound and the work done.
//! [`Shading::shade_batch`] shades many points at once, neighbouring points
//! sharing one certified cut (each still with its own certified bound).
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
//! let exact = shading.exact(p, n)?;
//! assert!(r.certifies(exact));
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
//! microfacet L_s = sum_i V_i I_i f(w_i, v) max(0, n.w_i) / d_i^2,
//!           f = D G2 F / (4 (n.w_i)(n.v)), 0 unless n.v > 0        (Ggx)
//! ```
//!
//! ([`Ggx`] states its GGX `D`, height-correlated Smith `G2` and Schlick
//! `F`.)
//!
//! `V_i` is the host's point-to-point visibility (1 without a
//! [`Visibility`]). The caller's `f32` point, normal, view and light
//! positions are taken as exact real numbers. Conventions, identical in
//! [`Shading::exact_query`] and every bound:
//!
//! * a light exactly on the shading point (`d_i = 0`) contributes 0 (its
//!   direction is undefined; the model's limit depends on the approach);
//! * `max(0, c)^e` is 0 for `c <= 0`, also when `e = 0`;
//! * normals and views need not be unit: the model uses `n = N / |N|` and
//!   `v = V / |V|` of the given `N` and `V`, exactly; zero or non-finite
//!   ones are refused with [`ShadeError`];
//! * `n . v < 0` (the eye below the surface): the Phong formula is applied as
//!   written (see [`Phong`]); hosts flip normals for two-sided shading.
//!
//! Lights may carry an emission profile ([`Emission`]; trees built with
//! [`LightTree::build_emitters`]): light `i` with axis `m_i` emits `I_i
//! f_i(c_i)` towards `p`, `c_i = m_i . (p - x_i) / |p - x_i|` (the stored
//! axis, normalized in `f64`), and every term above is multiplied by
//! `f_i(c_i)`:
//!
//! ```text
//! isotropic   f(c) = 1                                  (PointLight alone)
//! cosine lobe f(c) = c^k for c > 0, else 0, 0 <= k <= 1e4  (k = 1: a diffuse VPL)
//! glTF spot   f(c) = t^2, t = clamp((c - cos_outer) / (cos_inner - cos_outer), 0, 1),
//!             1 for c >= cos_inner, 0 for c <= cos_outer
//! two-sided   |c| in place of c
//! ```
//!
//! The sign of `m_i . (p - x_i)` is decided exactly, as the tangent plane's
//! is. A custom [`Shader`](shader::Shader) needs nothing for it: the crate
//! multiplies its `eval` by the profile's value, and its node bound by the
//! range of the members' profile values, which each node bounds from a
//! cone about its members' axes ([`Emission`] documents the profiles).
//!
//! [`Shading::exact_query`] (and its one-line form [`Shading::exact`]) sums
//! the model over every light in `f64` with compensated summation: it is the
//! reference, and nothing else. Where the model jumps, each term is decided
//! exactly from the `f32` inputs: whether a light lies above the tangent
//! plane (the sign of `N . (x_i - p)`), and whether it lies inside the Phong
//! lobe (the sign of `r . w_i`, which is that of `R . (x_i - p)` with `R = 2
//! (N.V) N - (N.N) V`: a polynomial in the inputs, no square root). Both
//! come from error-free transformations, so a light exactly in
//! the tangent plane or on the lobe's border contributes exactly 0, and one
//! barely off it its value to about `1e-12` relative.
//!
//! # Shading a point
//!
//! A [`Query`] carries what varies per shading point (point, normal, and a
//! view for view-dependent shaders), validated once where it is built;
//! [`Shading::shade_query`] and [`Shading::exact_query`] take it together
//! with the host's [`Visibility`] ([`Unoccluded`] for none). A query without
//! a view given to a view-dependent shader such as [`Phong`] does not
//! compile.
//!
//! # The certified bound
//!
//! For every input in the supported range,
//!
//! ```text
//! |radiance_k - exact_k| <= error_bound_k + ROUNDING_ALLOWANCE * exact_k
//! ```
//!
//! ([`ShadeResult::certifies`] checks it; [`ShadeResult::ROUNDING_ALLOWANCE`]
//! is `1e-9`)
//!
//! per channel `k`, with `exact` the model above (the inputs taken as exact
//! real numbers), provided the host's visibility classification is
//! conservative ([`Visibility`]). Every node bound rounds its absolute
//! errors outward (named slacks, each derived where it is defined; upward
//! rounding of stored radii, moments and harmonic norms), and the cut folds
//! its own `f64` summation error into the bound; the allowance covers what
//! is left, the relative rounding of single terms and of the reference sum.
//!
//! Some sums and bounds run in `f32` where that is a negligible part of the
//! target (relative targets of at least `2^-12`, without interpolation):
//! [`Lambert`] sums small groups of visible lights and bounds the children
//! of a refined node in `f32` lanes, and the batch call
//! ([`Shading::shade_batch`]) sums a shared cut's estimates in `f32` lanes
//! when its certified error is at least `2^-12` of the radiance it aims at.
//! Where an `f32` sum of lights is too coarse (lights within a hair of the
//! tangent plane, whose heights are a small difference of large
//! coordinates), [`Lambert`] sums them in plain `f64` instead of deciding
//! each term's sign exactly, bounding each height's rounding by its
//! magnitude. Each such sum or bound carries a certified bound on its own rounding
//! (derived in the code beside it), which the reported bound includes, so
//! the contract is the same.
//!
//! Where a term jumps, no allowance is needed, and none is widened: a
//! single light's term is exactly 0 when the model's is (in the tangent
//! plane; on or behind the Phong lobe's border, also for `e = 0`, where the
//! model is discontinuous), because its sign is decided exactly. Phong at
//! the lobe's border is evaluated exactly, not given a wider allowance. With
//! the default [`BoundKind::Series`], a node whose box lies at or below the
//! tangent plane is settled as exactly 0 by an exact test, so lights
//! exactly in the tangent plane cost a few evaluations, not a walk of the
//! tree. A Lambert term is within `2^-40` (about `9e-13`) relative, within
//! about `f64::EPSILON` near the plane; a Phong term within about `4e-12`
//! for every exponent up to [`Phong::MAX_EXPONENT`] (see [`Phong`]).
//!
//! `f64` sets one limit: a term below `f64::MIN_POSITIVE` (`2.2e-308`) is
//! subnormal, rounded to a multiple of `2^-1074` whatever its relative
//! accuracy, so in that range the contract holds up to an absolute few
//! `2^-1074` per light.
//!
//! When a budget stops the cut before a node whose ball contains the shading
//! point was refined, the bound is `+inf` (nothing finite is certain there).
//!
//! # Supported range
//!
//! * Light coordinates: finite, magnitude at most [`PointLight::MAX_COORDINATE`]
//!   (`1e18`); anything else is refused at build time. Shading points: any
//!   finite `f32`.
//! * Intensities: finite `f32`, `>= 0` (so up to `3.4e38`); node sums and all
//!   shading arithmetic are `f64`, so sums of many lights near `f32::MAX`
//!   neither overflow nor lose the bound.
//! * Emission: axes finite and non-zero, cosine exponents `0 ..= 1e4`, spot
//!   angles `0 <= inner <= outer <= pi/2` with `outer > 0` (`f32`'s
//!   `FRAC_PI_2`, just above pi/2, counts as pi/2); anything else is
//!   refused at build time ([`BuildError::InvalidEmission`]).
//! * Phong exponents `0 ..= 1e6` ([`Phong::MAX_EXPONENT`]); GGX roughness
//!   `1e-3 ..= 1` and `F0` in `[0, 1]` per channel ([`Ggx`]).
//! * Results are `f64` ([`glam::DVec3`]). A result is infinite only where the
//!   model is: never, for finite `f32` inputs, since the closest two distinct
//!   `f32` points are `1.4e-45` apart and `f32::MAX / (1.4e-45)^2` fits in an
//!   `f64`.
//!
//! # Cost
//!
//! A scene pays for what it uses: a diffuse-only shader computes no
//! specular term; the default [`Unoccluded`] visibility compiles every
//! visibility call away; a tree of isotropic lights stores nothing for
//! emission profiles and takes none of their paths; a [`Shading`] session
//! reuses its scratch, so shading allocates nothing once warmed.
//!
//! A point's cut costs at most about the exact sum of its lights: once its
//! work (a node bound counted as 16 lights) reaches half the scene's
//! lights, it stops bounding and sums the lights still waiting, so that
//! it evaluates each light at most once and at most `N / 32 + 8` node
//! bounds (scenes of at least 4,096 lights, without a budget, interpolation
//! across levels or a host's visibility, whose rays cost more than the
//! cut's classifications). That happens only where the bounds
//! settle little: a tangent plane running through a layer of lights
//! everywhere near the point. The batch call shades a group whose shared
//! cut does not pay point by point.
//!
//! Emitters cost more per evaluation than isotropic lights: their lights
//! are summed in `f64` with each profile's value (the `f32` light sums are
//! for isotropic lights), each node bound adds its profile range (from the
//! node's ball and from its box's extent along the members' mean axis),
//! and near a point a node whose members' cones may or may not reach it
//! is summed light by light. Nodes aimed away from a point cost one
//! evaluation and no light, so spot lamps, dark at most points, cost far
//! fewer evaluations than isotropic ones; a diffuse shader bounds a node
//! of diffuse VPLs about one axis to second order.
//!
//! # Feature flags
//!
//! * `rayon` (off by default): work spread over rayon's thread pool, with
//!   the same results as on one thread: `Shading::shade_batch_parallel`,
//!   `TreeBuilder::build_parallel` (`LightTree::builder().build_parallel(..)`
//!   for the default options), `TreeBuilder::rebuild_parallel` and
//!   `LightTree::refit_parallel`.
//!
//! Without it the crate depends only on `glam`, `smallvec` and `thiserror`.

#![deny(unsafe_code)]

mod combined;
mod cut;
mod dispatch;
mod emission;
mod error;
mod geometry;
mod ggx;
mod lambert;
mod lanes;
mod light;
mod numeric;
mod phong;
mod sampling;
pub mod shader;
mod shading;
#[cfg(test)]
mod testing;
mod tree;
mod visibility;

pub use combined::Combined;
pub use cut::{ShadeResult, Stop, Target, Threshold};
pub use emission::{Emission, Emitter};
pub use error::{BuildError, ShadeError, ValidationError};
pub use geometry::Aabb;
pub use ggx::Ggx;
pub use lambert::{BoundKind, Lambert};
pub(crate) use light::LightLanes;
pub use light::PointLight;
pub use phong::Phong;
pub use sampling::{LightSampler, Sampled, Stochastic};
pub use shading::{BatchStats, Query, Shading};
pub use tree::{LightTree, TreeBuilder};
pub use visibility::{Coverage, NodeRegion, PointGroup, Unoccluded, Visibility};

/// The type states of a [`Query`]: whether it carries a view direction
/// ([`WithView`](query::WithView)) or not ([`NoView`](query::NoView)), and
/// which a shader accepts ([`Accepts`](query::Accepts)). A view-dependent shader given a query without a view does
/// not compile; a renderer names these only in generic code over queries.
pub mod query {
    pub use crate::shading::{Accepts, NoView, WithView};
}

// The README's code blocks are compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
