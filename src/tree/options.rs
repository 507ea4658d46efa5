//! The build's options: [`TreeBuilder`]'s fields and setters. The build
//! itself (its methods `build`, `rebuild` and their parallel forms) is in
//! [`build`](super::build); a built tree keeps the options it was built with.

/// Options for building a [`LightTree`](crate::LightTree).
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
/// small ones: fewer nodes, which makes the build faster and the tree
/// smaller (the build table of `cargo run --release -p manylights-report
/// -- bounds` prints nodes and memory per light; the repository's
/// `docs/tuning.md` records the effect on the street city). A child that
/// holds more than `max_leaf_lights` lights is always a single sub-cell.
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
/// [`Shader::horizon`](crate::shader::Shader::horizon)), and the cut settles it
/// without walking its lights. Scenes without such
/// planes store nothing for them.
///
/// With the `rayon` feature, `build_parallel` builds the same tree, bit for
/// bit, on rayon's thread pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use]
pub struct TreeBuilder {
    /// Most lights of a leaf (see [`max_leaf_lights`](Self::max_leaf_lights)).
    pub(super) max_leaf_lights: usize,
    /// Most levels below the root (see [`max_depth`](Self::max_depth)).
    pub(super) max_depth: u32,
    /// Whether oriented emitters are split by axis first (see
    /// [`group_by_axis`](Self::group_by_axis)).
    pub(super) group_by_axis: bool,
    /// Whether large nodes keep slab moments (see
    /// [`slab_moments`](Self::slab_moments)).
    pub(super) slab_moments: bool,
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
    /// Smaller leaves mean more nodes to build and store for nothing, and a
    /// slower build. Smaller leaves can still pay where the host's
    /// visibility classifications are cheap and its shadow rays dear: they
    /// classify more nodes and trace fewer rays. The build table of `cargo run --release -p
    /// manylights-report -- bounds` prints a build's time, memory and nodes
    /// per light; the repository's `docs/tuning.md` records the comparison
    /// of leaves of 16 and 32 lights.
    pub const fn new() -> Self {
        Self {
            max_leaf_lights: 32,
            max_depth: 64,
            group_by_axis: true,
            slab_moments: true,
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

    /// Whether a tree of oriented emitters
    /// ([`build_emitters`](Self::build_emitters)) first splits its lights
    /// by the dominant direction of their axes (six classes: `+x`, `-x`,
    /// `+y`, `-y`, `+z`, `-z`), and only then by position (default: yes).
    ///
    /// A node's bound on its members' emission is as tight as their axes
    /// agree: the virtual point lights on the walls and floor of a room
    /// bound far better in one subtree per surface than mixed by position,
    /// where every node near a corner holds axes a right angle apart.
    /// Lights whose axes all fall in one class (street lamps aimed down)
    /// get the tree they would get without it. The `emitters` part of
    /// `cargo run --release -p manylights-report` compares both. Trees of
    /// isotropic lights are never split by axis.
    pub const fn group_by_axis(mut self, yes: bool) -> Self {
        self.group_by_axis = yes;
        self
    }

    /// Whether each node of at least 64 isotropic lights keeps its lights'
    /// moments in 16 slices across the thinnest axis of its box (default:
    /// yes).
    ///
    /// They bound a node that a shading point's tangent plane runs through
    /// (a roof among street lamps at its height, a floor among floor-level
    /// lights) at the level its distance allows, where the node's moments
    /// alone leave the cut to walk down to the leaves; see
    /// [`Lambert`](crate::Lambert)'s docs, "Nodes the tangent plane cuts".
    /// They cost about 2.5 KiB per such node and a pass over those nodes'
    /// lights at build and refit: on the street city of 10^6 lights about
    /// 40 bytes per light, and a one-thread build about four times slower
    /// (`cargo run --release -p manylights-report -- scaling` prints a
    /// tree's build time and memory per light). Scenes whose points never
    /// have lights around their tangent plane, or that rebuild their tree
    /// every frame, can leave them out; trees of oriented emitters never
    /// keep them.
    pub const fn slab_moments(mut self, yes: bool) -> Self {
        self.slab_moments = yes;
        self
    }
}
