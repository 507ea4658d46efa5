//! A node of the light hierarchy: the virtual light standing for the lights
//! below it, and the statistics the bounds read.

use core::ops::Range;

use glam::{DVec3, Vec3};

use crate::geometry::{Aabb, Cone};

/// One node of a [`LightTree`](crate::LightTree): a *virtual light*
/// standing for every light below it, with the data the bounds need.
///
/// With `w_i = max_k I_ik` the weight of light `i`
/// ([`PointLight::weight`](crate::PointLight::weight)), the node stores,
/// over its member lights `i` (positions `x_i`, RGB intensities `I_i`):
///
/// * [`intensity`](Self::intensity) `= sum_i I_i` (per channel, in `f64` so
///   that sums of lights near `f32::MAX` do not overflow);
/// * [`weight`](Self::weight) `W = sum_i w_i` (summed in `f64`, stored
///   rounded to `f32`, at most `f32::MAX`);
/// * [`centroid`](Self::centroid) `c = sum_i w_i x_i / W` rounded to `f32`
///   (the virtual light's position; the plain mean of the positions when
///   `W = 0`). Every other moment is taken about this *stored* `c`, so the
///   bounds hold for the value actually stored;
/// * [`radius`](Self::radius) `R >= max_i |x_i - c|`, rounded upward;
/// * [`channel_offsets`](Self::channel_offsets) `o_k = sum_i I_ik (x_i - c) / I_k`
///   per channel `k` (zero when `I_k = 0`): the first moment that the scalar
///   weight does not cancel when member colours differ;
/// * [`channel_covariances`](Self::channel_covariances)
///   `S_k = sum_i I_ik (x_i - c)(x_i - c)^T / I_k` per channel (zero when
///   `I_k = 0`), diagonals rounded upward;
/// * [`harmonic_norms`](Self::harmonic_norms) `q_lk` for degrees `l = 3, 4,
///   5` per channel: the norm of the node's degree-`l` multipole,
///   `q_lk^2 = sum_ij I_ik I_jk |y_i|^l |y_j|^l P_l(y^_i . y^_j) / (I_k R^l)^2`
///   with `y_i = x_i - c`, `y^_i = y_i / |y_i|` and `P_l` the Legendre
///   polynomial, rounded upward (at most 1, far less where the members'
///   multipoles cancel);
/// * [`aabb`](Self::aabb): the tight box of the members;
/// * [`moment_error`](Self::moment_error) `delta`: the build's certified
///   bound on the rounding of the `f64` first and second moment sums behind
///   `o_k` and `S_k` (each entry of `I_k o_k` within `delta I_k R` of its
///   exact value, each entry of `I_k S_k` within `delta I_k R^2`), before
///   their rounding to `f32`.
///
/// Its lights occupy a contiguous range of the tree's leaf order; its children,
/// if any, a contiguous range of the node array.
///
/// Every statistic is taken over the members as stored in the tree, so a
/// [`refit`](crate::LightTree::refit) recomputes them all.
#[derive(Clone, Copy, Debug, PartialEq)]
// In this order: what the cut reads of every node entering it (intensity,
// radius, counts and ranges, the moments' rounding bound, the centroid) in
// its first 60 bytes, which lie in one or two cache lines; the statistics
// that the children's blocks copy (see `groups`) after them.
#[repr(C)]
pub struct Node {
    pub(crate) intensity: DVec3,
    pub(crate) radius: f32,
    pub(crate) light_count: u32,
    pub(crate) first_light: u32,
    pub(crate) first_child: u32,
    pub(crate) child_count: u32,
    pub(crate) moment_error: f32,
    pub(crate) centroid: Vec3,
    pub(crate) weight: f32,
    pub(crate) aabb: Aabb,
    pub(crate) channel_offsets: [Vec3; 3],
    /// Per channel: xx, yy, zz, xy, xz, yz.
    pub(crate) channel_covariances: [[f32; 6]; 3],
    /// Per degree 3, 4, 5: the three channels' norms.
    pub(crate) harmonic_norms: [Vec3; 3],
}

impl Node {
    /// Summed RGB intensity of the member lights.
    #[inline]
    pub fn intensity(&self) -> DVec3 {
        self.intensity
    }
    /// Summed scalar weight `W` (largest channel per light), rounded to
    /// `f32` and at most `f32::MAX`.
    #[inline]
    pub fn weight(&self) -> f64 {
        f64::from(self.weight)
    }
    /// The build's bound `delta` on the rounding of the `f64` sums behind
    /// [`channel_offsets`](Self::channel_offsets) and
    /// [`channel_covariances`](Self::channel_covariances): each entry of
    /// `I_k o_k` is within `delta I_k R` of the exact sum, each entry of
    /// `I_k S_k` within `delta I_k R^2`, before the `f32` rounding
    /// (diagonals of `S_k` are rounded upward past it). On the street city
    /// of 10^6 lights: `2e-14` for the median node, `5e-13` at the root
    /// (where one `f64::EPSILON` per member light would be `2e-10`).
    #[inline]
    pub fn moment_error(&self) -> f64 {
        f64::from(self.moment_error)
    }
    /// Position of the virtual light: the weight-averaged member position.
    #[inline]
    pub fn centroid(&self) -> Vec3 {
        self.centroid
    }
    /// Radius of a ball about [`centroid`](Self::centroid) holding every member.
    #[inline]
    pub fn radius(&self) -> f32 {
        self.radius
    }
    /// Per-channel first moment about the centroid, divided by the channel's
    /// intensity: `o_k = sum_i I_ik (x_i - c) / I_k`.
    #[inline]
    pub fn channel_offsets(&self) -> [Vec3; 3] {
        self.channel_offsets
    }
    /// Per-channel second moment matrices about the centroid, each
    /// normalized by the channel's intensity, as `[xx, yy, zz, xy, xz, yz]`:
    /// `S_k = sum_i I_ik (x_i - c)(x_i - c)^T / I_k` (zero when `I_k = 0`).
    /// Diagonals are rounded upward, so each trace bounds the channel's
    /// mean squared member distance from above.
    #[inline]
    pub fn channel_covariances(&self) -> [[f32; 6]; 3] {
        self.channel_covariances
    }
    /// Traces of [`channel_covariances`](Self::channel_covariances): per
    /// channel `k`, `sum_i I_ik |x_i - c|^2 / I_k`.
    #[inline]
    pub fn mean_squared_radii(&self) -> DVec3 {
        let t = |s: &[f32; 6]| f64::from(s[0]) + f64::from(s[1]) + f64::from(s[2]);
        let s = &self.channel_covariances;
        DVec3::new(t(&s[0]), t(&s[1]), t(&s[2]))
    }
    /// Harmonic norms of the node's multipoles of degrees 3, 4 and 5
    /// (`[degree 3, degree 4, degree 5]`, each per channel), in units of
    /// `I_k R^l`: `q_lk = |sum_i I_ik R_l(x_i - c)| / (I_k R^l)` with `R_l`
    /// the `2l + 1` Schmidt semi-normalised regular solid harmonics of degree
    /// `l`. By the addition theorem of spherical harmonics
    /// `q_lk^2 R^(2l) I_k^2 = sum_ij I_ik I_jk |y_i|^l |y_j|^l P_l(y^_i . y^_j)`.
    /// Rounded upward; in `[0, 1]` up to that rounding.
    #[inline]
    pub fn harmonic_norms(&self) -> [Vec3; 3] {
        self.harmonic_norms
    }
    /// Tight axis-aligned box of the member lights.
    #[inline]
    pub fn aabb(&self) -> Aabb {
        self.aabb
    }
    /// The cone under which the node's ball is seen from `point`, or `None`
    /// when the ball reaches the point (see [`Cone::new`]): such a node has
    /// no finite bound and is always refined.
    #[inline]
    #[must_use]
    pub fn cone(&self, point: DVec3) -> Option<Cone> {
        Cone::new(point, self.centroid, self.radius)
    }
    /// Whether the node has no children (its lights are evaluated directly).
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.child_count == 0
    }
    /// Range of the node's lights in the tree's leaf order
    /// ([`LightTree::lights`](crate::LightTree::lights)).
    #[inline]
    pub fn lights(&self) -> Range<usize> {
        self.first_light as usize..(self.first_light + self.light_count) as usize
    }
    /// Number of lights below the node.
    #[inline]
    pub fn light_count(&self) -> usize {
        self.light_count as usize
    }
    /// Range of the node's children in the node array
    /// ([`LightTree::nodes`](crate::LightTree::nodes)); empty for a leaf.
    #[inline]
    pub fn children(&self) -> Range<usize> {
        self.first_child as usize..(self.first_child + self.child_count) as usize
    }
}

/// Most children of a node: the tree is an octree (a node splits into the
/// occupied sub-cells of its cell, some of them merged into one leaf, or
/// in two at a median).
pub(crate) const MAX_CHILDREN: usize = 8;
