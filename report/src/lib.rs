//! Scenes, baselines and the error-against-time report of the `manylights`
//! crate (an unpublished workspace member).
//!
//! * [`scenes`]: every procedural scene, generated from a seed with `rand`.
//! * Rendering helpers of the examples: [`camera`], [`raycast`] (primary
//!   rays through the night city), [`bvh`] (opaque boxes in an `obvhs`
//!   BVH), [`shadows`] (the visibility host of the scenes with occluders: a
//!   shaft classifier and any-hit shadow rays, the recipe for plugging a
//!   ray tracer into the crate), [`image`] (PNG output), [`compare`] (the
//!   certified check, error statistics and the printed table), [`options`].
//! * The report (binary `report`): the baselines [`exact`] (the exact sum,
//!   vectorized), [`sampling`] (Monte Carlo light sampling after Shirley et
//!   al. 1996 and Conty & Kulla 2018; one-sample samplers with their
//!   probabilities after pbrt-v4 and Cycles) and [`shadowed`] (the exact shadowed
//!   sum and Ward 1991); [`measure`], the sweeps ([`config`], [`sweep`],
//!   [`occluded`] for the night city with shadows and the canopy,
//!   [`mesh_city`] for the same city's buildings as triangles under
//!   `manylights-mesh`'s host,
//!   [`scaling`]), [`plot`], [`csv`], [`summary`], the
//!   ground scene's evaluations-per-point table ([`evaluations`]), the
//!   Lambert bounds on the coloured street city ([`bounds`]), batch
//!   shading of a camera view ([`batch`]), where a certified cut's work
//!   goes ([`anatomy`]), light sampling for path tracers
//!   ([`light_sampling`]) and the cut's cost on points among the street
//!   city's lamps ([`roofs`]).

pub mod anatomy;
pub mod batch;
pub mod bounds;
pub mod bvh;
pub mod camera;
pub mod compare;
pub mod config;
pub mod csv;
pub mod emitters;
pub mod evaluations;
pub mod exact;
pub mod exact_emitters;
pub mod ggx;
pub mod hostile;
pub mod image;
pub mod light_sampling;
pub mod measure;
pub mod mesh_city;
pub mod occluded;
pub mod options;
pub mod plot;
pub mod raycast;
pub mod roofs;
pub mod sampling;
pub mod scaling;
pub mod scenes;
pub mod shadowed;
pub mod shadows;
pub mod stochastic_batch;
pub mod summary;
pub mod sweep;
