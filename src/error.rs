//! Errors for bad input: building a tree, shading a point, validating a tree.

use thiserror::Error;

/// Why [`LightTree::build`](crate::LightTree::build) refused a set of lights.
///
/// Every case names the index of the offending light in the caller's slice.
#[derive(Clone, Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum BuildError {
    /// A coordinate of the light's position is NaN or infinite.
    #[error("light {index}: position is not finite")]
    NonFinitePosition {
        /// Index of the light in the slice given to the builder.
        index: usize,
    },
    /// A coordinate's magnitude exceeds [`PointLight::MAX_COORDINATE`](crate::PointLight::MAX_COORDINATE).
    #[error("light {index}: a coordinate exceeds the supported magnitude {max:e}")]
    PositionOutOfRange {
        /// Index of the light in the slice given to the builder.
        index: usize,
        /// The supported maximum magnitude.
        max: f32,
    },
    /// A channel of the light's intensity is NaN or infinite.
    #[error("light {index}: intensity is not finite")]
    NonFiniteIntensity {
        /// Index of the light in the slice given to the builder.
        index: usize,
    },
    /// A channel of the light's intensity is negative.
    #[error("light {index}: intensity has a negative channel")]
    NegativeIntensity {
        /// Index of the light in the slice given to the builder.
        index: usize,
    },
    /// More lights than a `u32` index can address.
    #[error("{count} lights exceed the supported maximum of {max}")]
    TooManyLights {
        /// Number of lights given.
        count: usize,
        /// The supported maximum.
        max: usize,
    },
    /// A light's [`Emission`](crate::Emission) profile is out of range.
    #[error("light {index}: emission {reason}")]
    InvalidEmission {
        /// Index of the light in the slice given to the builder.
        index: usize,
        /// What is out of range.
        reason: &'static str,
    },
    /// A builder option is out of its range.
    #[error("invalid builder option: {0}")]
    InvalidOption(&'static str),
    /// [`LightTree::refit`](crate::LightTree::refit) was given a different
    /// number of lights than the tree was built with.
    #[error("refit needs {expected} lights, as the tree was built with, got {got}")]
    LightCountMismatch {
        /// Number of lights the tree holds.
        expected: usize,
        /// Number of lights given.
        got: usize,
    },
}

/// Why a shading call refused its input.
#[derive(Clone, Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum ShadeError {
    /// A coordinate of the shading point is NaN or infinite.
    #[error("shading point is not finite")]
    NonFinitePoint,
    /// The normal is zero, NaN or infinite (any other normal, subnormal ones
    /// included, is normalized in `f64`).
    #[error("normal is zero or not finite")]
    InvalidNormal,
    /// The view direction is zero, NaN or infinite (any other view is
    /// normalized in `f64`).
    #[error("view direction is zero or not finite")]
    InvalidView,
    /// A threshold is NaN or negative.
    #[error("threshold must be a non-negative number (infinity allowed), got {0}")]
    InvalidThreshold(f64),
    /// A material parameter is NaN, infinite or negative.
    #[error("invalid material parameter: {0}")]
    InvalidMaterial(&'static str),
    /// The interpolation band must be finite and greater than 1.
    #[error("interpolation band must be finite and > 1, got {0}")]
    InvalidBand(f64),
    /// A batch call was given a results slice of another length than its
    /// queries.
    #[error("batch of {queries} queries given {results} result slots")]
    BatchLength {
        /// Number of queries.
        queries: usize,
        /// Number of result slots.
        results: usize,
    },
}

/// A broken invariant found by [`LightTree::validate`](crate::LightTree::validate).
#[derive(Clone, Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum ValidationError {
    /// A node's stored intensity differs from the sum of its children's or of
    /// its lights' beyond rounding.
    #[error("node {node}: intensity is not the sum of its members'")]
    IntensityMismatch {
        /// Offending node.
        node: usize,
    },
    /// A light of the node lies outside the node's stored sphere or box.
    #[error("node {node}: light {light} lies outside the node's stored bounds")]
    LightOutsideBounds {
        /// Offending node.
        node: usize,
        /// Index of the light in leaf order.
        light: usize,
    },
    /// The node's light range is not the union of its children's, or it has
    /// more than 8 children (an octree node has at most 8).
    #[error("node {node}: children do not partition its light range, or more than 8")]
    BadChildRange {
        /// Offending node.
        node: usize,
    },
    /// A node's stored moments do not bound its members' moments.
    #[error("node {node}: stored moments do not match its lights")]
    MomentMismatch {
        /// Offending node.
        node: usize,
    },
    /// The leaves do not cover each light exactly once, or the index map back
    /// to the caller's order is not a permutation.
    #[error("leaves do not cover each light exactly once")]
    BadCover,
    /// A stored value is NaN or infinite.
    #[error("node {node}: a stored value is not finite")]
    NonFinite {
        /// Offending node.
        node: usize,
    },
}
