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
//! Children whose lights all have one colour form a one-colour block
//! ([`MonoBlock`]): it stores channel 0's moments only, and per lane and
//! per other channel `k` the spread of the members' colour, an upper bound
//! on `max_i r_i / min_i r_i` with `r_i = I_k,i / I_0,i` (see
//! [`colour_spreads`]). That is half the bytes, and a third of the
//! per-channel work for its readers, which bound channel `k` from channel
//! 0 (the argument is in `lambert::group`'s docs). White or grey lights
//! have a spread of exactly 1, and their readers' results are the very
//! bits they would have computed from three channels (the moments are
//! computed channel by channel with the same operations, so equal
//! intensities give equal moments); lights of one colour scaled by
//! different factors have a spread within a few `f32` roundings of 1.
//!
//! What a lane holds is taken from the node's own statistics (see
//! [`Node`]) without further rounding, except for two fields: its box,
//! stored relative to its centroid and rounded outward, so that it still
//! contains every member; and its harmonic norms, stored as half-precision
//! numbers rounded upward (see [`half_up`]), so that they still bound the
//! node's multipoles.

use super::node::Node;
use super::notes::{Notes, RatioRange, Ratios};
use super::pool::Pool;
use crate::PointLight;

/// `f32` rows of a block, one per field.
pub(crate) const ROWS: usize = OFFSETS + 9 * 3;
/// Half-precision rows of a block: the harmonic norms, channel `k`,
/// degree `3 + d` at `3 k + d`.
pub(crate) const NORMS: usize = 3 * 3;
/// `f32` rows of a one-colour block: channel 0's offsets and second
/// moments, then the colour's spreads of channels 1 and 2 (see
/// [`Block::spread_row`]).
pub(crate) const MONO_ROWS: usize = OFFSETS + 9 + 2;
/// Half-precision rows of a one-colour block: channel 0's harmonic norms.
pub(crate) const MONO_NORMS: usize = 3;
/// Largest colour spread of a one-colour block's lanes: children whose
/// lights' colours differ more are kept in blocks of three channels, whose
/// bounds are tighter for them. Lights of one colour scaled by different
/// factors in `f32` differ by a few roundings, about `2^-22`.
const MONO_SPREAD_MAX: f64 = 1.0 + 1.0 / 4096.0;

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
/// Rows of the second moments `S_k` in a block of three channels:
/// channel `k`, entry `e` (`[xx, yy, zz, xy, xz, yz]`) at `COVARIANCES + 6
/// k + e` (see [`Block::covariance_row`]).
pub(crate) const COVARIANCES: usize = OFFSETS + 9;

/// A node's children side by side, `N` lanes, with `R` rows of `f32`
/// fields and `M` of half-precision norms: three channels' moments
/// ([`ROWS`], [`NORMS`]) or, in a [`MonoBlock`], one's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Block<const N: usize, const R: usize = ROWS, const M: usize = NORMS> {
    /// The `f32` fields.
    pub(crate) rows: [[f32; N]; R],
    /// The harmonic norms, half-precision bits rounded upward.
    pub(crate) norms: [[u16; N]; M],
}

/// A block whose lanes' lights have one colour: channel 0's moments and
/// the colour's spreads (see the module docs).
pub(crate) type MonoBlock<const N: usize> = Block<N, MONO_ROWS, MONO_NORMS>;

impl<const N: usize, const R: usize, const M: usize> Block<N, R, M> {
    /// The channels whose moments are stored: 3, or 1 in a one-colour
    /// block.
    pub(crate) const CHANNELS: usize = M / 3;

    /// Row of channel `k`'s offset along axis `a` (`k` below
    /// [`Self::CHANNELS`]).
    #[inline(always)]
    pub(crate) const fn offset_row(k: usize, a: usize) -> usize {
        OFFSETS + 3 * k + a
    }

    /// Row of channel `k`'s second moment `e` (`k` below
    /// [`Self::CHANNELS`]).
    #[inline(always)]
    pub(crate) const fn covariance_row(k: usize, e: usize) -> usize {
        OFFSETS + 3 * Self::CHANNELS + 6 * k + e
    }

    /// Row of the colour's spread of channel `k` (1 or 2) in a one-colour
    /// block: at least `max_i r_i / min_i r_i`, `r_i = I_k,i / I_0,i` over
    /// the lane's lights with some intensity, and exactly 1 where every
    /// such `r_i` is 1 or where channel `k` is 0 throughout.
    #[inline(always)]
    pub(crate) const fn spread_row(k: usize) -> usize {
        OFFSETS + 9 * Self::CHANNELS + k - 1
    }
}

/// The blocks of every node's children (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct NodeGroups {
    fours: Vec<Block<4>>,
    eights: Vec<Block<8>>,
    mono_fours: Vec<MonoBlock<4>>,
    mono_eights: Vec<MonoBlock<8>>,
    /// Per node, its children's block: an index into `fours`, into
    /// `eights` with [`EIGHT`] set, into `mono_fours` with [`MONO`] set, or
    /// into `mono_eights` with both; [`NO_BLOCK`] for a leaf.
    at: Vec<u32>,
}

/// Blocks are filled on the build's pool from this many on: a block is
/// cheap (its lanes' statistics gathered and rounded), and only some
/// thousands of them outweigh waking the pool's threads, which can be slow
/// on a busy machine. `cargo run --release -p manylights-report -- bounds`
/// times builds on the pool; `docs/tuning.md` has the figures behind the
/// value. Lower in the tests, so that their parallel builds take this path.
const PARALLEL_BLOCKS: usize = if cfg!(test) { 64 } else { 8192 };

/// No block: a leaf's entry in the table.
const NO_BLOCK: u32 = u32::MAX;
/// The table's flag for a block of eight lanes.
const EIGHT: u32 = 1 << 31;
/// The table's flag for a one-colour block.
const MONO: u32 = 1 << 30;

/// The children of one node.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Group<'a> {
    /// At most four children.
    Four(&'a Block<4>),
    /// Five to eight children.
    Eight(&'a Block<8>),
    /// At most four children of one colour.
    MonoFour(&'a MonoBlock<4>),
    /// Five to eight children of one colour.
    MonoEight(&'a MonoBlock<8>),
}

/// `$body` with `$block` bound to the block of `$group`, whatever its kind.
macro_rules! with_block {
    ($group:expr, $block:ident => $body:expr) => {
        match $group {
            $crate::tree::groups::Group::Four($block) => $body,
            $crate::tree::groups::Group::Eight($block) => $body,
            $crate::tree::groups::Group::MonoFour($block) => $body,
            $crate::tree::groups::Group::MonoEight($block) => $body,
        }
    };
}
pub(crate) use with_block;

impl<const N: usize, const R: usize, const M: usize> Block<N, R, M> {
    /// The block of `children` (at most `N`, at least one), whose colour
    /// spreads are `spreads` (read by one-colour blocks only).
    pub(crate) fn of(children: &[Node], spreads: &[[f32; 2]]) -> Self {
        let mut block = Self {
            rows: [[0.0; N]; R],
            norms: [[0; N]; M],
        };
        // A one-colour block keeps channel 0's rows (the same fields up to
        // its offsets, then its second moments), then the spreads.
        let moments_end = Self::covariance_row(Self::CHANNELS - 1, 6);
        for lane in 0..N {
            let last = lane.min(children.len() - 1);
            let (rows, norms) = lane_values(&children[last]);
            for (i, row) in block.rows.iter_mut().enumerate() {
                row[lane] = if i < Self::covariance_row(0, 0) {
                    rows[i]
                } else if i < moments_end {
                    rows[i - Self::covariance_row(0, 0) + COVARIANCES]
                } else {
                    spreads[last][i - moments_end]
                };
            }
            for (row, value) in block.norms.iter_mut().zip(norms) {
                row[lane] = value;
            }
        }
        block
    }
}

/// Per node, the spread of its lights' colour in channels 1 and 2: an
/// upper bound, rounded up to `f32`, on `max_i r_i / min_i r_i` with `r_i =
/// I_k,i / I_0,i` over the members with some intensity; exactly 1 where
/// every `r_i` is 1 (white or grey lights) or where channel `k` is 0 in
/// every member; infinity where a member has some intensity in channel `k`
/// but none in channel 0, or none in channel `k` while another has some
/// (members with nothing in either are passed over: they add nothing to
/// either sum). Spreads above [`MONO_SPREAD_MAX`] are only known to be
/// above it: a leaf's lights are read until its spread passes it. Computed
/// from the leaves up (children follow their parents).
///
/// A channel's Lambert sum over a node of spread `s` is within a factor
/// `s` of channel 0's scaled to channel `k`'s total: every term is at
/// least 0, so `S_k = sum r_i I_0,i f_i` lies in `[r_min S_0, r_max S_0]`
/// and `I_k = sum r_i I_0,i` in `[r_min I_0, r_max I_0]`, whence `S_k / I_k`
/// lies within `[S_0 / I_0 / s, s S_0 / I_0]`.
pub(crate) fn colour_spreads(nodes: &[Node], lights: &[PointLight]) -> Vec<[f32; 2]> {
    let mut notes = vec![Notes::NONE; nodes.len()];
    for (node, notes) in nodes.iter().zip(&mut notes) {
        if node.is_leaf() {
            notes.ratios = leaf_ratios(lights.get(node.lights()).unwrap_or(&[]));
        }
    }
    spreads_from_leaves(nodes, &mut notes)
}

/// Widens `range` to hold `[low, high]`: one minimum and one maximum
/// instruction, a NaN end failing its comparison and passed over.
#[allow(clippy::manual_clamp)]
#[inline(always)]
fn widen(range: &mut RatioRange, RatioRange { low, high }: RatioRange) {
    range.low = if low < range.low { low } else { range.low };
    range.high = if high > range.high { high } else { range.high };
}

/// The [`Ratios`] of a leaf's `lights`, read only until its spread passes
/// [`MONO_SPREAD_MAX`].
#[inline(always)]
pub(super) fn leaf_ratios(lights: &[PointLight]) -> Ratios {
    let mut range = [RatioRange::EMPTY; 2];
    // Without branches: a member with nothing in channel 0 has a ratio of
    // infinity where it has something in channel k, and NaN (0 / 0) where
    // it has nothing there either, adding 0 to both channels' sums.
    for light in lights {
        let i = light.intensity.as_dvec3();
        for (k, range) in range.iter_mut().enumerate() {
            let r = i[k + 1] / i.x;
            widen(range, RatioRange { low: r, high: r });
        }
        // A leaf of many colours is settled (and so are its ancestors):
        // the rest of its lights are not read.
        if range
            .iter()
            .any(|&RatioRange { low, high }| high > low * MONO_SPREAD_MAX)
        {
            break;
        }
    }
    range
}

/// [`colour_spreads`] from `notes` (one per node), which hold every
/// leaf's [`leaf_ratios`]: every other node's ratios from its children's
/// (which follow it), from the last node up, written into its notes.
fn spreads_from_leaves(nodes: &[Node], notes: &mut [Notes]) -> Vec<[f32; 2]> {
    for index in (0..nodes.len()).rev() {
        let node = &nodes[index];
        if node.is_leaf() {
            continue;
        }
        let mut range = [RatioRange::EMPTY; 2];
        for child in node.children() {
            for (range, &child_range) in range.iter_mut().zip(&notes[child].ratios) {
                widen(range, child_range);
            }
        }
        notes[index].ratios = range;
    }
    notes
        .iter()
        .map(|notes| {
            notes.ratios.map(|RatioRange { low, high }| {
                if high == 0.0 || (low == 1.0 && high == 1.0) {
                    1.0
                } else if low > 0.0 && high < f64::INFINITY {
                    // Both ratios within 2^-53 of their values, and the
                    // quotient's own rounding: 2^-50 covers them.
                    crate::numeric::round_up_f32(high / low * (1.0 + 1.0 / (1u64 << 50) as f64))
                } else {
                    f32::INFINITY
                }
            })
        })
        .collect()
}

impl NodeGroups {
    /// The blocks of `nodes` (a built tree's, root first, whose member
    /// lights are `lights`).
    pub(crate) fn new(nodes: &[Node], lights: &[PointLight]) -> Self {
        Self::new_on(nodes, lights, Pool::ONE)
    }

    /// [`NodeGroups::new`], the blocks filled on `pool` (the same blocks).
    pub(crate) fn new_on(nodes: &[Node], lights: &[PointLight], pool: Pool) -> Self {
        let mut groups = Self::default();
        groups.refill(nodes, lights, pool);
        groups
    }

    /// Makes these the blocks of `nodes` (whose member lights are
    /// `lights`), filled on `pool`, in the memory they hold (the same
    /// blocks as [`NodeGroups::new_on`]).
    pub(crate) fn refill(&mut self, nodes: &[Node], lights: &[PointLight], pool: Pool) {
        self.refill_spread(nodes, &colour_spreads(nodes, lights), pool);
    }

    /// [`refill`](Self::refill) with the nodes' [`colour_spreads`] given.
    pub(crate) fn refill_spread(&mut self, nodes: &[Node], spreads: &[[f32; 2]], pool: Pool) {
        let at = &mut self.at;
        at.clear();
        at.resize(nodes.len(), NO_BLOCK);
        let (mut fours, mut eights) = (Vec::new(), Vec::new());
        let (mut mono_fours, mut mono_eights) = (Vec::new(), Vec::new());
        for (index, parent) in nodes.iter().enumerate() {
            if parent.is_leaf() {
                continue;
            }
            let mono = spreads[parent.children()]
                .iter()
                .all(|s| s.iter().all(|&s| f64::from(s) <= MONO_SPREAD_MAX));
            let (list, flags) = match (parent.child_count <= 4, mono) {
                (true, false) => (&mut fours, 0),
                (false, false) => (&mut eights, EIGHT),
                (true, true) => (&mut mono_fours, MONO),
                (false, true) => (&mut mono_eights, EIGHT | MONO),
            };
            // A block's index takes the table's 30 low bits (below all ones,
            // which with both flags would read as `NO_BLOCK`). A node past
            // them (over 2^30 - 1 blocks of one kind, some 350 GB of them)
            // keeps `NO_BLOCK`: it is bounded child by child.
            if let Ok(i) = u32::try_from(list.len())
                && i < MONO - 1
            {
                at[index] = i | flags;
                list.push(index);
            }
        }
        fn block<const N: usize, const R: usize, const M: usize>(
            nodes: &[Node],
            spreads: &[[f32; 2]],
            index: usize,
        ) -> Block<N, R, M> {
            let children = nodes[index].children();
            Block::of(&nodes[children.clone()], &spreads[children])
        }
        let on = |blocks: usize| {
            if blocks >= PARALLEL_BLOCKS {
                pool
            } else {
                Pool::ONE
            }
        };
        on(fours.len()).map_into(&fours, &mut self.fours, |&i| block(nodes, spreads, i));
        on(eights.len()).map_into(&eights, &mut self.eights, |&i| block(nodes, spreads, i));
        on(mono_fours.len()).map_into(&mono_fours, &mut self.mono_fours, |&i| {
            block(nodes, spreads, i)
        });
        on(mono_eights.len()).map_into(&mono_eights, &mut self.mono_eights, |&i| {
            block(nodes, spreads, i)
        });
    }

    /// The children of node `index`, or `None` for a leaf.
    #[inline(always)]
    pub(crate) fn children(&self, index: usize) -> Option<Group<'_>> {
        let at = *self.at.get(index)?;
        if at == NO_BLOCK {
            return None;
        }
        let i = (at & !(EIGHT | MONO)) as usize;
        match (at & EIGHT != 0, at & MONO != 0) {
            (false, false) => self.fours.get(i).map(Group::Four),
            (true, false) => self.eights.get(i).map(Group::Eight),
            (false, true) => self.mono_fours.get(i).map(Group::MonoFour),
            (true, true) => self.mono_eights.get(i).map(Group::MonoEight),
        }
    }

    /// Heap memory held, in bytes.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.fours.capacity() * size_of::<Block<4>>()
            + self.eights.capacity() * size_of::<Block<8>>()
            + self.mono_fours.capacity() * size_of::<MonoBlock<4>>()
            + self.mono_eights.capacity() * size_of::<MonoBlock<8>>()
            + self.at.capacity() * size_of::<u32>()
    }

    /// The numbers of blocks holding three channels and one colour.
    #[cfg(test)]
    pub(crate) fn kinds(&self) -> (usize, usize) {
        (
            self.fours.len() + self.eights.len(),
            self.mono_fours.len() + self.mono_eights.len(),
        )
    }

    /// The first node whose children's block does not hold exactly what
    /// [`NodeGroups::new`] makes of `nodes` and `lights`.
    pub(crate) fn first_mismatch(&self, nodes: &[Node], lights: &[PointLight]) -> Option<usize> {
        let fresh = Self::new(nodes, lights);
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
            (Group::MonoFour(a), Group::MonoFour(b)) => bits_equal(a, b),
            (Group::MonoEight(a), Group::MonoEight(b)) => bits_equal(a, b),
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
fn bits_equal<const N: usize, const R: usize, const M: usize>(
    a: &Block<N, R, M>,
    b: &Block<N, R, M>,
) -> bool {
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

impl NodeGroups {
    /// Makes these the blocks of `nodes` (after a build or refit), on
    /// `pool`, the leaves' colour ratios taken from the statistics pass's
    /// `notes` (one per node) rather than read again from the lights: the
    /// blocks [`NodeGroups::new_on`] makes.
    pub(super) fn refill_from_notes(&mut self, nodes: &[Node], notes: &mut [Notes], pool: Pool) {
        let spreads = spreads_from_leaves(nodes, notes);
        self.refill_spread(nodes, &spreads, pool);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::{LightTree, PointLight};

    /// Every lane of every group holds its child's values, the box stored
    /// relative to the centroid contains every member, and the norms are
    /// rounded up to half precision; the blocks of white lights, or of one
    /// colour, hold one colour with its spreads, those of coloured ones do
    /// not, and a scene of both has both.
    #[test]
    fn groups_hold_their_childrens_values() {
        let mut state = 5u64;
        // A flat scene (nodes of four children) and a solid one (eight);
        // coloured lights, white ones, and white ones with a coloured
        // corner.
        for (depth, colours) in [
            (1e-3, 0),
            (30.0, 0),
            (1e-3, 1),
            (30.0, 1),
            (30.0, 2),
            (30.0, 3),
        ] {
            let lights = scene(&mut state, depth, colours);
            let tree = LightTree::build(&lights).unwrap();
            let spreads = colour_spreads(tree.nodes(), tree.lights());
            let (coloured, mono) = tree.groups.kinds();
            match colours {
                0 => assert_eq!(mono, 0),
                1 | 3 => assert_eq!(coloured, 0),
                _ => assert!(coloured > 0 && mono > coloured, "{coloured} {mono}"),
            }
            let mut checked = [0; 2];
            for (index, parent) in tree.nodes().iter().enumerate() {
                let Some(group) = tree.groups.children(index) else {
                    assert!(parent.is_leaf());
                    continue;
                };
                assert_eq!(
                    matches!(group, Group::Four(_) | Group::MonoFour(_)),
                    parent.children().len() <= 4
                );
                // One colour exactly where every child's spreads allow it.
                let one_colour = spreads[parent.children()]
                    .iter()
                    .all(|s| s.iter().all(|&s| f64::from(s) <= MONO_SPREAD_MAX));
                assert_eq!(
                    matches!(group, Group::MonoFour(_) | Group::MonoEight(_)),
                    one_colour
                );
                for (i, child) in tree.nodes()[parent.children()].iter().enumerate() {
                    let spread = spreads[parent.children().start + i];
                    check_lane(&tree, group, i, child, spread, colours);
                    checked
                        [usize::from(matches!(group, Group::Eight(..) | Group::MonoEight(..)))] +=
                        1;
                }
            }
            assert!(checked.iter().sum::<usize>() > 100, "{checked:?}");
            assert_eq!(
                tree.groups.first_mismatch(tree.nodes(), tree.lights()),
                None
            );
        }
    }

    /// 3,000 lights in a box `depth` thick: coloured (`colours` 0), white
    /// (1), white but for a coloured corner (2), or of one colour scaled
    /// (3).
    fn scene(state: &mut u64, depth: f32, colours: u32) -> Vec<PointLight> {
        let mut u = || crate::testing::uniform(state);
        (0..3000)
            .map(|_| {
                let p = Vec3::new(u() * 900.0 + 1e4, u() * 30.0 - 15.0, u() * depth);
                let white = colours == 1 || (colours == 2 && p.x > 1e4 + 100.0);
                let colour = if white {
                    Vec3::splat(u() * 3.0)
                } else if colours == 3 {
                    Vec3::new(1.0, 0.55, 0.2) * (u() * 3.0)
                } else {
                    Vec3::new(u(), u(), u() * 0.1)
                };
                PointLight::new(p, colour)
            })
            .collect()
    }

    /// Lane `i` of `group` holds the values of `child`, whose colour
    /// spreads are `spread`, in a tree of [`scene`]`(_, _, colours)`.
    fn check_lane(
        tree: &LightTree,
        group: Group<'_>,
        i: usize,
        child: &Node,
        spread: [f32; 2],
        colours: u32,
    ) {
        // A lane's rows, its norms, and the row of channel 0's first
        // second moment.
        let (lane, norm, covariances): (Vec<f32>, Vec<u16>, usize) = with_block!(group, b => (
            b.rows.iter().map(|r| r[i]).collect(),
            b.norms.iter().map(|r| r[i]).collect(),
            covariance_row_of(b, 0, 0),
        ));
        let mono = lane.len() == MONO_ROWS;
        if mono {
            assert_eq!(lane[MONO_ROWS - 2..], spread);
            // At least the largest over the smallest ratio of channel
            // k + 1 to channel 0 of its lights.
            for (k, &spread) in spread.iter().enumerate() {
                let (low, high) = tree.lights()[child.lights()]
                    .iter()
                    .map(|l| f64::from(l.intensity[k + 1]) / f64::from(l.intensity.x))
                    .fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(r), b.max(r)));
                if high > 0.0 {
                    assert!(f64::from(spread) >= high / low, "{spread} {high} {low}");
                }
            }
            let white = colours == 1 || child.intensity.x == child.intensity.y;
            assert_eq!(spread == [1.0; 2], white, "{spread:?}");
            assert!(spread.iter().all(|&s| s <= 1.0 + 1e-6), "{spread:?}");
        }
        // Channel 1 (channel 0 of a one-colour block), and channel 2's
        // norms (channel 0's).
        let (k, n) = if mono { (0, 0) } else { (1, 2) };
        assert_eq!(lane[RADIUS], child.radius);
        assert_eq!(lane[CENTROID + 2], child.centroid.z);
        assert_eq!(
            lane[covariances + 6 * k + 4],
            child.channel_covariances[k][4]
        );
        assert_eq!(lane[OFFSETS + 3 * k + 2], child.channel_offsets[k].z);
        let q = child.harmonic_norms[1][n];
        let stored = widen_half(norm[3 * n + 1]);
        assert!(stored >= q && stored <= q.max(6.2e-5) * (1.0 + 1.0 / 1024.0));
        for light in &tree.lights()[child.lights()] {
            for axis in 0..3 {
                let rel = f64::from(light.position[axis]) - f64::from(child.centroid[axis]);
                assert!(f64::from(lane[BOX_LOW + axis]) <= rel);
                assert!(f64::from(lane[BOX_HIGH + axis]) >= rel);
            }
        }
    }

    /// [`Block::covariance_row`] of `block`'s kind.
    fn covariance_row_of<const N: usize, const R: usize, const M: usize>(
        _: &Block<N, R, M>,
        k: usize,
        e: usize,
    ) -> usize {
        Block::<N, R, M>::covariance_row(k, e)
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
