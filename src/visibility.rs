//! Visibility: the host's Warnock-style answers about occlusion.

use glam::Vec3;

use crate::geometry::Aabb;

/// How much of a node the host sees from the shading point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Coverage {
    /// Every segment from the shading point to any point of the node's box
    /// is unoccluded: the node is used as if there were no occluders.
    Visible,
    /// Every such segment is blocked: the node contributes exactly 0.
    Occluded,
    /// Neither is certain: the node's contribution lies in `[0, unoccluded
    /// upper bound]`; it is refined, and at a leaf each light is asked
    /// point-to-point.
    Partial,
}

/// The region of space a node's lights occupy, as the cut describes it to
/// the host when it asks for a classification.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct NodeRegion {
    /// Index of the node in [`LightTree::nodes`](crate::LightTree::nodes).
    pub index: u32,
    /// Tight box of the node's lights.
    pub aabb: Aabb,
    /// The virtual light's position.
    pub centroid: Vec3,
    /// Radius of a ball about `centroid` holding every light of the node.
    pub radius: f32,
    /// Number of lights below the node.
    pub light_count: u32,
}

/// A group of shading points, as batch shading
/// ([`Shading::shade_batch`](crate::Shading::shade_batch)) describes it to the
/// host when it asks about a node for all of them at once.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct PointGroup {
    /// Tight box of the points.
    pub aabb: Aabb,
    /// Number of points.
    pub count: u32,
}

/// Occlusion answers supplied by the host renderer (its ray tracer).
///
/// # Contract
/// The crate's error bound is certified whenever the host is *conservative*:
///
/// * [`classify`](Self::classify) returns [`Coverage::Visible`] only if no
///   occluder meets any segment from `point` to any point of `node.aabb`,
///   and [`Coverage::Occluded`] only if every such segment is blocked. When
///   unsure it returns [`Coverage::Partial`], which is always correct.
/// * [`visible`](Self::visible) is the exact point-to-point visibility `V_i`
///   that the model (and its exact sum,
///   [`Shading::exact_query`](crate::Shading::exact_query)) uses, and
///   [`visible_lights`](Self::visible_lights) answers as `visible` does.
/// * [`classify_group`](Self::classify_group), for hosts that set
///   [`CLASSIFIES_GROUPS`](Self::CLASSIFIES_GROUPS), answers like `classify`
///   for every segment from any point of the group's box to any point of
///   the node's box.
/// * [`visible_fraction`](Self::visible_fraction) may be any estimate in
///   `[0, 1]`, e.g. volumetric visibility after Sillion 1995: it changes the
///   estimate of a partially occluded node, never its certified interval
///   `[0, upper]`.
///
/// A host that answers non-conservatively gets estimates, not certified
/// bounds. The methods take `&mut self` so a host can keep per-thread ray
/// caches or counters.
///
/// # Plugging in a ray tracer
///
/// A renderer makes one host per shading point from its own acceleration
/// structure. The repository's benchmark member, `manylights-report`,
/// does so in its `shadows` module over the `obvhs` BVH crate, and is the
/// recipe to copy; in words:
///
/// * [`visible`](Self::visible) is the renderer's any-hit shadow ray, from
///   the point (offset off its surface) to the light; the same function
///   defines the exact shadowed sum the bound is certified against.
/// * [`classify`](Self::classify) is a conservative shaft test (Haines and
///   Wallace 1994, "Shaft culling for efficient ray-traced radiosity")
///   between the point and the node's box. The occluders that may meet the
///   shaft (the bounding box of the point and the node's box, cut by the
///   planes through the point and the box's silhouette edges, each found in
///   the projection along one axis) are gathered, grown by a rounding
///   margin. `Visible` when there are none. `Occluded` when one of them,
///   shrunk by the margin, meets the segments from the point to all eight
///   corners of the box (the set of points whose segment meets a convex
///   occluder is convex, so the whole box is hidden). `Partial` otherwise.
/// * The cut asks about a node only after its parent answered `Partial`, and
///   casts rays to a leaf's lights right after the leaf did. So a host keeps
///   each partial node's gathered occluders, its *candidate list*, for the
///   current point: a node inside a listed box gathers from that list
///   rather than the acceleration structure (its shaft lies inside the
///   listed node's shaft), and a shadow ray to a light inside a listed box
///   tests only that list's occluders. With the margin the list holds every
///   occluder the ray's own test could hit, so the ray answers as a
///   traversal does. In the report's city a list holds about ten buildings,
///   and a shadow ray costs a few box tests instead of a traversal.
/// * [`visible_lights`](Self::visible_lights) gets the lights of a leaf
///   that answered `Partial` (those that may contribute: lit, and above
///   the shader's horizon), up to 32 at a time, before any of them is
///   evaluated: their rays share the point and the leaf's list, and a host can
///   test several of them against each listed occluder at once (the report's
///   host, four in the lanes of a vector).
/// * The cut stops asking in a call where small nodes keep answering
///   `Partial` (foliage, lattices), and a host stops keeping lists where
///   small nodes' shafts are crowded; then every light the cut needs is
///   asked point-to-point, about one shadow ray per light.
/// * [`classify_group`](Self::classify_group) is the same shaft test with
///   the group's box in place of the point: the shaft between two boxes.
///   Batch shading shares a cut between the points of a group where the
///   answers hold for the whole group and asks point-to-point for the
///   lights that stay partial.
/// * [`visible_fraction`](Self::visible_fraction) is worth its rays only
///   when partial nodes stay in the cut, that is when a budget stops it:
///   the cut refines a partial node right after asking about it.
pub trait Visibility {
    /// `true` for a host that never reports occlusion; the cut then skips
    /// every visibility call at compile time. Leave it `false`.
    const ALWAYS_VISIBLE: bool = false;

    /// Classifies `node`'s box as seen from `point`.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage;

    /// Whether the segment from `point` to a light at `light` is unoccluded.
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool;

    /// [`visible`](Self::visible) for each of `lights` from one `point`:
    /// sets `seen[i]` to `visible(point, lights[i])` (`seen` is as long as
    /// `lights`). The cut asks this way for the lights of a leaf it refines
    /// (up to 32 at a time). The default asks [`visible`](Self::visible)
    /// for each in order; a host may answer them together, e.g. testing
    /// several segments against each occluder at once, as long as every
    /// answer is the one `visible` gives.
    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        for (&light, seen) in lights.iter().zip(seen) {
            *seen = self.visible(point, light);
        }
    }

    /// `true` for a host that answers [`classify_group`](Self::classify_group):
    /// batch shading then shares cuts between neighbouring points; for
    /// other hosts (the default) it shades each point on its own.
    const CLASSIFIES_GROUPS: bool = false;

    /// Classifies `node`'s box as seen from every point of `group`:
    /// [`Coverage::Visible`] only if no occluder meets any segment from a
    /// point of `group.aabb` to a point of `node.aabb`,
    /// [`Coverage::Occluded`] only if every such segment is blocked. The
    /// default answers [`Coverage::Partial`], which is always correct.
    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        let _ = (group, node);
        Coverage::Partial
    }

    /// Optional estimate of the visible fraction of a partially occluded
    /// node, in `[0, 1]`. The default, `None`, makes the cut use the middle of
    /// the certified interval `[0, upper]`.
    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        let _ = (point, node);
        None
    }
}

/// No occluders: every node is visible. Compiles to nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unoccluded;

impl Visibility for Unoccluded {
    const ALWAYS_VISIBLE: bool = true;
    const CLASSIFIES_GROUPS: bool = true;

    #[inline(always)]
    fn classify_group(&mut self, _group: &PointGroup, _node: &NodeRegion) -> Coverage {
        Coverage::Visible
    }

    #[inline(always)]
    fn classify(&mut self, _point: Vec3, _node: &NodeRegion) -> Coverage {
        Coverage::Visible
    }

    #[inline(always)]
    fn visible(&mut self, _point: Vec3, _light: Vec3) -> bool {
        true
    }
}

impl<V: Visibility> Visibility for &mut V {
    const ALWAYS_VISIBLE: bool = V::ALWAYS_VISIBLE;
    const CLASSIFIES_GROUPS: bool = V::CLASSIFIES_GROUPS;

    #[inline]
    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        (**self).classify_group(group, node)
    }

    #[inline]
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        (**self).classify(point, node)
    }

    #[inline]
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        (**self).visible(point, light)
    }

    #[inline]
    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        (**self).visible_lights(point, lights, seen);
    }

    #[inline]
    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        (**self).visible_fraction(point, node)
    }
}
