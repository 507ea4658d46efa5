//! [`Occluders`]: opaque triangles and boxes in a BVH, shared by every
//! thread's host, and [`OccludersBuilder`], which checks them.

use std::collections::HashMap;

use glam::{Vec3, Vec3A};
use manylights::Aabb;
use obvhs::aabb::Aabb as BvhAabb;

use crate::bvh::{Bvh, Segment, to_bvh};
use crate::error::MeshError;
use crate::host::Shadows;
use crate::solid::{open_edges, solid_parts};
use crate::triangle::crosses;

/// Triangles' boxes, as the BVH and the shafts see them, are grown by this
/// many `f32::EPSILON`s of the occluders' largest coordinate `S` (see
/// "Rounding" in the [crate documentation](crate)): a shadow ray tests a
/// triangle only when its `f32` slab test meets this box. A slab parameter
/// is off by at most four roundings of half an `f32::EPSILON`, about
/// `4 f32::EPSILON M` in position along the axis, `M` the largest
/// coordinate of the segment and the box; so a segment that passes through
/// the triangle passes the slab test whenever `M` is at most
/// `RAY_BOX_ULPS / 4` times `S`, and triangles are tried as blockers only
/// for apexes and nodes within [`BLOCKER_REACH`] times `S`.
pub const RAY_BOX_ULPS: f32 = 256.0;

/// Triangles are tried as blockers only while every coordinate of the apex
/// and the node is at most this times the occluders' largest coordinate:
/// half the reach over which the growth of the triangles' boxes
/// ([`RAY_BOX_ULPS`]) covers the slab test's rounding.
pub const BLOCKER_REACH: f32 = RAY_BOX_ULPS / 8.0;

/// The classifier's margin, in `f32::EPSILON`s of the largest coordinate
/// involved (the occluders', the apex's and the node's): shafts are grown by
/// it before an occluder is said to miss them, and occluder boxes shrunk by
/// it before one is said to block a node. It covers the rounding of the
/// `f32` slab tests of the shadow rays (about `4 f32::EPSILON` of that
/// magnitude) and of a shaft plane's dot products with a box's corners
/// (about `4 f32::EPSILON`, in units of the plane normal's 1-norm), twice.
pub const MARGIN_ULPS: f32 = 64.0;

/// The default self-intersection offset, as a fraction of the occluders'
/// largest coordinate (`2^-13`, about a thousand `f32` ulps of it): a
/// shadow ray ignores what it meets closer than the offset to the shading
/// point, such as the surface the point lies on, whose position a renderer
/// knows to a few ulps of its coordinates (more along grazing primary
/// rays).
pub const DEFAULT_OFFSET_SCALE: f32 = 1.0 / 8192.0;

/// Two triangles that share an edge make one quad blocker (see
/// [`Occluders`]) when their unit normals' dot product is at least this:
/// nearly coplanar, as the two halves of a rectangle are. The pairing only
/// helps a quad block a node as a whole; the blocker test checks each
/// triangle's own plane, so no value of it can make an answer wrong.
pub const QUAD_COPLANAR_COS: f64 = 0.9999;

/// The closed surface of the box `b` as an indexed mesh: its eight corners
/// (as [`corners`](crate::corners) orders them) and twelve triangles wound
/// outwards, each face two triangles sharing a diagonal (paired into a
/// quad by [`OccludersBuilder::build`]).
pub fn box_mesh(b: &Aabb) -> ([Vec3; 8], [u32; 36]) {
    // Corner k takes the maximum on axis a where bit a of k is set.
    const FACES: [[u32; 4]; 6] = [
        [0, 2, 6, 4], // -x
        [1, 5, 7, 3], // +x
        [0, 4, 5, 1], // -y
        [2, 3, 7, 6], // +y
        [0, 1, 3, 2], // -z
        [4, 6, 7, 5], // +z
    ];
    let indices = std::array::from_fn(|i| {
        let f = FACES[i / 6];
        [f[0], f[1], f[2], f[0], f[2], f[3]][i % 6]
    });
    (crate::corners(b), indices)
}

/// No partner triangle.
pub(crate) const NO_PARTNER: u32 = u32::MAX;

/// One occluder, in the BVH's leaf order.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Prim {
    /// A triangle, and the slot of the triangle it makes a quad with
    /// ([`NO_PARTNER`] if none), and which of its edges (`bc`, `ca`, `ab`)
    /// it shares with that partner.
    Triangle {
        v: [Vec3; 3],
        partner: u32,
        shared: [bool; 3],
    },
    /// The box in the same slot of `Occluders::bounds`.
    Box,
    /// A connected part of a solid, one leaf of the BVH (its slot's bounds
    /// hold its members'): its members, boxes first, then triangles, are
    /// the slots `first..end`, none of them a part.
    Part { first: u32, end: u32 },
}

/// Opaque occluders, triangles and axis-aligned boxes, in a BVH of the
/// `obvhs` crate: what every thread's [`Shadows`] host tests shafts and
/// shadow rays against. `Send + Sync`: build it once, share it by
/// reference, and make one host per thread or per batch with
/// [`host`](Self::host).
///
/// Triangles are two-sided. Two triangles that share an edge (with
/// opposite directions, as consistently wound neighbours do) and are
/// nearly coplanar are paired into a *quad*, which the classifier tries as
/// a single blocker: the two halves of a rectangular wall block a node
/// behind the wall together even where neither does alone.
#[derive(Clone, Debug)]
pub struct Occluders {
    /// Per slot, the box a shadow ray's slab test and the shafts see: a
    /// box occluder itself, a triangle's box grown by [`RAY_BOX_ULPS`].
    pub(crate) bounds: Vec<BvhAabb>,
    pub(crate) prims: Vec<Prim>,
    pub(crate) bvh: Bvh,
    /// Largest absolute coordinate of the occluders.
    pub(crate) scale: f32,
    /// The self-intersection offset.
    pub(crate) offset: f32,
    triangles: usize,
    boxes: usize,
    solid_boxes: Vec<Aabb>,
    degenerate: usize,
    quads: usize,
}

/// Collects meshes and boxes, checks them, and builds [`Occluders`].
#[derive(Clone, Debug, Default)]
pub struct OccludersBuilder {
    triangles: Vec<[Vec3; 3]>,
    boxes: Vec<Aabb>,
    /// The triangles of the solids, degenerate ones included.
    solids: Vec<[Vec3; 3]>,
    meshes: usize,
    offset: Option<f32>,
    degenerate: usize,
}

impl OccludersBuilder {
    /// Adds an indexed triangle mesh: `indices` in threes, each an index
    /// into `positions`. Errors on a non-finite position, an index out of
    /// range, a number of indices that is not a multiple of 3, or a mesh
    /// without triangles; triangles of zero area (collinear or repeated
    /// vertices) block no segment and are dropped, counted by
    /// [`Occluders::degenerate`].
    pub fn mesh(mut self, positions: &[Vec3], indices: &[u32]) -> Result<Self, MeshError> {
        self.check_mesh(positions, indices)?;
        for t in indices.chunks_exact(3) {
            let v = [0, 1, 2].map(|k| positions[t[k] as usize]);
            self.push_triangle(v);
        }
        Ok(self)
    }

    /// Counts a mesh and checks it (see [`mesh`](Self::mesh)): its number.
    fn check_mesh(&mut self, positions: &[Vec3], indices: &[u32]) -> Result<usize, MeshError> {
        let mesh = self.meshes;
        self.meshes += 1;
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinite { mesh, vertex });
        }
        if !indices.len().is_multiple_of(3) {
            return Err(MeshError::IndicesNotTriangles {
                mesh,
                len: indices.len(),
            });
        }
        if indices.is_empty() {
            return Err(MeshError::EmptyMesh { mesh });
        }
        if let Some(&index) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(MeshError::IndexOutOfRange {
                mesh,
                index,
                vertices: positions.len(),
            });
        }
        Ok(mesh)
    }

    /// Adds a *solid*: a closed indexed triangle mesh whose enclosed region
    /// is opaque, such as a building, a rock or a statue. Its triangles are
    /// added as [`mesh`](Self::mesh) adds them, and [`build`](Self::build)
    /// adds boxes found inside the enclosed region as box occluders (see
    /// [`Occluders::solid_boxes`]): the classifier can then prove that the
    /// solid hides a node as a whole, which no single triangle of it shows.
    ///
    /// Closed means that every edge, over vertices identified by position
    /// (so that a mesh split at its creases still counts), is traversed as
    /// often in each direction; the enclosed region is where the surface's
    /// winding number is not zero, whichever way it is wound. The boxes lie
    /// inside that region, at least the *inset* `2 offset + 2 m` from the
    /// surface (`m` the classifier's margin at the occluders' scale,
    /// [`MARGIN_ULPS`]` f32::EPSILON`[`scale`](Occluders::scale)), so that a
    /// point on the surface sees past them what it sees past the surface.
    ///
    /// The boxes join the model: a shadow ray that meets one is blocked.
    /// For a segment from outside the solid this changes nothing, as it
    /// crosses the surface on its way in; a shading point inside the solid
    /// (a room modelled as a closed box, seen from within) should be given
    /// as a [`mesh`](Self::mesh) instead.
    ///
    /// Errors as [`mesh`](Self::mesh) does, and with
    /// [`MeshError::NotClosed`] on a mesh that is not closed.
    pub fn solid(mut self, positions: &[Vec3], indices: &[u32]) -> Result<Self, MeshError> {
        let mesh = self.check_mesh(positions, indices)?;
        let triangles: Vec<[Vec3; 3]> = indices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| positions[t[k] as usize]))
            .collect();
        let open_edges = open_edges(&triangles);
        if open_edges > 0 {
            return Err(MeshError::NotClosed { mesh, open_edges });
        }
        self.solids.extend(triangles);
        Ok(self)
    }

    /// Adds triangles given by their corners (a triangle soup): errors on a
    /// non-finite corner or an empty slice; drops triangles of zero area as
    /// [`mesh`](Self::mesh) does.
    pub fn triangles(mut self, triangles: &[[Vec3; 3]]) -> Result<Self, MeshError> {
        let mesh = self.meshes;
        self.meshes += 1;
        if triangles.is_empty() {
            return Err(MeshError::EmptyMesh { mesh });
        }
        if let Some(k) = triangles
            .iter()
            .position(|t| !t.iter().all(|p| p.is_finite()))
        {
            return Err(MeshError::NonFinite {
                mesh,
                vertex: 3 * k,
            });
        }
        for &t in triangles {
            self.push_triangle(t);
        }
        Ok(self)
    }

    /// Adds opaque axis-aligned boxes (solid: a segment that meets a box
    /// anywhere, inside included, is blocked). Errors on a non-finite box
    /// or one with `min > max` on some axis.
    pub fn boxes(mut self, boxes: &[Aabb]) -> Result<Self, MeshError> {
        for (index, b) in boxes.iter().enumerate() {
            if !(b.min.is_finite() && b.max.is_finite() && b.min.cmple(b.max).all()) {
                return Err(MeshError::BadBox { index });
            }
        }
        self.boxes.extend_from_slice(boxes);
        Ok(self)
    }

    /// Sets the self-intersection offset (see [`Shadows`]): a shadow ray
    /// ignores occluders closer than `offset` to the shading point. The
    /// default is [`DEFAULT_OFFSET_SCALE`] times the occluders' largest
    /// coordinate. Errors on a negative or non-finite offset.
    pub fn offset(mut self, offset: f32) -> Result<Self, MeshError> {
        if !(offset >= 0.0 && offset.is_finite()) {
            return Err(MeshError::BadOffset(offset));
        }
        self.offset = Some(offset);
        Ok(self)
    }

    /// Keeps a triangle unless its area is zero (in `f64`, where the cross
    /// product of two edges of `f32` corners is exact but for a final
    /// rounding or two).
    fn push_triangle(&mut self, v: [Vec3; 3]) {
        let [a, b, c] = v.map(Vec3::as_dvec3);
        if (b - a).cross(c - a) == glam::DVec3::ZERO {
            self.degenerate += 1;
        } else {
            self.triangles.push(v);
        }
    }

    /// The occluders in their BVH. An empty set (no mesh, no box) is valid:
    /// its hosts see everything.
    pub fn build(self) -> Occluders {
        let scale = self
            .triangles
            .iter()
            .chain(&self.solids)
            .flatten()
            .chain(self.boxes.iter().flat_map(|b| [&b.min, &b.max]))
            .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let offset = self.offset.unwrap_or(DEFAULT_OFFSET_SCALE * scale);
        let inset = 2.0 * f64::from(offset) + 2.0 * f64::from(MARGIN_ULPS * f32::EPSILON * scale);
        let parts = if self.solids.is_empty() {
            Vec::new()
        } else {
            solid_parts(&self.solids, inset)
        };
        let grow = RAY_BOX_ULPS * f32::EPSILON * scale;
        let triangle_box = |t: &[Vec3; 3]| {
            let (min, max) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
            BvhAabb::new(Vec3A::from(min) - grow, Vec3A::from(max) + grow)
        };
        // The BVH's leaves: the loose triangles, the boxes given, and one
        // leaf per part of a solid (the union of its members' boxes).
        let mut bounds: Vec<BvhAabb> = self.triangles.iter().map(triangle_box).collect();
        bounds.extend(self.boxes.iter().map(to_bvh));
        for part in &parts {
            let mut b = BvhAabb::empty();
            for t in &part.triangles {
                b = b.union(&triangle_box(t));
            }
            for x in &part.boxes {
                b = b.union(&to_bvh(x));
            }
            bounds.push(b);
        }
        let partners = pair_quads(&self.triangles);
        let (bvh, order) = Bvh::new(&bounds);
        let mut slot_of = vec![0u32; order.len()];
        for (slot, &input) in order.iter().enumerate() {
            slot_of[input as usize] = slot as u32;
        }
        let (tri_count, box_count) = (self.triangles.len(), self.boxes.len());
        // The parts' members take the slots after the leaves': a part's
        // boxes, then its triangles.
        let mut member_bounds = Vec::new();
        let mut members = Vec::new();
        let mut ranges = Vec::with_capacity(parts.len());
        let mut quads = partners.iter().flatten().count() / 2;
        for part in &parts {
            let first = order.len() + members.len();
            for x in &part.boxes {
                member_bounds.push(to_bvh(x));
                members.push(Prim::Box);
            }
            let base = order.len() + members.len();
            let pairs = pair_quads(&part.triangles);
            quads += pairs.iter().flatten().count() / 2;
            for (t, pair) in part.triangles.iter().zip(&pairs) {
                let (partner, shared) = match *pair {
                    Some((other, edge)) => {
                        let mut shared = [false; 3];
                        shared[edge] = true;
                        ((base + other) as u32, shared)
                    }
                    None => (NO_PARTNER, [false; 3]),
                };
                member_bounds.push(triangle_box(t));
                members.push(Prim::Triangle {
                    v: *t,
                    partner,
                    shared,
                });
            }
            ranges.push((first as u32, (order.len() + members.len()) as u32));
        }
        let mut prims: Vec<Prim> = order
            .iter()
            .map(|&input| {
                let input = input as usize;
                if input < tri_count {
                    let (partner, shared) = match partners[input] {
                        Some((other, edge)) => {
                            let mut shared = [false; 3];
                            shared[edge] = true;
                            (slot_of[other], shared)
                        }
                        None => (NO_PARTNER, [false; 3]),
                    };
                    Prim::Triangle {
                        v: self.triangles[input],
                        partner,
                        shared,
                    }
                } else if input < tri_count + box_count {
                    Prim::Box
                } else {
                    let (first, end) = ranges[input - tri_count - box_count];
                    Prim::Part { first, end }
                }
            })
            .collect();
        prims.extend(members);
        let mut bounds: Vec<BvhAabb> = order.iter().map(|&i| bounds[i as usize]).collect();
        bounds.extend(member_bounds);
        let solid_boxes: Vec<Aabb> = parts.iter().flat_map(|p| p.boxes.iter().copied()).collect();
        let part_triangles: usize = parts.iter().map(|p| p.triangles.len()).sum();
        Occluders {
            bounds,
            prims,
            bvh,
            scale,
            offset,
            triangles: tri_count + part_triangles,
            boxes: box_count + solid_boxes.len(),
            solid_boxes,
            degenerate: self.degenerate + parts.iter().map(|p| p.degenerate).sum::<usize>(),
            quads,
        }
    }
}

/// For each triangle, the neighbour it makes a quad with and the index of
/// the shared edge in its own order (`bc`, `ca`, `ab`): neighbours across
/// an edge with opposite direction whose unit normals' dot product is at
/// least [`QUAD_COPLANAR_COS`], paired greedily in input order.
fn pair_quads(triangles: &[[Vec3; 3]]) -> Vec<Option<(usize, usize)>> {
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    // Edge `k` of a triangle runs from vertex `k + 1` to vertex `k + 2`.
    let edge = |t: &[Vec3; 3], k: usize| (key(t[(k + 1) % 3]), key(t[(k + 2) % 3]));
    let mut edges = HashMap::with_capacity(3 * triangles.len());
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            edges.entry(edge(t, k)).or_insert((i, k));
        }
    }
    let normal = |t: &[Vec3; 3]| {
        let [a, b, c] = t.map(Vec3::as_dvec3);
        (b - a).cross(c - a).normalize()
    };
    let mut partners = vec![None; triangles.len()];
    for (i, t) in triangles.iter().enumerate() {
        if partners[i].is_some() {
            continue;
        }
        for k in 0..3 {
            let (from, to) = edge(t, k);
            let Some(&(j, l)) = edges.get(&(to, from)) else {
                continue;
            };
            if j != i
                && partners[j].is_none()
                && normal(t).dot(normal(&triangles[j])) >= QUAD_COPLANAR_COS
            {
                partners[i] = Some((j, k));
                partners[j] = Some((i, l));
                break;
            }
        }
    }
    partners
}

impl Occluders {
    /// A builder: add meshes, triangles and boxes, then
    /// [`build`](OccludersBuilder::build).
    pub fn builder() -> OccludersBuilder {
        OccludersBuilder::default()
    }

    /// The occluders of one indexed triangle mesh (see
    /// [`OccludersBuilder::mesh`]).
    pub fn from_mesh(positions: &[Vec3], indices: &[u32]) -> Result<Self, MeshError> {
        Ok(Self::builder().mesh(positions, indices)?.build())
    }

    /// A host for one thread (or one batch call): classifications and
    /// shadow rays against these occluders, with scratch space of its own.
    /// Cheap: it allocates nothing until it keeps candidate lists.
    pub fn host(&self) -> Shadows<'_> {
        Shadows::new(self)
    }

    /// Triangles kept (degenerate ones dropped).
    pub fn triangles(&self) -> usize {
        self.triangles
    }

    /// Box occluders, those found inside solids included.
    pub fn boxes(&self) -> usize {
        self.boxes
    }

    /// The box occluders found inside solids (see
    /// [`OccludersBuilder::solid`]).
    pub fn solid_boxes(&self) -> &[Aabb] {
        &self.solid_boxes
    }

    /// Triangles dropped for their zero area.
    pub fn degenerate(&self) -> usize {
        self.degenerate
    }

    /// Pairs of triangles tried as quad blockers.
    pub fn quads(&self) -> usize {
        self.quads
    }

    /// Whether there are no occluders.
    pub fn is_empty(&self) -> bool {
        self.prims.is_empty()
    }

    /// The self-intersection offset: a shadow ray ignores occluders closer
    /// than this to the shading point.
    pub fn offset(&self) -> f32 {
        self.offset
    }

    /// The largest absolute coordinate of the occluders: the magnitude the
    /// rounding margins scale with.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Whether some occluder blocks the segment from `from` to `to`, past
    /// the offset: the host's shadow ray (see [`Shadows`]), an any-hit
    /// traversal of the BVH.
    pub fn blocked(&self, from: Vec3, to: Vec3) -> bool {
        let Some((segment, t_min)) = self.shadow_ray(from, to) else {
            return false;
        };
        self.bvh
            .any_along(&segment, |slot| self.hits(slot, &segment, from, to, t_min))
    }

    /// The segment of a shadow ray from `from` to `to`, and the parameter
    /// the offset reaches along it; `None` for a segment of zero or
    /// non-finite length, which nothing blocks.
    #[inline]
    fn shadow_ray(&self, from: Vec3, to: Vec3) -> Option<(Segment, f64)> {
        let length = (to.as_dvec3() - from.as_dvec3()).length();
        (length != 0.0 && length.is_finite())
            .then(|| (Segment::new(from, to), f64::from(self.offset) / length))
    }

    /// [`blocked`](Self::blocked), testing only the occluders in `slots`
    /// (which must hold every one whose box the segment's slab test may
    /// meet) instead of traversing the BVH.
    pub(crate) fn blocked_by(&self, slots: &[u32], from: Vec3, to: Vec3) -> bool {
        let Some((segment, t_min)) = self.shadow_ray(from, to) else {
            return false;
        };
        slots
            .iter()
            .any(|&slot| self.hits(slot as usize, &segment, from, to, t_min))
    }

    /// The position in `slots` of the first occluder that blocks the
    /// segment from `from` to `to` (as [`blocked`](Self::blocked) tests
    /// it), if one does.
    #[inline]
    pub(crate) fn blocker_in(&self, slots: &[u32], from: Vec3, to: Vec3) -> Option<usize> {
        let (segment, t_min) = self.shadow_ray(from, to)?;
        slots
            .iter()
            .position(|&slot| self.hits(slot as usize, &segment, from, to, t_min))
    }

    /// Whether the shadow ray `segment` (from `from` to `to`, hits counted
    /// from parameter `t_min`) meets the occluder in `slot`.
    #[inline]
    pub(crate) fn hits(
        &self,
        slot: usize,
        segment: &Segment,
        from: Vec3,
        to: Vec3,
        t_min: f64,
    ) -> bool {
        match self.prims[slot] {
            Prim::Part { first, end } => {
                segment.hits(&self.bounds[slot])
                    && (first as usize..end as usize)
                        .any(|m| self.hits_one(m, segment, from, to, t_min))
            }
            _ => self.hits_one(slot, segment, from, to, t_min),
        }
    }

    /// [`hits`](Self::hits) for a box or a triangle (not a part).
    #[inline]
    pub(crate) fn hits_one(
        &self,
        slot: usize,
        segment: &Segment,
        from: Vec3,
        to: Vec3,
        t_min: f64,
    ) -> bool {
        let b = &self.bounds[slot];
        match self.prims[slot] {
            Prim::Triangle { ref v, .. } => segment.hits(b) && crosses(from, to, t_min, v),
            _ => segment.hits_from(b, t_min as f32),
        }
    }
}
