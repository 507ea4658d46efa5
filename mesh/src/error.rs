//! The errors of building occluders.

use thiserror::Error;

/// What was wrong with the occluders given to
/// [`OccludersBuilder`](crate::OccludersBuilder).
#[derive(Clone, Copy, Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum MeshError {
    /// A vertex (or a triangle's corner) has a NaN or infinite coordinate.
    #[error("mesh {mesh}: vertex {vertex} is not finite")]
    NonFinite {
        /// The mesh, counted from 0 in the order added.
        mesh: usize,
        /// The vertex (for a triangle soup, three times the triangle).
        vertex: usize,
    },
    /// An index points past the mesh's positions.
    #[error("mesh {mesh}: index {index} out of range ({vertices} vertices)")]
    IndexOutOfRange {
        /// The mesh.
        mesh: usize,
        /// The index.
        index: u32,
        /// Number of positions.
        vertices: usize,
    },
    /// The number of indices is not a multiple of 3.
    #[error("mesh {mesh}: {len} indices do not make whole triangles")]
    IndicesNotTriangles {
        /// The mesh.
        mesh: usize,
        /// Number of indices.
        len: usize,
    },
    /// A mesh without triangles.
    #[error("mesh {mesh} has no triangles")]
    EmptyMesh {
        /// The mesh.
        mesh: usize,
    },
    /// A box with a non-finite bound or `min > max` on some axis.
    #[error("box {index} is not finite or has min > max")]
    BadBox {
        /// The box, counted from 0 over all boxes added in one call.
        index: usize,
    },
    /// A mesh given as a solid is not closed: some edges (over vertices
    /// identified by position) are traversed more often in one direction
    /// than in the other, so it encloses no region.
    #[error("mesh {mesh} is not closed: {open_edges} edges lack their reverse")]
    NotClosed {
        /// The mesh.
        mesh: usize,
        /// Edges without a balancing reverse.
        open_edges: usize,
    },
    /// A negative or non-finite self-intersection offset.
    #[error("offset {0} is not a finite non-negative distance")]
    BadOffset(f32),
}
