//! The light hierarchy: its layout, its build, refit and invariant checks.
//! Nothing here knows shading.

mod build;
pub(crate) mod groups;
mod layout;
mod moments;
pub(crate) mod morton;
mod plane;
mod pool;
mod refit;
mod validate;

pub use build::TreeBuilder;
pub use layout::{LightTree, Node};
pub(crate) use layout::{MAX_CHILDREN, NO_PLANE};
