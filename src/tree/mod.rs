//! The light hierarchy: its layout, its build, refit and invariant checks.
//! Nothing here knows shading.

mod build;
mod layout;
pub(crate) mod morton;
mod refit;
mod validate;

pub use build::TreeBuilder;
pub use layout::{LightTree, Node};
