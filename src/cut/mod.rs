//! The cut: the paper's error list refining the light tree until a
//! threshold is met, for one shading point or for a group of them.
//!
//! One engine ([`Cut`]) runs the list for a *region* of shading points:
//! it starts at the root, takes the waiting node of greatest (class,
//! error), refines it (its children, or a leaf's lights, enter the cut)
//! and stops when the threshold is met or the budget spent. Visibility,
//! budgets, the specular criterion, interpolation across levels and the
//! rules that sum small or near nodes light by light are written once,
//! here; a [`Region`](engine::Region) supplies what depends on where the bounds must hold:
//!
//! * [`Point`](point::Point): one shading point. A node's entry is the shader's
//!   certified interval at the point ([`Shader::bound`]); single lights
//!   are evaluated and summed at once; the host is asked about a node when
//!   the list takes it.
//! * [`Shared`]: every point of a group (the batch call). The group only
//!   widens each node's bound: its entry carries one error that holds at
//!   every point of the group (the node's series width taken at the
//!   group's nearest distance and largest cosine, see
//!   [`GroupView`](crate::geometry::GroupView)), and the estimate is left
//!   to each point, which sums the final cut at its own position and
//!   normal; single lights are kept for the points to evaluate; the host
//!   is asked about a node for the whole group when it enters, so that
//!   every entry holds for every point.
//!
//! [`Shader::bound`]: crate::shader::Shader::bound

mod engine;
mod entries;
mod error_list;
mod group;
mod interpolate;
mod lights;
mod point;
pub(crate) mod policy;
mod result;
mod steering;
mod threshold;

pub(crate) use engine::{Cut, Outcome};
pub(crate) use entries::settle_point;
pub(crate) use error_list::{ErrorList, Seen};
pub(crate) use group::{GroupCut, GroupScratch, Shared, Spend};
#[cfg(test)]
pub(crate) use lights::shade_small_scene;
pub(crate) use point::{Lent, PointScratch, emitted, reported_bound, shade_point};
pub use result::{ShadeResult, Stop};
pub(crate) use steering::{SAMPLES, Samples, Spread};
pub use threshold::{Target, Threshold};
