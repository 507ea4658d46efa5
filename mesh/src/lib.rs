//! Shadows for [`manylights`] from a renderer's own geometry: opaque
//! triangle meshes (and boxes) in a BVH of the [`obvhs`] crate, and a
//! ready-made [`Visibility`](manylights::Visibility) host over them,
//! conservative as the crate's certified bound needs.
//!
//! ```
//! use glam::Vec3;
//! use manylights::{Lambert, LightTree, PointLight, Query, Threshold};
//! use manylights_mesh::Occluders;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // A square roof over the origin, as two triangles.
//! let positions = [
//!     Vec3::new(-1.0, -1.0, 2.0),
//!     Vec3::new(1.0, -1.0, 2.0),
//!     Vec3::new(1.0, 1.0, 2.0),
//!     Vec3::new(-1.0, 1.0, 2.0),
//! ];
//! let occluders = Occluders::from_mesh(&positions, &[0, 1, 2, 0, 2, 3])?; // shared
//! let lights: Vec<PointLight> = (0..1_000)
//!     .map(|i| PointLight::new(Vec3::new((i % 40) as f32 - 20.0, (i / 40) as f32 - 12.0, 5.0), Vec3::ONE))
//!     .collect();
//! let tree = LightTree::build(&lights)?;
//! let mut shading = tree.shading(Lambert::new(Vec3::splat(0.8)));
//! let mut host = occluders.host(); // one per thread
//! let query = Query::new(Vec3::ZERO, Vec3::Z)?;
//! let r = shading.shade_query(&query, Threshold::relative(0.01), &mut host)?;
//! assert!(r.certifies(shading.exact_query(&query, occluders.host())));
//! # Ok(())
//! # }
//! ```
//!
//! * [`Occluders`] (built with [`Occluders::builder`] from indexed meshes,
//!   triangle soups and boxes, which it checks: [`MeshError`]) is shared by
//!   reference between threads (`Send + Sync`).
//! * [`Shadows`], made by [`Occluders::host`], is one thread's host: it
//!   classifies a node's box as seen from a shading point
//!   ([`classify`](manylights::Visibility::classify)) or from a group of
//!   points ([`classify_group`](manylights::Visibility::classify_group),
//!   which lets [`Shading::shade_batch`](manylights::Shading::shade_batch)
//!   share cuts), and casts any-hit shadow rays, each past a
//!   self-intersection offset. The rays define the visibility of the
//!   model, so [`Shading::exact_query`](manylights::Shading::exact_query)
//!   with a host is the exact shadowed sum the bound is certified against.
//! * Solids ([`OccludersBuilder::solid`]): a closed mesh whose enclosed
//!   region is opaque, such as a building. The builder finds boxes inside
//!   it, box occluders that let the host prove the solid hides a node as a
//!   whole where no single triangle or quad of it does, and makes each of
//!   its connected parts one leaf of the BVH.
//! * [`shaft`]: the shafts of Haines and Wallace (1994) between a point or a
//!   box and a box.
//!
//! # Rounding
//!
//! A `Visible` or `Occluded` answer must hold for the host's own `f32` and
//! `f64` tests of every segment, so each test leaves room for the rounding
//! of the other:
//!
//! * A shadow ray tests a triangle only when its `f32` slab test meets the
//!   triangle's box grown by [`RAY_BOX_ULPS`]` f32::EPSILON` of the
//!   occluders' largest coordinate `S`. Each slab parameter is off by at
//!   most four roundings, about `4 f32::EPSILON` of the coordinates'
//!   magnitude in position along its axis, so a segment that passes
//!   through the triangle passes the slab test while its ends lie within
//!   [`BLOCKER_REACH`]` S`, and a segment that passes the slab test comes
//!   within that rounding of the grown box.
//! * `Visible`: no occluder's (grown) box meets the shaft grown by the
//!   margin, [`MARGIN_ULPS`]` f32::EPSILON` of the largest coordinate
//!   involved, which covers the slab test's rounding (`4 f32::EPSILON` per
//!   axis, twice for the segment's two ends' differences) and the shaft
//!   planes' own (a few `f32::EPSILON`, in units of each plane normal's
//!   1-norm) many times over: no segment's slab test can meet an occluder.
//! * `Visible` past a triangle that every segment leaves behind within the
//!   offset (the surface the shading point lies on): the segments' signed
//!   crossing predicates clear [`PREDICATE_SLACK`]` M^3` at every pair of
//!   corners, so no computed crossing comes past the offset (see below).
//! * `Occluded` by a box: the box shrunk by the margin meets the segments
//!   between the corners, so by convexity every segment passes at least a
//!   margin deep through the box, farther than its slab test's rounding.
//! * `Occluded` by a triangle or a quad: every predicate of the segment
//!   test (edge functions, the crossing's side of both ends) clears
//!   [`PREDICATE_SLACK`]` M^3` at every pair of corners, `M` twice the
//!   largest coordinate involved, and the apex and the node lie within
//!   [`BLOCKER_REACH`]` S`. The predicates are affine in each
//!   end, so they clear it, less twice their `f64` error (below
//!   `2^-46 M^3`), at every pair of points: every segment's computed test
//!   hits, the quad's shared edge being exactly antisymmetric.
//!
//! The crate's tests check the answers against brute-force shadow rays to
//! many points of random boxes, over triangle soups, closed meshes and
//! grids of buildings.

mod bvh;
mod error;
mod host;
mod lists;
mod occluders;
pub mod shaft;
mod solid;
mod triangle;

pub use bvh::corners;
pub use error::MeshError;
pub use host::{BATCH_CANDIDATES_MAX, BLOCKER_CANDIDATES, Shadows};
pub use lists::{CANDIDATES_MAX, GIVE_UP_CROWDED, SMALL_NODE_LIGHTS};
pub use obvhs;
pub use occluders::{
    BLOCKER_REACH, DEFAULT_OFFSET_SCALE, MARGIN_ULPS, Occluders, OccludersBuilder,
    QUAD_COPLANAR_COS, RAY_BOX_ULPS, box_mesh,
};
pub use solid::{BOXES_PER_PART, GRID_CELLS, open_edges};
pub use triangle::PREDICATE_SLACK;
