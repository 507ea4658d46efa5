//! Building the tree: an adaptive octree over point lights, and the node
//! statistics that building and refitting share.

use core::ops::{Add, Mul, Sub};

use glam::{DVec3, Vec3};

use super::groups::{Ratios, leaf_ratios};
use super::layout::{LightTree, MAX_CHILDREN, Node};
use super::moments::{LeafScratch, Moments, Statistics};
use super::morton;
use super::pool::Pool;
use crate::geometry::Aabb;
use crate::numeric::{BUILD_LENGTH_SLACK, HARMONIC_BUILD_PAD, round_up_f32};
use crate::{BuildError, PointLight};

impl LightTree {
    /// Builds a tree with the default options of [`TreeBuilder`].
    ///
    /// An empty slice gives an empty tree, which shades to zero with zero
    /// error.
    ///
    /// # Errors
    /// A [`BuildError`] naming the first light with a non-finite or
    /// out-of-range position, or a non-finite or negative intensity channel.
    pub fn build(lights: &[PointLight]) -> Result<Self, BuildError> {
        TreeBuilder::new().build(lights)
    }

    /// [`build`](Self::build) spread over rayon's thread pool (with the
    /// `rayon` feature): the same tree, bit for bit (see
    /// [`TreeBuilder::build_parallel`]).
    ///
    /// # Errors
    /// As [`build`](Self::build).
    #[cfg(feature = "rayon")]
    pub fn build_parallel(lights: &[PointLight]) -> Result<Self, BuildError> {
        TreeBuilder::new().build_parallel(lights)
    }

    /// A builder carrying the options (maximum lights per leaf, maximum depth).
    pub fn builder() -> TreeBuilder {
        TreeBuilder::new()
    }

    /// Rebuilds this tree over `lights` with the options it was built with,
    /// in the memory it holds: the tree [`TreeBuilder::build`] gives, bit
    /// for bit (see [`TreeBuilder::rebuild`]).
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{LightTree, PointLight};
    ///
    /// let mut lights: Vec<PointLight> = (0..1000)
    ///     .map(|i| PointLight::new(Vec3::new((i % 40) as f32, (i / 40) as f32, 5.0), Vec3::ONE))
    ///     .collect();
    /// let mut tree = LightTree::build(&lights)?;
    /// // Next frame: some lights switched off, a new one on.
    /// lights.truncate(600);
    /// lights.push(PointLight::new(Vec3::new(3.0, 4.0, 6.0), Vec3::splat(2.0)));
    /// tree.rebuild(&lights)?;
    /// assert_eq!(tree.len(), 601);
    /// # Ok::<(), manylights::BuildError>(())
    /// ```
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was.
    pub fn rebuild(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        let options = self.options;
        options.rebuild(self, lights)
    }

    /// [`rebuild`](Self::rebuild) spread over rayon's thread pool (with the
    /// `rayon` feature), as [`TreeBuilder::build_parallel`].
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was.
    #[cfg(feature = "rayon")]
    pub fn rebuild_parallel(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        let options = self.options;
        options.rebuild_parallel(self, lights)
    }
}

/// Options for building a [`LightTree`].
///
/// The tree is the paper's octree over the scene's bounding cube, adapted to
/// its content. The lights are sorted once along a Morton (Z-order) curve
/// with 21 bits per axis (a linear-time radix sort), so every octree cell is
/// a contiguous run of lights; a node's children are the occupied sub-cells
/// at the first level where its lights' cells differ, so levels with a
/// single occupied cell are skipped and a node has 2 to 8 children. Cells
/// are cubes, so a flat scene (a city) is split along its thin axis only
/// where cells become as small as its thickness.
///
/// Occupied sub-cells that together hold at most
/// [`max_leaf_lights`](Self::max_leaf_lights) lights become one leaf
/// rather than several: the children are found by halving the cell along
/// each axis in turn, and a half or a quarter of the cell (or a pair of
/// neighbouring sub-cells) with few enough lights is not halved further.
/// So a node splits into a few well-filled leaves instead of up to eight
/// small ones: on the street city the leaves average 21 to 23 lights at
/// 10^4 to 10^7 lights against 12 to 21 without this, and the tree has
/// 0.058 to 0.075 nodes per light instead of 0.062 to 0.12, which makes
/// the build faster and the tree smaller. A child that holds more than
/// `max_leaf_lights` lights is always a single sub-cell.
///
/// A node becomes a leaf when it holds at most
/// [`max_leaf_lights`](Self::max_leaf_lights) lights, when it reaches
/// [`max_depth`](Self::max_depth), or when all its lights are coincident
/// (zero extent): thousands of coincident lights make one leaf, never an
/// endless recursion, and the cut evaluates such a leaf as one light of
/// their summed intensity. Lights that share a finest Morton cell (cells
/// are `2^-21` of the scene's extent; exponentially clustered lights, at
/// `2^-k` say) are halved at the median of their longest axis instead, which
/// needs at most `log2(n)` more levels, so leaves stay small however deep
/// the clustering.
///
/// The build also records each node whose lights lie *exactly* in one
/// tilted plane (decided in exact integer arithmetic on the `f32`
/// coordinates; nodes of fewer than 8 lights, or whose box is flat along an
/// axis, are not examined): a shading point whose tangent plane is exactly
/// parallel to that plane, with the lights at or below it, receives exactly
/// nothing from such a node under Lambert's model (see
/// [`Shader::horizon`](crate::Shader::horizon)), and the cut settles it
/// without walking its lights. Scenes without such
/// planes store nothing for them.
///
/// With the `rayon` feature, `build_parallel` builds the same tree, bit for
/// bit, on rayon's thread pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use]
pub struct TreeBuilder {
    max_leaf_lights: usize,
    max_depth: u32,
}

impl Default for TreeBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl TreeBuilder {
    /// Default options: at most 32 lights per leaf, depth at most 64.
    ///
    /// Thirty-two suits the cut: a node of at most 32 lights known visible
    /// is summed light by light when it enters the cut, so without
    /// interpolation or occluders no leaf is ever bounded, and the same
    /// cut costs the same evaluations with 32 as with 16 lights per leaf.
    /// Smaller leaves mean more nodes to build and store for nothing. Leaves
    /// of at most 16 lights measured against 32 on the street city at 10^6
    /// lights (one core): 0.13 nodes per light instead of 0.069, 86 bytes
    /// per light instead of 59, a build about 1.4x slower. Smaller leaves
    /// can still pay where the host's visibility classifications are cheap
    /// and its shadow rays dear: they classify more nodes and trace fewer
    /// rays.
    pub const fn new() -> Self {
        Self {
            max_leaf_lights: 32,
            max_depth: 64,
        }
    }

    /// Maximum number of lights a leaf holds (at least 1; leaves deeper than
    /// `max_depth` or of coincident lights may hold more).
    pub const fn max_leaf_lights(mut self, n: usize) -> Self {
        self.max_leaf_lights = n;
        self
    }

    /// Maximum depth of the tree (the root is at depth 0).
    pub const fn max_depth(mut self, depth: u32) -> Self {
        self.max_depth = depth;
        self
    }

    /// Builds the tree.
    ///
    /// The sort is linear, and so are the node statistics: each leaf sums
    /// its lights' moments (up to degree 5) once, and every other node
    /// shifts its children's moments to its own centroid, with a certified
    /// bound on the rounding carried along (see
    /// [`Node::moment_error`](crate::Node::moment_error)). The radii stay
    /// exact (the farthest member, rounded up): a leaf measures its lights'
    /// distances from the offsets its moment sums take, and every other
    /// node looks for its farthest member through its subtree, skipping the
    /// subtrees that its children's radii show cannot hold it, so that it
    /// reads the lights of a few leaves rather than all of its own. Memory
    /// `O(n)`.
    ///
    /// # Errors
    /// [`BuildError`] for a light with a non-finite or out-of-range
    /// coordinate, a non-finite or negative intensity channel (naming the
    /// first such light), more than `u32::MAX` lights, or
    /// `max_leaf_lights == 0`.
    pub fn build(&self, lights: &[PointLight]) -> Result<LightTree, BuildError> {
        self.build_on(lights, Pool::ONE)
    }

    /// [`build`](Self::build) spread over rayon's thread pool (with the
    /// `rayon` feature): the same tree, bit for bit, and the same errors.
    ///
    /// The node statistics (sums, radii and moments), most of a build's
    /// work, are computed subtree by subtree side by side (the calling
    /// thread takes subtrees too), then the few nodes above those subtrees;
    /// from 8,192 lights on. The lighter passes (the checks, the Morton
    /// codes, the sort's buckets, the gathering of the lights and the
    /// planes) run in parallel from 524,288 lights on, below which waking
    /// the pool's threads costs more than they gain. The split into nodes
    /// stays on the calling thread. A pool of one thread builds on the
    /// calling thread.
    ///
    /// # Errors
    /// As [`build`](Self::build).
    #[cfg(feature = "rayon")]
    pub fn build_parallel(&self, lights: &[PointLight]) -> Result<LightTree, BuildError> {
        self.build_on(lights, Pool::for_lights(lights.len()))
    }

    /// Rebuilds `tree` over `lights` with these options, in the memory the
    /// tree holds: the same tree, bit for bit, as [`build`](Self::build)
    /// gives. The tree keeps these options for [`LightTree::rebuild`].
    ///
    /// For scenes whose lights change from frame to frame (lights switched
    /// on and off, added or removed). A fresh build writes its tree into
    /// new memory, which the operating system maps page by page where the
    /// allocator takes it from the system, as it does for the arrays of
    /// millions of lights; a rebuild writes over the memory the tree holds,
    /// growing it only where the new tree is larger (the build's own
    /// working arrays are still taken afresh). On the street city, one
    /// thread, a rebuild took 0.8 to 0.9 times a fresh build's time at 10^6
    /// and 10^7 lights, and about the same at 10^5 and below, where the
    /// allocator hands back memory it has already mapped. Lights that only move, in
    /// the same number, are cheaper still to [`refit`](LightTree::refit).
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was (the
    /// lights are checked before it is touched).
    pub fn rebuild(&self, tree: &mut LightTree, lights: &[PointLight]) -> Result<(), BuildError> {
        self.build_into(tree, lights, Pool::ONE)
    }

    /// [`rebuild`](Self::rebuild) spread over rayon's thread pool (with the
    /// `rayon` feature), as [`build_parallel`](Self::build_parallel): the
    /// same tree, bit for bit.
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was.
    #[cfg(feature = "rayon")]
    pub fn rebuild_parallel(
        &self,
        tree: &mut LightTree,
        lights: &[PointLight],
    ) -> Result<(), BuildError> {
        self.build_into(tree, lights, Pool::for_lights(lights.len()))
    }

    fn build_on(&self, lights: &[PointLight], pool: Pool) -> Result<LightTree, BuildError> {
        let mut tree = LightTree {
            nodes: Vec::new(),
            lights: Vec::new(),
            order: Vec::new(),
            depth: 0,
            planes: Vec::new(),
            node_planes: Vec::new(),
            groups: Default::default(),
            options: *self,
        };
        self.build_into(&mut tree, lights, pool)?;
        Ok(tree)
    }

    /// Builds the tree of `lights` into `tree`, reusing its memory; `tree`
    /// is left as it was on an error.
    fn build_into(
        &self,
        tree: &mut LightTree,
        lights: &[PointLight],
        pool: Pool,
    ) -> Result<(), BuildError> {
        if self.max_leaf_lights == 0 {
            return Err(BuildError::InvalidOption("max_leaf_lights must be >= 1"));
        }
        if lights.len() > u32::MAX as usize {
            return Err(BuildError::TooManyLights {
                count: lights.len(),
                max: u32::MAX as usize,
            });
        }
        // The checks and the scene's box in one read of the lights.
        let scene = check_and_bound(lights, pool.cheap(lights.len()))?;

        let n = lights.len();
        tree.options = *self;
        tree.depth = 0;
        if n == 0 {
            tree.nodes.clear();
            tree.lights.clear();
            tree.order.clear();
            tree.planes.clear();
            tree.node_planes.clear();
            tree.fill_groups(&mut [], Pool::ONE);
            return Ok(());
        }
        // Sort once along the Morton curve and gather the lights into that
        // order: every octree cell is then a contiguous run, and every later
        // pass over a node's lights reads memory in sequence.
        let cheap = pool.cheap(n);
        let grid = morton::Grid::over(scene);
        let unsorted = grid.codes_of(lights, cheap);
        // Median splits reorder lights within a run of equal codes only, so
        // the sorted codes stay valid for every run.
        let codes = morton::sort_into(&unsorted, cheap, &mut tree.order);
        // Freed before the arrays that follow are taken, which can reuse
        // its memory.
        drop(unsorted);
        cheap.map_into(&tree.order, &mut tree.lights, |&k| lights[k as usize]);

        // Breadth-first: children of a node are appended together, so they
        // are contiguous. The shape comes first, in compact records (lights
        // and children of each node, and its depth); the nodes are made
        // from it in one allocation, and their statistics follow,
        // bottom-up.
        // Each node's sub-cells are read off the levels at which
        // neighbouring codes first differ (one byte a light, scanned in
        // sequence) rather than searched for in the codes, whose reads at
        // each node's ends would miss the cache.
        let levels = morton::split_levels(&codes);
        drop(codes);
        let mut shapes = vec![Shape {
            first_light: 0,
            light_count: n as u32,
            first_child: 0,
            child_count: 0,
            depth: 0,
        }];
        let mut i = 0;
        while i < shapes.len() {
            let shape = shapes[i];
            let range = shape.lights();
            tree.depth = tree.depth.max(shape.depth);
            if range.len() > self.max_leaf_lights && shape.depth < self.max_depth {
                // The octree cell's occupied sub-cells at the first level
                // where the codes differ; lights in one finest cell are
                // halved at their median instead.
                let groups = match morton::children(
                    &levels[range.start..range.end - 1],
                    self.max_leaf_lights,
                ) {
                    Some(groups) => groups,
                    None => median_split(
                        &mut tree.lights[range.clone()],
                        &mut tree.order[range.clone()],
                    ),
                };
                if groups.len() > 1 {
                    shapes[i].first_child = shapes.len() as u32;
                    shapes[i].child_count = groups.len() as u32;
                    for g in groups {
                        shapes.push(Shape {
                            first_light: (range.start + g.start) as u32,
                            light_count: g.len() as u32,
                            first_child: 0,
                            child_count: 0,
                            depth: shape.depth + 1,
                        });
                    }
                }
            }
            i += 1;
        }
        drop(levels);
        cheap.map_into(&shapes, &mut tree.nodes, Shape::node);
        drop(shapes);
        let mut notes = fill_statistics(tree, pool);
        super::plane::record_planes(tree, &notes, cheap);
        tree.fill_groups(&mut notes, pool);
        Ok(())
    }
}

/// `0..n` cut into [`Pool::parts`] ranges of nearly equal length (one when
/// the pool is the calling thread).
fn chunks(n: usize, pool: Pool) -> Vec<core::ops::Range<usize>> {
    let parts = pool.parts().clamp(1, n.max(1));
    (0..parts)
        .map(|k| k * n / parts..(k + 1) * n / parts)
        .collect()
}

/// The first light that cannot be built, as [`BuildError`], checked in
/// parts on `pool` (the first failing part's first error).
pub(super) fn check_lights(lights: &[PointLight], pool: Pool) -> Result<(), BuildError> {
    check_and_bound(lights, pool).map(|_| ())
}

/// [`check_lights`], and the box of the lights when they can be built: one
/// read of the lights, in parts on `pool`.
fn check_and_bound(lights: &[PointLight], pool: Pool) -> Result<Aabb, BuildError> {
    let parts = pool.map(&chunks(lights.len(), pool), |r| {
        let part = &lights[r.clone()];
        let (aabb, valid) = bound_part(part);
        if valid {
            Ok(aabb)
        } else {
            // Some light is bad: the slower check names the first.
            check_range(part).map_err(|e| shifted(e, r.start))?;
            debug_assert!(false, "bound_part accepts exactly what check_range accepts");
            Ok(aabb)
        }
    });
    parts
        .into_iter()
        .try_fold(Aabb::EMPTY, |b, part| Ok(b.union(part?)))
}

/// Lights [`bound_part`] reads at once: their positions and intensities,
/// 24 values, as six vectors of four.
const BOUND_LIGHTS: usize = 4;

/// The box of `lights` and whether every light passes [`check_range`],
/// without a branch per light: a coordinate passes when its magnitude is
/// at most [`PointLight::MAX_COORDINATE`] (false for NaN and infinities),
/// an intensity channel when it lies in `[0, f32::MAX]` (false for NaN,
/// infinities and negative values; `-0` passes, as there).
///
/// [`BOUND_LIGHTS`] lights at a time, as one array of their 24 values
/// (which the compiler keeps as six vectors): per value, its smallest and
/// largest so far, and whether some value was NaN. Every value passes when
/// there was no NaN and each value's extremes lie in its range; the box is
/// the positions' extremes. The lights left over are taken one by one.
/// The same box as light by light but perhaps for the sign of a zero
/// bound (`-0` and `0` compare equal, and which of them a minimum keeps
/// depends on the order), which the Morton grid over the box does not
/// see. Measured with callgrind (the street city, 10^6 lights): 11
/// instructions a light, against 44 light by light.
fn bound_part(lights: &[PointLight]) -> (Aabb, bool) {
    const VALUES: usize = 6 * BOUND_LIGHTS;
    // Per value of a group, the ends of its range.
    const LOW: [f32; VALUES] = {
        let mut out = [0.0; VALUES];
        let mut k = 0;
        while k < VALUES {
            out[k] = if k % 6 < 3 {
                -PointLight::MAX_COORDINATE
            } else {
                0.0
            };
            k += 1;
        }
        out
    };
    const HIGH: [f32; VALUES] = {
        let mut out = [0.0; VALUES];
        let mut k = 0;
        while k < VALUES {
            out[k] = if k % 6 < 3 {
                PointLight::MAX_COORDINATE
            } else {
                f32::MAX
            };
            k += 1;
        }
        out
    };
    let mut lo = [f32::INFINITY; VALUES];
    let mut hi = [f32::NEG_INFINITY; VALUES];
    let mut nan = [0u32; 4];
    let groups = lights.chunks_exact(BOUND_LIGHTS);
    let rest = groups.remainder();
    for group in groups {
        let mut v = [0.0f32; VALUES];
        for (v, l) in v.chunks_exact_mut(6).zip(group) {
            v[..3].copy_from_slice(&l.position.to_array());
            v[3..].copy_from_slice(&l.intensity.to_array());
        }
        // Four lanes at a time, so that the NaN flags are one vector.
        for q in 0..VALUES / 4 {
            for (k, nan) in nan.iter_mut().enumerate() {
                let i = 4 * q + k;
                let x = v[i];
                // As `Vec3::min` and `Vec3::max` compare (a NaN is not
                // kept: the flags see it).
                lo[i] = if lo[i] < x { lo[i] } else { x };
                hi[i] = if hi[i] > x { hi[i] } else { x };
                *nan |= u32::from(x.is_nan());
            }
        }
    }
    let (mut aabb, mut valid) = bound_each(rest);
    for (lo, hi) in lo.chunks_exact(6).zip(hi.chunks_exact(6)) {
        aabb = aabb.union(Aabb {
            min: Vec3::from_slice(&lo[..3]),
            max: Vec3::from_slice(&hi[..3]),
        });
    }
    valid &= nan == [0; 4];
    for i in 0..VALUES {
        valid &= lo[i] >= LOW[i] && hi[i] <= HIGH[i];
    }
    (aabb, valid)
}

/// [`bound_part`] light by light.
fn bound_each(lights: &[PointLight]) -> (Aabb, bool) {
    let max = Vec3::splat(PointLight::MAX_COORDINATE);
    let mut aabb = Aabb::EMPTY;
    let mut valid = true;
    for l in lights {
        let (p, i) = (l.position, l.intensity);
        valid &= p.abs().cmple(max).all() & i.cmpge(Vec3::ZERO).all() & i.cmple(Vec3::MAX).all();
        aabb = aabb.union_point(p);
    }
    (aabb, valid)
}

/// `error` with the light's index moved up by `by`.
fn shifted(error: BuildError, by: usize) -> BuildError {
    match error {
        BuildError::NonFinitePosition { index } => {
            BuildError::NonFinitePosition { index: index + by }
        }
        BuildError::PositionOutOfRange { index, max } => BuildError::PositionOutOfRange {
            index: index + by,
            max,
        },
        BuildError::NonFiniteIntensity { index } => {
            BuildError::NonFiniteIntensity { index: index + by }
        }
        BuildError::NegativeIntensity { index } => {
            BuildError::NegativeIntensity { index: index + by }
        }
        other => other,
    }
}

/// [`check_lights`] on one part, indices relative to it.
fn check_range(lights: &[PointLight]) -> Result<(), BuildError> {
    for (index, l) in lights.iter().enumerate() {
        if !l.position.is_finite() {
            return Err(BuildError::NonFinitePosition { index });
        }
        if l.position.abs().max_element() > PointLight::MAX_COORDINATE {
            return Err(BuildError::PositionOutOfRange {
                index,
                max: PointLight::MAX_COORDINATE,
            });
        }
        if !l.intensity.is_finite() {
            return Err(BuildError::NonFiniteIntensity { index });
        }
        // `!(x >= 0)` would also catch NaN, already excluded above.
        if l.intensity.min_element() < 0.0 {
            return Err(BuildError::NegativeIntensity { index });
        }
    }
    Ok(())
}

/// Halves a run of lights (and their original indices, kept in step) at
/// the median position along the box's longest axis: two ranges, or one
/// when all lights coincide. Used for lights that share a finest Morton
/// cell (exponentially clustered lights, at `2^-k` say): halving the count
/// bounds the extra depth by `log2(n)`.
fn median_split(
    lights: &mut [PointLight],
    order: &mut [u32],
) -> smallvec::SmallVec<[core::ops::Range<usize>; 8]> {
    let aabb = lights
        .iter()
        .fold(Aabb::EMPTY, |b, l| b.union_point(l.position));
    let extent = aabb.max - aabb.min;
    let mut out = smallvec::SmallVec::new();
    if extent.max_element() <= 0.0 {
        // All lights coincide: nothing can separate them.
        out.push(0..lights.len());
        return out;
    }
    let axis = extent.max_position();
    let mut pairs: Vec<(PointLight, u32)> =
        lights.iter().copied().zip(order.iter().copied()).collect();
    let mid = pairs.len() / 2;
    pairs.select_nth_unstable_by(mid, |a, b| {
        a.0.position[axis].total_cmp(&b.0.position[axis])
    });
    for ((l, o), (pl, po)) in lights.iter_mut().zip(order.iter_mut()).zip(pairs) {
        (*l, *o) = (pl, po);
    }
    out.push(0..mid);
    out.push(mid..lights.len());
    out
}

/// Number of real solid harmonics of degrees 3, 4 and 5: `7 + 9 + 11`.
pub(crate) const HARMONIC_COUNT: usize = 27;

/// Index of the first harmonic of degree `l` (3, 4 or 5) in the output of
/// [`solid_harmonics`].
pub(crate) const fn harmonic_offset(l: usize) -> usize {
    // Degrees below l hold sum_{j=3}^{l-1} (2j + 1) = l^2 - 9 harmonics.
    l * l - 9
}

/// Squared Schmidt semi-normalisation of each output of [`solid_harmonics`]:
/// `(2 - [m = 0]) (l - m)! / (l + m)!` for degree `l`, order `m`.
pub(crate) const HARMONIC_NORM_SQ: [f64; HARMONIC_COUNT] = {
    const fn factorial(k: usize) -> f64 {
        let mut f = 1.0;
        let mut i = 2;
        while i <= k {
            f *= i as f64;
            i += 1;
        }
        f
    }
    let mut out = [0.0; HARMONIC_COUNT];
    let mut l = 3;
    while l <= 5 {
        let mut m = 0;
        while m <= l {
            let v = factorial(l - m) / factorial(l + m);
            if m == 0 {
                out[harmonic_offset(l)] = v;
            } else {
                out[harmonic_offset(l) + 2 * m - 1] = 2.0 * v;
                out[harmonic_offset(l) + 2 * m] = 2.0 * v;
            }
            m += 1;
        }
        l += 1;
    }
    out
};

/// The real regular solid harmonics of degrees 3, 4 and 5 at `y`, without
/// their normalisation: for degree `l` and order `m = 0..=l`,
/// `r^l P_l^m(cos theta)` times `cos(m phi)` and (for `m >= 1`)
/// `sin(m phi)`, in that order. Multiplied by the square roots of
/// [`HARMONIC_NORM_SQ`] they are Schmidt semi-normalised, for which the
/// addition theorem reads `sum_j R_lj(a) R_lj(b) = |a|^l |b|^l P_l(a^ . b^)`;
/// the sum of squares of one degree is `|y|^(2l)`.
///
/// Evaluated as `(x + i y)^m T_lm(z, r^2)` with
/// `T_lm = r^(l-m) P_l^(m)(z / r)`, the `m`-th derivative of the Legendre
/// polynomial made homogeneous (no Condon-Shortley phase; signs cancel in
/// every product the crate forms).
#[inline]
pub(crate) fn solid_harmonics(y: DVec3) -> [f64; HARMONIC_COUNT] {
    solid_harmonics_of(y.x, y.y, y.z)
}

/// [`solid_harmonics`] for any ring: `f64` values, or polynomials to read
/// off each harmonic's monomials.
#[inline]
pub(crate) fn solid_harmonics_of<T>(x: T, y: T, z: T) -> [T; HARMONIC_COUNT]
where
    T: Copy + Add<Output = T> + Sub<Output = T> + Mul<Output = T> + Mul<f64, Output = T>,
{
    let r2 = x * x + y * y + z * z;
    let (z2, r4) = (z * z, r2 * r2);
    let z3 = z2 * z;
    // (x + i y)^m = c_m + i s_m.
    let (c1, s1) = (x, y);
    let (c2, s2) = (c1 * x - s1 * y, c1 * y + s1 * x);
    let (c3, s3) = (c2 * x - s2 * y, c2 * y + s2 * x);
    let (c4, s4) = (c3 * x - s3 * y, c3 * y + s3 * x);
    let (c5, s5) = (c4 * x - s4 * y, c4 * y + s4 * x);
    let t30 = (z3 * 5.0 - z * r2 * 3.0) * 0.5;
    let t31 = (z2 * 15.0 - r2 * 3.0) * 0.5;
    let t32 = z * 15.0;
    let t40 = (z2 * z2 * 35.0 - z2 * r2 * 30.0 + r4 * 3.0) * 0.125;
    let t41 = (z3 * 35.0 - z * r2 * 15.0) * 0.5;
    let t42 = (z2 * 105.0 - r2 * 15.0) * 0.5;
    let t43 = z * 105.0;
    let t50 = (z3 * z2 * 63.0 - z3 * r2 * 70.0 + z * r4 * 15.0) * 0.125;
    let t51 = (z2 * z2 * 315.0 - z2 * r2 * 210.0 + r4 * 15.0) * 0.125;
    let t52 = (z3 * 315.0 - z * r2 * 105.0) * 0.5;
    let t53 = (z2 * 945.0 - r2 * 105.0) * 0.5;
    let t54 = z * 945.0;
    [
        t30,
        t31 * c1,
        t31 * s1,
        t32 * c2,
        t32 * s2,
        c3 * 15.0,
        s3 * 15.0,
        t40,
        t41 * c1,
        t41 * s1,
        t42 * c2,
        t42 * s2,
        t43 * c3,
        t43 * s3,
        c4 * 105.0,
        s4 * 105.0,
        t50,
        t51 * c1,
        t51 * s1,
        t52 * c2,
        t52 * s2,
        t53 * c3,
        t53 * s3,
        t54 * c4,
        t54 * s4,
        c5 * 945.0,
        s5 * 945.0,
    ]
}

/// Harmonic norms of degrees 3 to 5 per channel (rounded upward, see
/// [`HARMONIC_BUILD_PAD`]) from the unnormalised moments `moments[k]` of
/// channel `k` (sums of `I_ik` times [`solid_harmonics`] of `y_i / R` over
/// `terms` members) and the channel intensities.
pub(crate) fn harmonic_norms(
    moments: &[[f64; HARMONIC_COUNT]; 3],
    intensity: DVec3,
    terms: usize,
) -> [Vec3; 3] {
    let pad = (terms as f64 + HARMONIC_BUILD_PAD) * f64::EPSILON;
    let mut out = [Vec3::ZERO; 3];
    for (d, norms) in out.iter_mut().enumerate() {
        let l = d + 3;
        let range = harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1;
        for k in 0..3 {
            if intensity[k] > 0.0 {
                let sq: f64 = moments[k][range.clone()]
                    .iter()
                    .zip(&HARMONIC_NORM_SQ[range.clone()])
                    .map(|(c, n)| c * c * n)
                    .sum();
                let q = sq.sqrt() / intensity[k];
                norms[k] = round_up_f32((q + pad) * (1.0 + BUILD_LENGTH_SLACK));
            }
        }
    }
    out
}

/// A node's place in the tree while the build shapes it: its lights (leaf
/// order), its children and its depth.
#[derive(Clone, Copy, Debug)]
struct Shape {
    first_light: u32,
    light_count: u32,
    first_child: u32,
    child_count: u32,
    depth: u32,
}

impl Shape {
    fn lights(&self) -> core::ops::Range<usize> {
        self.first_light as usize..(self.first_light + self.light_count) as usize
    }

    /// The node of this shape, with no statistics yet.
    fn node(&self) -> Node {
        Node {
            intensity: DVec3::ZERO,
            weight: 0.0,
            moment_error: 0.0,
            centroid: Vec3::ZERO,
            radius: 0.0,
            channel_offsets: [Vec3::ZERO; 3],
            channel_covariances: [[0.0; 6]; 3],
            harmonic_norms: [Vec3::ZERO; 3],
            aabb: Aabb::EMPTY,
            first_light: self.first_light,
            light_count: self.light_count,
            first_child: self.first_child,
            child_count: self.child_count,
        }
    }
}

/// Computes every node's statistics from the lights, in time linear in
/// their number (but for the radii's search through each node's subtree,
/// which reads a few leaves per node), for a tree whose topology is set:
/// children hold larger indices than their parent.
///
/// One depth-first pass, children before their parent, so that a
/// subtree's lights are read while they are in the cache:
///
/// 1. A leaf sums its lights' intensities, weights, weighted positions and
///    box; any other node its children's sums. Then the centroid.
/// 2. The radius: the largest distance from the centroid to a member (a
///    leaf's over its lights; any other node's found through its subtree,
///    see [`farthest_member`]).
/// 3. Moments up to degree 5 (see [`Moments`]): summed directly over each
///    leaf's lights, shifted from the children's centroids to the parent's
///    for every other node; a node's children's moments wait in one buffer
///    per level of the path until its centroid is known (eight moments of
///    about 2 KiB a level: some 350 KiB for a tree 20 levels deep, per
///    thread).
///
/// On a pool, disjoint subtrees are done side by side (each node by the
/// same operations in the same order as on one thread), then the few nodes
/// above them.
///
/// Returns every node's [`Notes`] for the planes and the blocks.
pub(super) fn fill_statistics(tree: &mut LightTree, pool: Pool) -> Vec<Notes> {
    let (lights, nodes) = (&tree.lights, &mut tree.nodes);
    let mut notes = vec![Notes::NONE; nodes.len()];
    if nodes.is_empty() {
        return notes;
    }
    let mut scratch = StatisticsScratch::new();
    if !pool.parallel() {
        let mut levels = Levels::split(nodes, &mut notes, &[0])
            .pop()
            .expect("one subtree");
        fill_subtree(&mut levels, lights, &mut scratch);
        return notes;
    }
    let roots = subtrees(nodes, pool.parts());
    let subtrees = Levels::split(nodes, &mut notes, &roots);
    let done = pool.map_owned(subtrees, StatisticsScratch::new, |scratch, mut levels| {
        let (sums, moments) = fill_subtree(&mut levels, lights, scratch);
        Done {
            root: levels.root() as u32,
            sums,
            moments: *moments,
        }
    });
    let mut done = done;
    done.sort_unstable_by_key(|d| d.root);
    let mut levels = Levels::split(nodes, &mut notes, &[0])
        .pop()
        .expect("one subtree");
    levels.done = &done;
    fill_subtree(&mut levels, lights, &mut scratch);
    notes
}

/// A node's sums that its parent's are made of, in `f64`: its members'
/// summed weight, weighted position and plain position.
type Sums = (f64, DVec3, DVec3);

/// A subtree whose statistics are done: its root, the root's sums and its
/// moments about its centroid.
struct Done {
    root: u32,
    sums: Sums,
    moments: Moments,
}

/// One level's run of a subtree's nodes: the index of its first node, the
/// nodes and their notes.
type Run<'a> = (usize, &'a mut [Node], &'a mut [Notes]);

/// What the statistics pass notes of each node for the passes after it,
/// from the lights it reads anyway (a leaf's while they are in the cache):
/// the leaf's colour ratios (see [`leaf_ratios`]) and whether the node is
/// known to hold four lights certainly off one plane (see
/// [`certainly_not_coplanar`](super::plane::certainly_not_coplanar)): a
/// leaf's first three and last, or any child's. Those passes would
/// otherwise read every leaf's lights again, from memory.
#[derive(Clone, Copy, Debug)]
pub(super) struct Notes {
    /// A leaf's [`leaf_ratios`]; for other nodes, set from their
    /// children's when the blocks are made.
    pub(super) ratios: Ratios,
    /// Whether four of the node's lights lie certainly off one plane.
    pub(super) off_plane: bool,
}

impl Notes {
    pub(super) const NONE: Self = Self {
        ratios: [(f64::INFINITY, 0.0); 2],
        off_plane: false,
    };
}

/// Mutable access to one subtree's nodes, level by level. In breadth-first
/// order a node's descendants at each depth are one contiguous run, so
/// disjoint subtrees own disjoint runs.
struct Levels<'a> {
    /// Per level below the subtree's root (the root's first): the index of
    /// the run's first node, and the run.
    runs: Vec<Run<'a>>,
    /// Subtrees below this one whose statistics are done, by root (the
    /// pass stops there); empty but for the nodes above a pool's subtrees.
    done: &'a [Done],
}

impl<'a> Levels<'a> {
    /// The subtrees of `roots` (disjoint: none holds another), each as its
    /// runs of `nodes`.
    fn split(nodes: &'a mut [Node], notes: &'a mut [Notes], roots: &[u32]) -> Vec<Self> {
        // Every subtree's runs, with the subtree they belong to: a run
        // below the last is from the first child of its first inner node
        // to the last child of its last.
        let mut runs = Vec::new();
        for (k, &root) in roots.iter().enumerate() {
            let mut run = root as usize..root as usize + 1;
            loop {
                runs.push((run.start, run.end, k));
                let level = &nodes[run.clone()];
                let Some(first) = level.iter().find(|n| !n.is_leaf()) else {
                    break;
                };
                let last = level.iter().rev().find(|n| !n.is_leaf()).unwrap_or(first);
                run = first.children().start..last.children().end;
            }
        }
        runs.sort_unstable();
        let mut out: Vec<Self> = roots
            .iter()
            .map(|_| Self {
                runs: Vec::new(),
                done: &[],
            })
            .collect();
        // Runs in the order of the array: each subtree's come shallowest
        // first.
        let (mut rest, mut rest_notes, mut offset) = (nodes, notes, 0);
        for (start, end, k) in runs {
            let (_, tail) = rest.split_at_mut(start - offset);
            let (run, tail) = tail.split_at_mut(end - start);
            let (_, tail_notes) = rest_notes.split_at_mut(start - offset);
            let (run_notes, tail_notes) = tail_notes.split_at_mut(end - start);
            out[k].runs.push((start, run, run_notes));
            (rest, rest_notes, offset) = (tail, tail_notes, end);
        }
        out
    }

    /// Index of the subtree's root.
    fn root(&self) -> usize {
        self.runs[0].0
    }

    /// Node `index`, at `depth` levels below the subtree's root.
    #[inline(always)]
    fn node(&self, depth: usize, index: usize) -> &Node {
        let (start, run, _) = &self.runs[depth];
        &run[index - start]
    }

    /// See [`node`](Self::node).
    #[inline(always)]
    fn node_mut(&mut self, depth: usize, index: usize) -> &mut Node {
        let (start, run, _) = &mut self.runs[depth];
        &mut run[index - *start]
    }

    /// The notes of node `index` (see [`node`](Self::node)).
    #[inline(always)]
    fn notes(&self, depth: usize, index: usize) -> &Notes {
        let (start, _, notes) = &self.runs[depth];
        &notes[index - start]
    }

    /// See [`notes`](Self::notes).
    #[inline(always)]
    fn notes_mut(&mut self, depth: usize, index: usize) -> &mut Notes {
        let (start, _, notes) = &mut self.runs[depth];
        &mut notes[index - *start]
    }

    /// The statistics of the subtree of `index` if they are done.
    #[inline(always)]
    fn done(&self, index: usize) -> Option<&Done> {
        if self.done.is_empty() {
            return None;
        }
        let k = self
            .done
            .binary_search_by_key(&(index as u32), |d| d.root)
            .ok()?;
        Some(&self.done[k])
    }
}

/// What one thread's pass over subtrees reuses: the moments of the root,
/// the buffers of the children's moments (one per level of a path) and the
/// leaves' scratch.
struct StatisticsScratch {
    root: Moments,
    children: Vec<[Moments; MAX_CHILDREN]>,
    leaf: LeafScratch,
}

impl StatisticsScratch {
    /// Empty buffers, grown to the depth of the first subtree filled.
    fn new() -> Self {
        Self {
            root: Moments::ZERO,
            children: Vec::new(),
            leaf: LeafScratch::new(),
        }
    }
}

/// Fills the statistics of the subtree of `levels` (see
/// [`fill_statistics`]); returns its root's sums and moments.
// Calling the AVX2 copy is one of the crate's unsafe blocks (see
// `dispatch`).
#[allow(unsafe_code)]
fn fill_subtree<'s>(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    scratch: &'s mut StatisticsScratch,
) -> (Sums, &'s Moments) {
    let depth = levels.runs.len();
    if scratch.children.len() < depth {
        scratch
            .children
            .resize(depth, [Moments::ZERO; MAX_CHILDREN]);
    }
    let root = levels.root();
    let StatisticsScratch {
        root: out,
        children,
        leaf,
    } = scratch;
    #[cfg(target_arch = "x86_64")]
    {
        if crate::dispatch::avx2_fma() {
            // SAFETY: the processor has AVX2 and FMA (`dispatch::avx2_fma`
            // checked).
            let sums = unsafe { fill_node_avx2(levels, lights, 0, root, out, children, leaf) };
            return (sums, out);
        }
    }
    let sums = fill_node_baseline(levels, lights, 0, root, out, children, leaf);
    (sums, out)
}

/// Statistics of node `index` (`depth` levels below the subtree's root)
/// and its descendants, children before parents; the node's moments about
/// its centroid into `out`, its children's into `below[0]` (their
/// children's one level down), and its sums returned. `$recurse` is the
/// function itself (one per compiled copy).
macro_rules! fill_node_body {
    ($recurse:ident, $levels:ident, $lights:ident, $depth:ident, $index:ident, $out:ident, $below:ident, $scratch:ident) => {{
        if let Some(done) = $levels.done($index) {
            *$out = done.moments;
            return done.sums;
        }
        let node = $levels.node($depth, $index);
        let (members, children, count) = (node.lights(), node.children(), node.light_count);
        let mut intensity = DVec3::ZERO;
        let (mut weight, mut weighted, mut plain) = (0.0f64, DVec3::ZERO, DVec3::ZERO);
        let mut aabb = Aabb::EMPTY;
        let (kids, below) = if children.is_empty() {
            // The lights of the leaves that follow, read next in this
            // order, start loading while this one is summed.
            let ahead = members.end..(members.end + LIGHTS_AHEAD).min($lights.len());
            super::layout::prefetch(super::layout::as_bytes_range(&$lights[ahead]));
            let leaf = &$lights[members.clone()];
            *$levels.notes_mut($depth, $index) = Notes {
                ratios: leaf_ratios(leaf),
                off_plane: leaf.len() >= 4
                    && super::plane::certainly_not_coplanar(
                        leaf[0].position,
                        leaf[1].position,
                        leaf[2].position,
                        leaf[leaf.len() - 1].position,
                    ),
            };
            for l in leaf {
                let w = f64::from(l.weight());
                let x = l.position.as_dvec3();
                intensity += l.intensity.as_dvec3();
                weight += w;
                weighted += w * x;
                plain += x;
                aabb = aabb.union_point(l.position);
            }
            (None, $below)
        } else {
            let (kids, below) = $below
                .split_first_mut()
                .expect("one buffer per level of the tree");
            let mut sums = [(0.0, DVec3::ZERO, DVec3::ZERO); MAX_CHILDREN];
            for ((k, kid), sum) in children.clone().zip(kids.iter_mut()).zip(&mut sums) {
                *sum = $recurse($levels, $lights, $depth + 1, k, kid, below, $scratch);
            }
            let off_plane = children
                .clone()
                .any(|k| $levels.notes($depth + 1, k).off_plane);
            $levels.notes_mut($depth, $index).off_plane = off_plane;
            for (k, (w, wx, x)) in children.clone().zip(sums) {
                let child = $levels.node($depth + 1, k);
                intensity += child.intensity;
                weight += w;
                weighted += wx;
                plain += x;
                aabb = aabb.union(child.aabb);
            }
            (Some(kids), below)
        };
        let _ = below;
        // Zero total weight: every member is dark; use the plain mean so the
        // node still has a sensible position (its contribution is zero either
        // way).
        let centroid = if weight > 0.0 {
            weighted / weight
        } else {
            plain / f64::from(count)
        };
        {
            let node = $levels.node_mut($depth, $index);
            node.intensity = intensity;
            node.weight = (weight as f32).min(f32::MAX);
            // The average lies in the box in exact arithmetic; clamp away
            // rounding.
            node.centroid = centroid.as_vec3().clamp(aabb.min, aabb.max);
            node.aabb = aabb;
        }
        let c = $levels.node($depth, $index).centroid.as_dvec3();
        // The largest squared distance from the centroid to a member: a
        // leaf's from the offsets its moments take, any other node's
        // through its subtree.
        let radius_sq = match kids {
            None => $out.set_to_lights(&$lights[members], c, $scratch),
            Some(kids) => {
                // The first child's shifted moments are written, the others'
                // added: no clearing of `$out` (the same bits, see
                // `Moments::shift_to`).
                for (j, (k, kid)) in children.zip(kids.iter_mut()).enumerate() {
                    let t = $levels.node($depth + 1, k).centroid.as_dvec3() - c;
                    if j == 0 {
                        kid.shift_to(t, $out);
                    } else {
                        kid.shift_into(t, $out);
                    }
                }
                farthest_member($levels, $lights, $depth, $index)
            }
        };
        let node = $levels.node_mut($depth, $index);
        node.radius = round_up_f32(radius_sq.sqrt() * (1.0 + BUILD_LENGTH_SLACK));
        let radius = node.radius;
        let stats = $out.statistics(intensity, radius, count as usize);
        store($levels.node_mut($depth, $index), stats);
        (weight, weighted, plain)
    }};
}

/// Lights past a leaf's whose loading [`fill_node_body`] starts as it
/// reaches the leaf (a leaf or two, in the build's default leaves).
const LIGHTS_AHEAD: usize = 32;

/// See [`fill_node_body`]: the baseline copy.
fn fill_node_baseline(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    depth: usize,
    index: usize,
    out: &mut Moments,
    below: &mut [[Moments; MAX_CHILDREN]],
    scratch: &mut LeafScratch,
) -> Sums {
    fill_node_body!(
        fill_node_baseline,
        levels,
        lights,
        depth,
        index,
        out,
        below,
        scratch
    )
}

/// [`fill_node_baseline`] compiled for AVX2 and FMA (the same bits, see
/// [`dispatch`](crate::dispatch)).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fill_node_avx2(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    depth: usize,
    index: usize,
    out: &mut Moments,
    below: &mut [[Moments; MAX_CHILDREN]],
    scratch: &mut LeafScratch,
) -> Sums {
    fill_node_body!(
        fill_node_avx2,
        levels,
        lights,
        depth,
        index,
        out,
        below,
        scratch
    )
}

/// The largest squared distance, as computed in `f64`, from the centroid
/// of node `index` (`depth` levels below the subtree's root), which has
/// children, to a member light: the same value as over all its lights, but
/// subtrees that cannot hold a farther member are skipped. Its
/// descendants' statistics are set. (A leaf's comes with its moments, see
/// [`Moments::set_to_lights`]: the same value as over its lights here.)
///
/// A member `x` of a subtree with centroid `c'`, stored radius `r'` (at
/// least its members' exact distances) and box `B` lies within `|c' - c| +
/// r'` of `c`, and no farther than `B`'s farthest corner; both computed in
/// `f64` are within a few `2^-53` of their exact values, and so is the
/// computed squared distance of `x` of the exact one. So a subtree whose
/// `min((|c' - c| (1 + 2^-40) + r')^2, corner^2) (1 + 2^-40)` is below the
/// largest computed value so far holds no larger one. Subtrees are taken
/// farthest bound first, depth first.
#[inline(always)]
fn farthest_member(levels: &Levels<'_>, lights: &[PointLight], depth: usize, index: usize) -> f64 {
    const MARGIN: f64 = 1.0 + 1.0 / 1_099_511_627_776.0; // 1 + 2^-40
    let node = levels.node(depth, index);
    let c = node.centroid.as_dvec3();
    // The largest of 0 and the members' squared distances, four running
    // maxima side by side (a maximum is exact, so in any order the same
    // value; no distance is NaN or -0, so a comparison serves).
    let squared = |members: &[PointLight]| {
        let distance = |l: &PointLight| (l.position.as_dvec3() - c).length_squared();
        let larger = |a: f64, b: f64| if b > a { b } else { a };
        let mut best = [0.0f64; 4];
        let fours = members.chunks_exact(4);
        let rest = fours.remainder();
        for four in fours {
            for (best, l) in best.iter_mut().zip(four) {
                *best = larger(*best, distance(l));
            }
        }
        for (best, l) in best.iter_mut().zip(rest) {
            *best = larger(*best, distance(l));
        }
        larger(larger(best[0], best[1]), larger(best[2], best[3]))
    };
    debug_assert!(!node.is_leaf(), "a leaf's radius comes with its moments");
    let mut best = 0.0f64;
    // Subtrees still to search (index and depth), with the bounds of their
    // members' squared distances.
    type Stack = smallvec::SmallVec<[(u32, u32, f64); 64]>;
    let push_children = |stack: &mut Stack, n: &Node, depth: usize| {
        let start = stack.len();
        for k in n.children() {
            let child = levels.node(depth + 1, k);
            let reach = (child.centroid.as_dvec3() - c).length() * MARGIN + f64::from(child.radius);
            let (lo, hi) = (child.aabb.min.as_dvec3() - c, child.aabb.max.as_dvec3() - c);
            let corner = (lo * lo).max(hi * hi).element_sum();
            stack.push((
                k as u32,
                (depth + 1) as u32,
                (reach * reach).min(corner) * MARGIN,
            ));
        }
        // The farthest bound on top.
        stack[start..].sort_unstable_by(|a, b| a.2.total_cmp(&b.2));
    };
    let mut stack = Stack::new();
    push_children(&mut stack, node, depth);
    while let Some((k, d, bound)) = stack.pop() {
        if bound < best {
            continue;
        }
        let n = levels.node(d as usize, k as usize);
        if n.is_leaf() {
            best = best.max(squared(&lights[n.lights()]));
        } else {
            push_children(&mut stack, n, d as usize);
        }
    }
    best
}

/// Roots of about `parts` disjoint subtrees that hold every leaf: from the
/// root, the subtree of most lights is replaced by its children's while
/// there are fewer than `parts` and it has children.
fn subtrees(nodes: &[Node], parts: usize) -> Vec<u32> {
    let mut roots = vec![0u32];
    while roots.len() < parts {
        let Some((k, &largest)) = roots
            .iter()
            .enumerate()
            .max_by_key(|(_, r)| nodes[**r as usize].light_count)
        else {
            break;
        };
        let node = &nodes[largest as usize];
        if node.is_leaf() {
            break;
        }
        roots.swap_remove(k);
        roots.extend(node.children().map(|c| c as u32));
    }
    roots
}

/// `stats` into `node`.
#[inline(always)]
fn store(node: &mut Node, stats: Statistics) {
    node.channel_offsets = stats.offsets;
    node.channel_covariances = stats.covariances;
    node.harmonic_norms = stats.harmonic_norms;
    node.moment_error = stats.moment_error;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `P_l(x)` by the three-term recurrence.
    fn legendre(l: usize, x: f64) -> f64 {
        let (mut p0, mut p1) = (1.0, x);
        for k in 2..=l {
            (p0, p1) = (
                p1,
                ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64,
            );
        }
        p1
    }

    /// The addition theorem `sum_j N_j^2 R_lj(a) R_lj(b) = |a|^l |b|^l
    /// P_l(a^ . b^)` on points of the unit ball: it checks the recurrence,
    /// the normalisation and, to `2^11 eps`, the evaluation error that
    /// `HARMONIC_BUILD_PAD` assumes.
    #[test]
    fn solid_harmonics_satisfy_the_addition_theorem() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..10_000 {
            let a = DVec3::new(uniform(), uniform(), uniform());
            let b = DVec3::new(uniform(), uniform(), uniform());
            if a.length() > 1.0 || b.length() > 1.0 || a.length() == 0.0 || b.length() == 0.0 {
                continue;
            }
            let (ha, hb) = (solid_harmonics(a), solid_harmonics(b));
            for l in 3..=5 {
                let range = harmonic_offset(l)..harmonic_offset(l) + 2 * l + 1;
                let sum: f64 = range.map(|j| HARMONIC_NORM_SQ[j] * ha[j] * hb[j]).sum();
                let cos = (a.dot(b) / (a.length() * b.length())).clamp(-1.0, 1.0);
                let expected =
                    a.length().powi(l as i32) * b.length().powi(l as i32) * legendre(l, cos);
                let scale = a.length().powi(l as i32) * b.length().powi(l as i32);
                assert!(
                    (sum - expected).abs() <= 2048.0 * f64::EPSILON * scale,
                    "degree {l}: {sum} against {expected}"
                );
            }
        }
    }
}

#[cfg(test)]
mod checks {
    use glam::Vec3;

    use super::{bound_each, bound_part, check_range};
    use crate::PointLight;

    /// The branch-free check accepts exactly the lights that the checks
    /// one by one accept, on the edges of each condition, the light at
    /// every place of a group of lights read at once and among the lights
    /// left over; and its box is the box light by light (up to the sign
    /// of a zero bound).
    #[test]
    fn the_fast_check_accepts_what_the_checks_accept() {
        let max = PointLight::MAX_COORDINATE;
        let coordinates = [
            0.0,
            -0.0,
            1.5,
            -max,
            max,
            f32::from_bits(max.to_bits() + 1),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let channels = [
            0.0,
            -0.0,
            2.0,
            f32::MAX,
            -f32::MIN_POSITIVE,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        for (a, &c) in coordinates.iter().enumerate() {
            for (b, &i) in channels.iter().enumerate() {
                for axis in 0..3 {
                    let mut light = PointLight::new(Vec3::ONE, Vec3::ONE);
                    light.position[axis] = c;
                    light.intensity[(axis + a + b) % 3] = i;
                    for len in 1..=9 {
                        for at in 0..len {
                            let mut lights: Vec<PointLight> = (0..len)
                                .map(|k| PointLight::new(Vec3::splat(k as f32 - 2.0), Vec3::ONE))
                                .collect();
                            lights[at] = light;
                            let (aabb, valid) = bound_part(&lights);
                            assert_eq!(
                                valid,
                                check_range(&lights).is_ok(),
                                "coordinate {c}, channel {i}, light {at} of {len}"
                            );
                            if valid {
                                assert_eq!(aabb, bound_each(&lights).0);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod copies {
    use glam::Vec3;

    use crate::dispatch::baseline;
    use crate::{LightTree, PointLight};

    /// The build's copy compiled for AVX2 and FMA (where the processor has
    /// them) and the baseline give the same nodes, also after a refit.
    #[test]
    fn both_copies_of_the_build_give_the_same_nodes() {
        let mut state = 3u64;
        let mut uniform = move || crate::testing::uniform(&mut state);
        let lights: Vec<PointLight> = (0..5000)
            .map(|_| {
                let p = Vec3::new(uniform() * 100.0, uniform() * 100.0, uniform() * 3.0);
                PointLight::new(p, Vec3::new(uniform(), uniform() * 5.0, uniform() * 0.01))
            })
            .collect();
        let a = LightTree::build(&lights).unwrap();
        let b = baseline(|| LightTree::build(&lights).unwrap());
        assert_eq!(a.nodes(), b.nodes());
        let moved: Vec<PointLight> = lights
            .iter()
            .map(|l| PointLight::new(l.position * 1.5 + Vec3::ONE, l.intensity))
            .collect();
        let (mut a, mut b) = (a, b);
        a.refit(&moved).unwrap();
        baseline(|| b.refit(&moved).unwrap());
        assert_eq!(a.nodes(), b.nodes());
    }
}

#[cfg(test)]
mod test_trees {
    use glam::Vec3;

    use crate::{BuildError, LightTree, PointLight, TreeBuilder};

    /// Lights enough for the pool: clusters of street lights, a tilted roof
    /// of lights exactly in one plane, and coincident lights.
    pub(super) fn lights(seed: u64, count: usize) -> Vec<PointLight> {
        let mut state = seed;
        let mut uniform = move || crate::testing::uniform(&mut state);
        (0..count)
            .map(|i| {
                let p = match i % 5 {
                    0 => Vec3::new(uniform() * 2000.0, uniform() * 2000.0, 6.0),
                    1 => {
                        // z = (x + y) / 4 on the integers: exactly one plane.
                        let (x, y) = ((uniform() * 64.0).floor(), (uniform() * 64.0).floor());
                        Vec3::new(x, y, (x + y) * 0.25)
                    }
                    2 => Vec3::new(500.0, 500.0, 20.0),
                    _ => Vec3::new(uniform() * 300.0, uniform() * 300.0, uniform() * 90.0),
                };
                PointLight::new(p, Vec3::new(uniform(), uniform() * 3.0, uniform() * 0.5))
            })
            .collect()
    }

    pub(super) fn assert_same(a: &LightTree, b: &LightTree) {
        assert_eq!(a.nodes, b.nodes);
        assert_eq!(a.lights, b.lights);
        assert_eq!(a.order, b.order);
        assert_eq!(a.depth, b.depth);
        assert_eq!(a.planes, b.planes);
        assert_eq!(a.node_planes, b.node_planes);
        assert_eq!(a.groups, b.groups);
        assert_eq!(a.options, b.options);
    }

    /// A rebuild gives the tree a fresh build gives, whatever the tree held
    /// before: more lights, fewer, none, or a tilted plane no longer there;
    /// and it keeps the options the tree was built with.
    #[test]
    fn a_rebuild_gives_the_tree_of_a_fresh_build() {
        let many = lights(11, 30_000);
        let flat: Vec<PointLight> = lights(12, 9_000)
            .into_iter()
            .map(|l| PointLight::new(l.position.with_z(4.0), l.intensity))
            .collect();
        let builder = TreeBuilder::new().max_leaf_lights(5).max_depth(12);
        let mut tree = LightTree::build(&[]).unwrap();
        for (options, scene) in [
            (TreeBuilder::new(), &many[..]),
            (TreeBuilder::new(), &many[..700]),
            (builder, &flat[..]),
            (builder, &many[..]),
            (TreeBuilder::new(), &[][..]),
            (TreeBuilder::new(), &many[5..20_000]),
        ] {
            options.rebuild(&mut tree, scene).unwrap();
            assert_same(&tree, &options.build(scene).unwrap());
            assert!(tree.validate().is_ok());
        }
        // The options it was last built with.
        let mut tree = builder.build(&many[..100]).unwrap();
        tree.rebuild(&flat).unwrap();
        assert_same(&tree, &builder.build(&flat).unwrap());
    }

    /// A rebuild over lights it cannot build leaves the tree as it was.
    #[test]
    fn a_failed_rebuild_leaves_the_tree_as_it_was() {
        let mut scene = lights(13, 4_000);
        let mut tree = LightTree::build(&scene).unwrap();
        let before = tree.clone();
        scene[3_210].position.y = f32::NAN;
        assert_eq!(
            tree.rebuild(&scene),
            Err(BuildError::NonFinitePosition { index: 3_210 })
        );
        assert_same(&tree, &before);
        assert_eq!(
            TreeBuilder::new()
                .max_leaf_lights(0)
                .rebuild(&mut tree, &scene[..10]),
            Err(BuildError::InvalidOption("max_leaf_lights must be >= 1"))
        );
        assert_same(&tree, &before);
    }
}

#[cfg(all(test, feature = "rayon"))]
mod parallel {
    use glam::Vec3;

    use super::test_trees::{assert_same, lights};
    use crate::{BuildError, LightTree, PointLight, TreeBuilder};

    /// `f` on a pool of two threads, whatever the machine has.
    fn on_two_threads<T: Send>(f: impl FnOnce() -> T + Send) -> T {
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(f)
    }

    #[test]
    fn a_parallel_build_and_refit_give_the_tree_of_one_thread() {
        let lights = lights(5, 60_000);
        let one = LightTree::build(&lights).unwrap();
        let pool = on_two_threads(|| LightTree::build_parallel(&lights).unwrap());
        assert!(!one.planes.is_empty(), "the roof is recorded as a plane");
        assert_same(&one, &pool);

        let builder = TreeBuilder::new().max_leaf_lights(3).max_depth(9);
        let one = builder.build(&lights).unwrap();
        let mut pool = on_two_threads(|| builder.build_parallel(&lights).unwrap());
        assert_same(&one, &pool);

        let moved: Vec<PointLight> = lights
            .iter()
            .map(|l| PointLight::new(l.position * 0.5 - Vec3::ONE, l.intensity * 2.0))
            .collect();
        let mut one = one;
        one.refit(&moved).unwrap();
        on_two_threads(|| pool.refit_parallel(&moved).unwrap());
        assert_same(&one, &pool);

        // Rebuilt in place on the pool, over fewer lights and then more.
        on_two_threads(|| pool.rebuild_parallel(&lights[..20_000]).unwrap());
        assert_same(&builder.build(&lights[..20_000]).unwrap(), &pool);
        on_two_threads(|| pool.rebuild_parallel(&moved).unwrap());
        assert_same(&builder.build(&moved).unwrap(), &pool);
    }

    #[test]
    fn a_parallel_build_reports_the_first_bad_light() {
        let mut lights = lights(9, 50_000);
        lights[41_234].intensity.y = f32::NAN;
        lights[45_000].position.x = f32::INFINITY;
        let one = LightTree::build(&lights).unwrap_err();
        let pool = on_two_threads(|| LightTree::build_parallel(&lights).unwrap_err());
        assert_eq!(one, BuildError::NonFiniteIntensity { index: 41_234 });
        assert_eq!(one, pool);

        let mut tree = LightTree::build(&lights[..40_000]).unwrap();
        lights[33_000].intensity.z = -1.0;
        let refit = on_two_threads(|| tree.refit_parallel(&lights[3_001..43_001]).unwrap_err());
        assert_eq!(refit, BuildError::NegativeIntensity { index: 29_999 });
    }
}
