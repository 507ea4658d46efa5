//! Geometry the bounds are built from: boxes, the cone under which a ball is
//! seen, the validated shading point. Nothing here knows the tree.

mod aabb;
mod cone;
mod group;
mod surface;

pub use aabb::Aabb;
pub use cone::Cone;
pub use group::GroupView;
pub(crate) use group::{GroupBounds, Side};
pub use surface::Surface;
