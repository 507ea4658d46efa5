//! The cut's policy: when summing lights costs less than bounding them,
//! when a small scene is summed whole, when coarse (`f32`) sums and bounds
//! are used, when asking the host stops paying, and what a group's shared
//! cut may cost before its points are shaded one by one.
//!
//! Each number was chosen by measurement on the report's street city (the
//! scenes of `report/`); `docs/tuning.md` records the measurements, and
//! `cargo run --release -p manylights-report -- scaling` (one point at a
//! time) and `-- batch` (the batch call) measure the effect of a change.

use crate::tree::{LightTree, Node};

pub(crate) use crate::shader::{COARSE_LIGHTS_MAX, SUM_LIGHTS_MAX};

/// Nodes of at most this many lights, known visible, are summed light by
/// light when they enter a point's cut instead of bounded (without
/// interpolation across levels, whose blend needs the bounded nodes to
/// ramp through): a node bound costs about as much as summing a few tens
/// of lights, and an exact sum leaves no error to refine later.
pub(crate) const EXACT_NODE_LIGHTS: u32 = 32;

/// Nodes of at most this many lights, known visible, are also summed light
/// by light when they are near the shading point for their size: `n D^2 <=`
/// [`NEAR_NODE_REACH`]` R^2`, `n` the node's lights, `D` the distance from
/// the point to its centroid and `R` its radius (without interpolation
/// across levels, as [`EXACT_NODE_LIGHTS`], nor under a budget, which one
/// such sum could spend at once). A certified cut takes a near node down
/// to its lights anyway: summing it at once skips the bounds and the steps
/// on the way down. The reach shrinks as the lights grow in number (a node
/// of 64 lights within `2.8 R`, of 512 within `R`): the larger the node,
/// the nearer it must be for the cut to need all of its lights.
pub(crate) const NEAR_NODE_LIGHTS: u32 = 512;

/// See [`NEAR_NODE_LIGHTS`].
pub(crate) const NEAR_NODE_REACH: f64 = 512.0;

/// Scenes of at most this many lights (and no coincident ones) are small:
/// a point whose lights are known visible sums them light by light rather
/// than cut them, when the root alone does not meet the threshold (and
/// without interpolation across levels), because summing costs less.
pub(crate) const SMALL_SCENE_LIGHTS: u32 = 256;

/// [`SMALL_SCENE_LIGHTS`] where the lights are summed coarsely (relative
/// targets of at least [`COARSE_TARGET_MIN`], in one call from lights kept
/// side by side): the whole sum then costs less than the cut up to about
/// this many lights at every target.
pub(crate) const SMALL_SCENE_LIGHTS_COARSE: u32 = 1024;

/// Scenes summed whole wherever the point lies, once known visible: the
/// sum of this many lights costs less than setting up the cut and bounding
/// the root.
pub(crate) const TINY_SCENE_LIGHTS: usize = 192;

/// The smallest relative target for which the cut sums lights and bounds
/// children coarsely (in `f32`): `2^-12`, about `2.4e-4`. Below it the
/// coarse rounding would be a sizeable part of the target.
pub(crate) const COARSE_TARGET_MIN: f64 = 1.0 / 4096.0;

/// The share of the target a coarse sum's certified error may be for the
/// sum to be kept, as a divisor of the relative target: `1/32`.
pub(crate) const COARSE_SHARE_DIVISOR: f64 = 32.0;

/// A point's cut whose work reaches `1 /` this share of its scene's lights
/// (a node bound counted as [`NODE_WORK`] lights) stops bounding and sums
/// the lights of every entry left in its list: where the bounds settle
/// little (a tangent plane through the lights, a point inside a cluster at
/// every scale) the walk to the leaves would bound about one node per 14
/// lights on the way, each costing the sums of a dozen lights or more. So
/// a point's cut evaluates every light at most once and at most `N / 32 +
/// 8` node bounds (`N / (2 * 16)`, plus one refinement's children): never
/// much more than the exact sum of its lights. Only without a host's
/// visibility ([`Unoccluded`](crate::Unoccluded)): with one, the lights
/// left would take a shadow ray each, where the cut's classifications
/// settle whole nodes (the occluded city of the report's tests, leaves of
/// four lights, went from under 500 rays a point to 7,941). Half rather than less: the
/// sum takes every light still waiting, where a cut that is only slow (a
/// point inside a cluster) would have settled most of them in nodes.
pub(crate) const REST_SHARE_DIVISOR: u64 = 2;

/// A node bound's cost in lights' sums, for [`REST_SHARE_DIVISOR`]: a
/// Lambert node bound (children bounded side by side, with the slab
/// moments' test) took about as many instructions as the plain `f64` sums
/// of 16 to 25 lights (callgrind, `docs/tuning.md`).
pub(crate) const NODE_WORK: u64 = 16;

/// Scenes of fewer lights never stop bounding for [`REST_SHARE_DIVISOR`]:
/// summing them costs little either way.
pub(crate) const REST_MIN_LIGHTS: u64 = 4096;

/// Coarse (`f32`) sums of lights a point's cut may fail to keep in a row
/// before it sums lights in plain `f64` (with its rounding bound) without
/// trying the coarse sum first: where the tangent plane runs through a
/// layer of lights, every light's `f32` height is mostly rounding and
/// every coarse sum is thrown away.
pub(crate) const COARSE_MISSES_MAX: u32 = 4;

/// Node evaluations after which a cut bounds children in `f64` only. The
/// single-precision bounds carry a rounding allowance of a few dozen `f32`
/// ulps of `I kd / D^2`, while a node seen at a grazing angle (the lights
/// of a whole city from a point on the ground beyond its edge) is worth
/// the cosine of that angle times as much: there the allowance can stay
/// above a relative target until the nodes are very small, and the cut
/// would refine far deeper than the `f64` bounds need. Ordinary cuts stop
/// long before this many evaluations; the entries already bounded keep
/// their certified coarse intervals.
pub(crate) const COARSE_NODES_MAX: u32 = 512;

/// Partial answers for small nodes before the cut may judge classification
/// useless (see [`Cut::gave_up_classifying`](super::Cut)).
pub(crate) const GIVE_UP_AFTER: u32 = 32;

/// Fewer useful (visible or occluded) answers than one per this many partial
/// answers for small nodes and the cut stops asking.
pub(crate) const GIVE_UP_RATIO: u32 = 8;

/// Nodes of at most this many lights are small: after a partial answer for
/// one, its few lights are soon asked one by one, so the classification did
/// not pay.
pub(crate) const SMALL_NODE_LIGHTS: u32 = 16;

/// Most lights asked about in one call of
/// [`Visibility::visible_lights`](crate::Visibility::visible_lights): where
/// coarse sums are used, a whole leaf of the default builder (at most 32
/// lights); elsewhere the lights of one exact evaluation, at most
/// [`SUM_LIGHTS_MAX`].
pub(crate) const ASK_MAX: usize = 32;

/// Entries a point sums over a shared cut in the time of one shared node
/// bound: the unit in which a group's shared cut and its points' sums are
/// weighed against the points shaded alone. Instruction counts of the two
/// set it (`docs/tuning.md`); `cargo run --release -p manylights-report --
/// batch` measures the batch call.
pub(crate) const ENTRIES_PER_BOUND: u64 = 32;

/// Most entries in a shared cut: the points' lane sums are certified up to
/// `2^16` terms.
pub(crate) const MAX_SHARED_ENTRIES: usize = 1 << 15;

/// Whether a tree may be a small scene (see [`SMALL_SCENE_LIGHTS`] and
/// [`SMALL_SCENE_LIGHTS_COARSE`]): at most the larger number of lights,
/// none of them coincident (a leaf of coincident lights is one light to
/// the cut, and stays so).
pub(crate) fn is_small_scene(tree: &LightTree) -> bool {
    tree.nodes.first().is_some_and(|root| {
        root.light_count <= SMALL_SCENE_LIGHTS_COARSE
            && !tree
                .nodes
                .iter()
                .any(|n| n.radius == 0.0 && n.light_count > 1)
    })
}

/// Whether a visible node of `count` lights, within `radius` of its
/// centroid at squared distance `distance_sq` from the point, is near
/// enough to be summed light by light (see [`NEAR_NODE_LIGHTS`]):
/// `n D^2 <= NEAR_NODE_REACH R^2` in `f64`, where neither side can overflow
/// for finite `f32` inputs.
#[inline(always)]
pub(crate) fn is_near(node: &Node, distance_sq: f64) -> bool {
    let r = f64::from(node.radius);
    f64::from(node.light_count) * distance_sq <= NEAR_NODE_REACH * r * r
}

/// A group's shared cut gives up (its points are shaded one by one) once
/// this many of its nodes are cut by the tangent plane at the group's
/// centre with some of their slab bins wholly above or below it, where the
/// shader narrows point bounds from slab moments: a point alone settles
/// such nodes at the level their distance allows, the shared cut (whose
/// group bounds do not read the bins) would refine them to the leaves.
/// Few enough to stop before the shared cut has spent much; more than one,
/// so that a group barely touching a layer still shares.
pub(crate) const LAYER_NODES_MAX: u32 = 4;
