//! What the statistics pass notes of each node for the passes after it
//! (the planes and the blocks), from the lights it reads anyway: shared
//! bookkeeping of the build and refit, with no logic of its own.

/// The smallest and largest ratio of one channel to channel 0 over some
/// lights (see [`colour_spreads`](super::groups::colour_spreads)), each
/// computed within one rounding (`2^-53` relative) of its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct RatioRange {
    /// The smallest ratio (infinity over no lights).
    pub(super) low: f64,
    /// The largest ratio (0 over no lights).
    pub(super) high: f64,
}

impl RatioRange {
    /// The range over no lights: every ratio widens it.
    pub(super) const EMPTY: Self = Self {
        low: f64::INFINITY,
        high: 0.0,
    };
}

/// Per channel 1 and 2, the [`RatioRange`] of a node's lights.
pub(super) type Ratios = [RatioRange; 2];

/// What the statistics pass notes of each node, from the lights it reads
/// anyway (a leaf's while they are in the cache): the leaf's colour ratios
/// (see [`leaf_ratios`](super::groups::leaf_ratios)) and whether the node
/// is known to hold four lights certainly off one plane (see
/// [`certainly_not_coplanar`](super::plane::certainly_not_coplanar)): a
/// leaf's first three and last, or any child's. The passes after it would
/// otherwise read every leaf's lights again, from memory.
#[derive(Clone, Copy, Debug)]
pub(super) struct Notes {
    /// A leaf's [`leaf_ratios`](super::groups::leaf_ratios); for other
    /// nodes, set from their children's when the blocks are made.
    pub(super) ratios: Ratios,
    /// Whether four of the node's lights lie certainly off one plane.
    pub(super) off_plane: bool,
}

impl Notes {
    /// Nothing noted yet.
    pub(super) const NONE: Self = Self {
        ratios: [RatioRange::EMPTY; 2],
        off_plane: false,
    };
}
