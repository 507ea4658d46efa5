//! The children of every node side by side: structure-of-arrays blocks,
//! so that a node's children are bounded together from a few contiguous
//! vector loads instead of gathered field by field from their node records.
//!
//! The children of a node with at most four children form a [`Block`] of
//! four lanes (one SSE vector of `f32` per row), those of a node with five
//! to eight children a block of eight lanes (one AVX2 vector): row `f`
//! holds field `f` of every child, lane `i` being child `first_child + i`;
//! lanes past the children repeat the last child (finite values, ignored by
//! the readers). A table gives each node's block.
//!
//! What a lane holds is taken from the node's own statistics (see
//! [`Node`]) without further rounding, except for two fields: its box,
//! stored relative to its centroid and rounded outward, so that it still
//! contains every member; and its harmonic norms, stored as half-precision
//! numbers rounded upward (see [`half_up`]), so that they still bound the
//! node's multipoles.

use super::layout::{LightTree, Node};
use super::pool::Pool;

/// `f32` rows of a block, one per field.
pub(crate) const ROWS: usize = 37;
/// Half-precision rows of a block: the harmonic norms, channel `k`,
/// degree `3 + d` at `3 k + d`.
pub(crate) const NORMS: usize = 9;

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

/// A node's children side by side, `N` lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Block<const N: usize> {
    /// The `f32` fields ([`ROWS`] of them).
    pub(crate) rows: [[f32; N]; ROWS],
    /// The harmonic norms, half-precision bits rounded upward ([`NORMS`]
    /// of them).
    pub(crate) norms: [[u16; N]; NORMS],
}

/// The blocks of every node's children (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct NodeGroups {
    fours: Vec<Block<4>>,
    eights: Vec<Block<8>>,
    /// Per node, its children's block: an index into `fours`, or into
    /// `eights` with [`EIGHT`] set; [`NO_BLOCK`] for a leaf.
    at: Vec<u32>,
}

/// Blocks are filled on the build's pool from this many on: a block takes
/// about a tenth of a microsecond (its lanes' statistics gathered and
/// rounded), so a few thousand of them outweigh waking the pool's threads
/// (up to a millisecond or more on a busy machine); the street city has
/// 2,000 blocks at 10^5 lights and 22,000 at 10^6. Lower in the tests, so
/// that their parallel builds take this path.
const PARALLEL_BLOCKS: usize = if cfg!(test) { 64 } else { 8192 };

/// No block: a leaf's entry in the table.
const NO_BLOCK: u32 = u32::MAX;
/// The table's flag for a block of eight lanes.
const EIGHT: u32 = 1 << 31;

/// The children of one node.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Group<'a> {
    /// At most four children.
    Four(&'a Block<4>),
    /// Five to eight children.
    Eight(&'a Block<8>),
}

impl Group<'_> {
    /// The block's address range.
    #[inline(always)]
    pub(crate) fn bytes(&self) -> core::ops::Range<usize> {
        let (start, len) = match self {
            Group::Four(b) => (core::ptr::from_ref(*b) as usize, size_of::<Block<4>>()),
            Group::Eight(b) => (core::ptr::from_ref(*b) as usize, size_of::<Block<8>>()),
        };
        start..start + len
    }
}

impl<const N: usize> Block<N> {
    /// The block of `children` (at most `N`, at least one).
    fn of(children: &[Node]) -> Self {
        let mut block = Self {
            rows: [[0.0; N]; ROWS],
            norms: [[0; N]; NORMS],
        };
        for lane in 0..N {
            let child = &children[lane.min(children.len() - 1)];
            let (rows, norms) = lane_values(child);
            for (row, value) in block.rows.iter_mut().zip(rows) {
                row[lane] = value;
            }
            for (row, value) in block.norms.iter_mut().zip(norms) {
                row[lane] = value;
            }
        }
        block
    }
}

impl NodeGroups {
    /// The blocks of `nodes` (a built tree's, root first).
    pub(crate) fn new(nodes: &[Node]) -> Self {
        Self::new_on(nodes, Pool::ONE)
    }

    /// [`NodeGroups::new`], the blocks filled on `pool` (the same blocks).
    pub(crate) fn new_on(nodes: &[Node], pool: Pool) -> Self {
        let mut groups = Self::default();
        groups.refill(nodes, pool);
        groups
    }

    /// Makes these the blocks of `nodes`, filled on `pool`, in the memory
    /// they hold (the same blocks as [`NodeGroups::new_on`]).
    pub(crate) fn refill(&mut self, nodes: &[Node], pool: Pool) {
        let at = &mut self.at;
        at.clear();
        at.resize(nodes.len(), NO_BLOCK);
        let (mut fours, mut eights) = (Vec::new(), Vec::new());
        for (index, parent) in nodes.iter().enumerate() {
            if parent.is_leaf() {
                continue;
            }
            // Node counts fit in `u32`, and so do block counts (fewer).
            at[index] = if parent.child_count <= 4 {
                fours.push(index);
                (fours.len() - 1) as u32
            } else {
                eights.push(index);
                (eights.len() - 1) as u32 | EIGHT
            };
        }
        let block = |&index: &usize| &nodes[nodes[index].children()];
        let on = |blocks: usize| {
            if blocks >= PARALLEL_BLOCKS {
                pool
            } else {
                Pool::ONE
            }
        };
        on(fours.len()).map_into(&fours, &mut self.fours, |i| Block::of(block(i)));
        on(eights.len()).map_into(&eights, &mut self.eights, |i| Block::of(block(i)));
    }

    /// The children of node `index`, or `None` for a leaf.
    #[inline(always)]
    pub(crate) fn children(&self, index: usize) -> Option<Group<'_>> {
        let at = *self.at.get(index)?;
        if at == NO_BLOCK {
            None
        } else if at & EIGHT == 0 {
            self.fours.get(at as usize).map(Group::Four)
        } else {
            self.eights.get((at & !EIGHT) as usize).map(Group::Eight)
        }
    }

    /// Heap memory held, in bytes.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.fours.capacity() * size_of::<Block<4>>()
            + self.eights.capacity() * size_of::<Block<8>>()
            + self.at.capacity() * size_of::<u32>()
    }

    /// The first node whose children's block does not hold exactly what
    /// [`NodeGroups::new`] makes of `nodes`.
    pub(crate) fn first_mismatch(&self, nodes: &[Node]) -> Option<usize> {
        let fresh = Self::new(nodes);
        if self.at != fresh.at {
            return Some(
                self.at
                    .iter()
                    .zip(&fresh.at)
                    .position(|(a, b)| a != b)
                    .unwrap_or(0),
            );
        }
        let same = |a: &Group<'_>, b: &Group<'_>| match (a, b) {
            (Group::Four(a), Group::Four(b)) => bits_equal(a, b),
            (Group::Eight(a), Group::Eight(b)) => bits_equal(a, b),
            _ => false,
        };
        (0..nodes.len()).find(|&i| match (self.children(i), fresh.children(i)) {
            (Some(a), Some(b)) => !same(&a, &b),
            (None, None) => false,
            _ => true,
        })
    }
}

/// Whether two blocks hold the same bits.
fn bits_equal<const N: usize>(a: &Block<N>, b: &Block<N>) -> bool {
    a.norms == b.norms
        && a.rows
            .iter()
            .flatten()
            .zip(b.rows.iter().flatten())
            .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The half-precision number at or above `q` (non-negative and finite):
/// 0 stays 0, a positive `q` below the smallest normal half-precision
/// number (`2^-14`) becomes that number, and a `q` above the largest
/// (`65504`) becomes infinity, which no bound uses (harmonic norms lie in
/// `[0, 1]` up to their rounding). Only normal numbers and 0 are stored,
/// so that [`widen_half`] is a shift and an add.
pub(crate) fn half_up(q: f32) -> u16 {
    const MIN_NORMAL: f32 = 6.103_515_6e-5; // 2^-14
    if !(q > 0.0) {
        return 0;
    }
    if q > 65504.0 {
        return 0x7c00;
    }
    let q = q.max(MIN_NORMAL);
    let bits = q.to_bits();
    // Exponent rebiased from 127 to 15, mantissa cut from 23 to 10 bits,
    // one step up where bits were cut (a carry into the exponent is the
    // next power of two, still correct).
    let exponent = (bits >> 23) - 112;
    let mantissa = (bits >> 13) & 0x3ff;
    let cut = bits & 0x1fff;
    let half = (exponent << 10 | mantissa) + u32::from(cut != 0);
    half as u16
}

/// The `f32` value of half-precision bits from [`half_up`] (0 or normal):
/// exact.
#[inline(always)]
pub(crate) fn widen_half(h: u16) -> f32 {
    let h = u32::from(h);
    // The exponent's bias 15 raised to 127: (127 - 15) << 23.
    let bits = if h == 0 { 0 } else { (h << 13) + (112 << 23) };
    f32::from_bits(bits)
}

/// What lane `child` holds, field by field: its `f32` rows and its
/// harmonic norms' half-precision bits.
fn lane_values(child: &Node) -> ([f32; ROWS], [u16; NORMS]) {
    let mut v = [0.0f32; ROWS];
    let c = child.centroid;
    v[CENTROID..CENTROID + 3].copy_from_slice(&c.to_array());
    v[RADIUS] = child.radius;
    for axis in 0..3 {
        let (low, high) = relative_extent(child.aabb.min[axis], child.aabb.max[axis], c[axis]);
        v[BOX_LOW + axis] = low;
        v[BOX_HIGH + axis] = high;
    }
    let mut norms = [0u16; NORMS];
    for k in 0..3 {
        v[OFFSETS + 3 * k..OFFSETS + 3 * k + 3]
            .copy_from_slice(&child.channel_offsets[k].to_array());
        v[COVARIANCES + 6 * k..COVARIANCES + 6 * k + 6]
            .copy_from_slice(&child.channel_covariances[k]);
        for d in 0..3 {
            norms[3 * k + d] = half_up(child.harmonic_norms[d][k]);
        }
    }
    (v, norms)
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
    /// Recomputes the node groups from the nodes (after a build or refit),
    /// on `pool`.
    pub(crate) fn fill_groups(&mut self, pool: Pool) {
        self.groups.refill(&self.nodes, pool);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::PointLight;

    /// Every lane of every group holds its child's values, the box stored
    /// relative to the centroid contains every member, and the norms are
    /// rounded up to half precision.
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
                let Some(group) = tree.groups.children(index) else {
                    assert!(parent.is_leaf());
                    continue;
                };
                assert_eq!(
                    matches!(group, Group::Four(_)),
                    parent.children().len() <= 4
                );
                for (i, child) in tree.nodes()[parent.children()].iter().enumerate() {
                    let (lane, norm) = match group {
                        Group::Four(b) => (b.rows.map(|r| r[i]), b.norms.map(|r| r[i])),
                        Group::Eight(b) => (b.rows.map(|r| r[i]), b.norms.map(|r| r[i])),
                    };
                    assert_eq!(lane[RADIUS], child.radius);
                    assert_eq!(lane[CENTROID + 2], child.centroid.z);
                    assert_eq!(lane[COVARIANCES + 6 + 4], child.channel_covariances[1][4]);
                    assert_eq!(lane[OFFSETS + 3 + 2], child.channel_offsets[1].z);
                    let q = child.harmonic_norms[1][2];
                    let stored = widen_half(norm[3 * 2 + 1]);
                    assert!(stored >= q && stored <= q.max(6.2e-5) * (1.0 + 1.0 / 1024.0));
                    for light in &tree.lights()[child.lights()] {
                        for axis in 0..3 {
                            let rel =
                                f64::from(light.position[axis]) - f64::from(child.centroid[axis]);
                            assert!(f64::from(lane[BOX_LOW + axis]) <= rel);
                            assert!(f64::from(lane[BOX_HIGH + axis]) >= rel);
                        }
                    }
                    checked[usize::from(matches!(group, Group::Eight(..)))] += 1;
                }
            }
            assert!(checked.iter().sum::<usize>() > 100, "{checked:?}");
            assert_eq!(tree.groups.first_mismatch(tree.nodes()), None);
        }
    }

    /// `half_up` rounds every `f32` in `[0, 65504]` up to a half-precision
    /// number (0 and normal ones only), which `widen_half` reads back
    /// exactly; no half-precision number lies strictly between.
    #[test]
    fn halves_round_up() {
        let mut state = 9u64;
        for i in 0..200_000 {
            let q = if i < 1000 {
                // Every half-precision value's neighbourhood near 1.
                f32::from_bits(0x3f80_0000 - 500 * 8192 + i * 8192 + (i % 3))
            } else {
                let e = crate::testing::uniform(&mut state) * 40.0 - 30.0;
                2f32.powf(e)
            };
            let h = half_up(q);
            let back = widen_half(h);
            assert!(back >= q, "{q} -> {back}");
            assert!(h & 0x7c00 != 0 || h == 0, "{q}: subnormal {h:#x}");
            if h > 0x0400 {
                assert!(
                    widen_half(h - 1) < q,
                    "{q} -> {back}, one below {}",
                    widen_half(h - 1)
                );
            }
        }
        assert_eq!(half_up(0.0), 0);
        assert_eq!(widen_half(half_up(1.0)), 1.0);
        assert_eq!(widen_half(half_up(1e-9)), 6.103_515_6e-5);
    }
}
