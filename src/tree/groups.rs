//! The children of every node side by side: structure-of-arrays blocks of
//! `f32`, so that a node's children are bounded together from a few
//! contiguous vector loads instead of gathered field by field from their
//! node records.
//!
//! The children of a node with at most four children form a block of
//! [`FIELDS`] rows of four lanes (one SSE vector of `f32` per row), those
//! of a node with five to eight children a block of rows of eight lanes
//! (one AVX2 vector): row `f` holds field `f` of every child, lane `i`
//! being child `first_child + i`; lanes past the children repeat the last
//! child (finite values, ignored by the readers). A table gives where each
//! node's block starts.
//!
//! What a lane holds is taken from the node's own statistics (see
//! [`Node`]) without further rounding, except for its box, which is stored
//! relative to its centroid and rounded outward, so that the stored box
//! still contains every member.

use super::layout::{LightTree, Node};

/// Rows of a block, one per field.
pub(crate) const FIELDS: usize = 46;

/// Row of the centroid's `x` (`y` and `z` follow).
pub(crate) const CENTROID: usize = 0;
/// Row of the radius.
pub(crate) const RADIUS: usize = 3;
/// Rows of the box's lowest corner relative to the centroid, `x, y, z`,
/// rounded down.
pub(crate) const BOX_LOW: usize = 4;
/// Rows of the box's highest corner relative to the centroid, rounded up.
pub(crate) const BOX_HIGH: usize = 7;
/// Rows of the channel offsets `o_k`: channel `k`, axis `a` at
/// `OFFSETS + 3 k + a`.
pub(crate) const OFFSETS: usize = 10;
/// Rows of the second moments `S_k`: channel `k`, entry `e` (`[xx, yy, zz,
/// xy, xz, yz]`) at `COVARIANCES + 6 k + e`.
pub(crate) const COVARIANCES: usize = 19;
/// Rows of the harmonic norms: channel `k`, degree `3 + d` at
/// `HARMONICS + 3 k + d`.
pub(crate) const HARMONICS: usize = 37;

/// No block: a leaf's entry in the table.
const NO_BLOCK: u32 = u32::MAX;

/// The blocks of every node's children (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct NodeGroups {
    rows: Vec<f32>,
    /// Per node, where its children's block starts in `rows`, or
    /// [`NO_BLOCK`].
    at: Vec<u32>,
}

/// A block of `N` lanes: `FIELDS` rows.
pub(crate) type Block<const N: usize> = [[f32; N]; FIELDS];

/// The children of one node.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Group<'a> {
    /// At most four children.
    Four(&'a Block<4>),
    /// Five to eight children.
    Eight(&'a Block<8>),
}

/// Lanes of the block of a node of `count` children.
#[inline(always)]
fn lanes_for(count: usize) -> usize {
    if count <= 4 { 4 } else { 8 }
}

impl NodeGroups {
    /// The blocks of `nodes` (a built tree's, root first). Trees too large
    /// for the table's offsets get none (their children are bounded one
    /// by one).
    pub(crate) fn new(nodes: &[Node]) -> Self {
        let mut at = vec![NO_BLOCK; nodes.len()];
        let size: usize = nodes
            .iter()
            .filter(|n| !n.is_leaf())
            .map(|n| lanes_for(n.children().len()) * FIELDS)
            .sum();
        if size >= NO_BLOCK as usize {
            return Self::default();
        }
        let mut rows = vec![0.0f32; size];
        let mut start = 0;
        for (index, parent) in nodes.iter().enumerate() {
            if parent.is_leaf() {
                continue;
            }
            let children = &nodes[parent.children()];
            let lanes = lanes_for(children.len());
            at[index] = start as u32;
            for lane in 0..lanes {
                let child = &children[lane.min(children.len() - 1)];
                for (field, value) in lane_values(child).into_iter().enumerate() {
                    rows[start + field * lanes + lane] = value;
                }
            }
            start += lanes * FIELDS;
        }
        Self { rows, at }
    }

    /// The children of node `index`, or `None` for a leaf (or a tree too
    /// large for the table).
    #[inline(always)]
    pub(crate) fn children(&self, index: usize, parent: &Node) -> Option<Group<'_>> {
        let start = *self.at.get(index)?;
        if start == NO_BLOCK {
            return None;
        }
        let start = start as usize;
        if parent.children().len() <= 4 {
            let rows = self.rows.get(start..start + 4 * FIELDS)?;
            let (block, _) = rows.as_chunks::<4>();
            Some(Group::Four(block.try_into().ok()?))
        } else {
            let rows = self.rows.get(start..start + 8 * FIELDS)?;
            let (block, _) = rows.as_chunks::<8>();
            Some(Group::Eight(block.try_into().ok()?))
        }
    }

    /// Heap memory held, in bytes.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.rows.capacity() * size_of::<f32>() + self.at.capacity() * size_of::<u32>()
    }

    /// The first node whose children's block does not hold exactly what
    /// [`NodeGroups::new`] makes of `nodes`.
    pub(crate) fn first_mismatch(&self, nodes: &[Node]) -> Option<usize> {
        let fresh = Self::new(nodes);
        if self.at != fresh.at || self.rows.len() != fresh.rows.len() {
            return Some(0);
        }
        let differs = self
            .rows
            .iter()
            .zip(&fresh.rows)
            .position(|(a, b)| a.to_bits() != b.to_bits())?;
        // The node whose block starts last at or before the difference.
        self.at
            .iter()
            .enumerate()
            .filter(|&(_, &a)| a != NO_BLOCK && a as usize <= differs)
            .max_by_key(|&(_, &a)| a)
            .map(|(i, _)| i)
    }
}

/// What lane `child` holds, field by field.
fn lane_values(child: &Node) -> [f32; FIELDS] {
    let mut v = [0.0f32; FIELDS];
    let c = child.centroid;
    v[CENTROID..CENTROID + 3].copy_from_slice(&c.to_array());
    v[RADIUS] = child.radius;
    for axis in 0..3 {
        let (low, high) = relative_extent(child.aabb.min[axis], child.aabb.max[axis], c[axis]);
        v[BOX_LOW + axis] = low;
        v[BOX_HIGH + axis] = high;
    }
    for k in 0..3 {
        v[OFFSETS + 3 * k..OFFSETS + 3 * k + 3]
            .copy_from_slice(&child.channel_offsets[k].to_array());
        v[COVARIANCES + 6 * k..COVARIANCES + 6 * k + 6]
            .copy_from_slice(&child.channel_covariances[k]);
        for d in 0..3 {
            v[HARMONICS + 3 * k + d] = child.harmonic_norms[d][k];
        }
    }
    v
}

/// `[min - c, max - c]` rounded outward to `f32`: the difference is taken
/// in `f64` (within `2^-53` of its value), moved outward by `2^-50` of its
/// magnitude (more than that rounding), and rounded outward to `f32`.
fn relative_extent(min: f32, max: f32, c: f32) -> (f32, f32) {
    const MARGIN: f64 = 1.0 / (1u64 << 50) as f64;
    let low = f64::from(min) - f64::from(c);
    let high = f64::from(max) - f64::from(c);
    let low = -crate::numeric::round_up_f32(-(low - low.abs() * MARGIN));
    let high = crate::numeric::round_up_f32(high + high.abs() * MARGIN);
    (low, high)
}

impl LightTree {
    /// Recomputes the node groups from the nodes (after a build or refit).
    pub(crate) fn fill_groups(&mut self) {
        self.groups = NodeGroups::new(&self.nodes);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::PointLight;

    /// Every lane of every group holds its child's values, and the box
    /// stored relative to the centroid contains every member.
    #[test]
    fn groups_hold_their_childrens_values() {
        let mut state = 5u64;
        let mut u = || crate::testing::uniform(&mut state);
        // A flat scene (nodes of four children) and a solid one (eight).
        for depth in [1e-3, 30.0] {
            let lights: Vec<PointLight> = (0..3000)
                .map(|_| {
                    let p = Vec3::new(u() * 900.0 + 1e4, u() * 30.0 - 15.0, u() * depth);
                    PointLight::new(p, Vec3::new(u(), u(), u() * 0.1))
                })
                .collect();
            let tree = LightTree::build(&lights).unwrap();
            let mut checked = [0; 2];
            for (index, parent) in tree.nodes().iter().enumerate() {
                let Some(group) = tree.groups.children(index, parent) else {
                    assert!(parent.is_leaf());
                    continue;
                };
                assert_eq!(
                    matches!(group, Group::Four(_)),
                    parent.children().len() <= 4
                );
                for (i, child) in tree.nodes()[parent.children()].iter().enumerate() {
                    let lane = |field: usize| match group {
                        Group::Four(b) => b[field][i],
                        Group::Eight(b) => b[field][i],
                    };
                    assert_eq!(lane(RADIUS), child.radius);
                    assert_eq!(lane(CENTROID + 2), child.centroid.z);
                    assert_eq!(lane(COVARIANCES + 6 + 4), child.channel_covariances[1][4]);
                    assert_eq!(lane(HARMONICS + 3 * 2 + 1), child.harmonic_norms[1][2]);
                    assert_eq!(lane(OFFSETS + 3 + 2), child.channel_offsets[1].z);
                    for light in &tree.lights()[child.lights()] {
                        for axis in 0..3 {
                            let rel =
                                f64::from(light.position[axis]) - f64::from(child.centroid[axis]);
                            assert!(f64::from(lane(BOX_LOW + axis)) <= rel);
                            assert!(f64::from(lane(BOX_HIGH + axis)) >= rel);
                        }
                    }
                    checked[usize::from(matches!(group, Group::Eight(..)))] += 1;
                }
            }
            assert!(checked.iter().sum::<usize>() > 100, "{checked:?}");
            assert_eq!(tree.groups.first_mismatch(tree.nodes()), None);
        }
    }
}
