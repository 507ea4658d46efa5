//! The light hierarchy: its layout, its build, refit and invariant checks.
//! Nothing here knows shading.
//!
//! One concern a module, listed so that each imports only modules listed
//! before it (no two import each other, directly or in a cycle):
//!
//! * [`pool`]: where the passes run, on the calling thread or rayon's pool;
//! * [`prefetch`]: hints that start loading memory about to be read;
//! * [`harmonics`]: the solid harmonics of degrees 3 to 5;
//! * [`notes`]: what the statistics pass notes for the passes after it;
//! * [`node`]: a node, the virtual light of the lights below it;
//! * [`options`]: the build's options ([`TreeBuilder`]);
//! * [`moments`]: moments up to degree 5 and their shift to a new centre;
//! * [`radix`]: the radix sort of the Morton codes;
//! * [`morton`]: Morton codes and the octree's cells in their order;
//! * [`leaf_moments`]: a leaf's moments, summed over its lights;
//! * [`moment_statistics`]: what a node stores, read off its moments;
//! * [`check`]: the checks of the lights before a build or refit;
//! * [`groups`]: every node's children side by side, in blocks;
//! * [`layout`]: the tree's storage ([`LightTree`]);
//! * [`orientation`]: the lights' emission profiles and each node's bound
//!   on its members' axes;
//! * [`plane`]: nodes whose lights lie exactly in one tilted plane;
//! * [`slabs`]: the large nodes' moments in slices across their thinnest
//!   axis;
//! * [`statistics_pass`]: every node's statistics, bottom-up, and what
//!   follows from them;
//! * [`build`], [`refit`] and [`validate`]: the tree's constructors, its
//!   refit and its invariant checks.

mod build;
mod check;
pub(crate) mod groups;
mod harmonics;
mod layout;
mod leaf_moments;
mod moment_statistics;
mod moments;
pub(crate) mod morton;
mod node;
mod notes;
mod options;
pub(crate) mod orientation;
mod plane;
mod pool;
mod prefetch;
mod radix;
mod refit;
pub(crate) mod slabs;
mod statistics_pass;
mod validate;

pub use layout::LightTree;
pub(crate) use layout::NO_PLANE;
pub(crate) use node::MAX_CHILDREN;
pub use node::Node;
pub use options::TreeBuilder;
