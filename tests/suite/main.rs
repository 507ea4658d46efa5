//! The integration tests, as one test binary: the shading code they share
//! is compiled once rather than once per file.
//!
//! * `bound`, `batch`, `visibility`, `grazing`, `interpolation`: property
//!   tests of the certified-bound contract against the exact sum,
//!   `Shading::exact_query` (long runs: `PROPTEST_CASES=100000`, see
//!   [`common::cases`]).
//! * `node_bound`: the node bounds and the `f32` light sums against `f64`
//!   references.
//! * `stability`: stiff and extreme inputs.
//! * `contract`: the edges of the documented contract (met thresholds,
//!   infinite thresholds, budgets, refits of the wrong size).
//! * `cliffs`: hostile scenes, by their evaluation counts.
//! * `no_alloc`: a warmed session shades without allocating.
//! * `emitters`: oriented emitters (lobes, spots) in every shading path,
//!   against the exact sum; stiff cases of the profiles.
//! * `sampling`: the light sampler and the stochastic cut: probabilities,
//!   frequencies (chi-square) and unbiasedness.

mod batch;
mod bound;
mod cliffs;
mod common;
mod contract;
mod emitters;
mod ggx;
mod grazing;
mod interpolation;
mod no_alloc;
mod sampling;
mod stability;
mod visibility;
