//! The per-point query: what varies from one shading point to the next,
//! validated once where it is built.

use core::marker::PhantomData;

use glam::Vec3;

use crate::ShadeError;
use crate::geometry::Surface;
use crate::shader::{Shader, ViewIndependent};

/// Marks a [`Query`] built without a view direction: only
/// [`ViewIndependent`] shaders accept it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoView {}

/// Marks a [`Query`] that carries a view direction: every shader accepts it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WithView {}

/// One shading point: its position, normal and (for view-dependent shaders)
/// view direction, checked and normalized once.
///
/// ```
/// use glam::Vec3;
/// use manylights::Query;
///
/// let diffuse = Query::new(Vec3::ZERO, Vec3::Z)?;
/// let glossy = Query::new(Vec3::ZERO, Vec3::Z)?.with_view(Vec3::new(1.0, 0.0, 1.0))?;
/// assert!(Query::new(Vec3::ZERO, Vec3::ZERO).is_err());
/// # Ok::<(), manylights::ShadeError>(())
/// ```
///
/// Whether the query has a view is part of its type (`Query<NoView>` or
/// `Query<WithView>`), so passing a view-less query to a view-dependent
/// shader such as [`Phong`](crate::Phong) does not compile:
///
/// ```compile_fail
/// use glam::Vec3;
/// use manylights::{LightTree, Phong, PointLight, Query, Threshold, Unoccluded};
///
/// let tree = LightTree::build(&[PointLight::new(Vec3::Z, Vec3::ONE)]).unwrap();
/// let mut shading = tree.shading(Phong::new(Vec3::ONE, 10.0));
/// let query = Query::new(Vec3::ZERO, Vec3::Z).unwrap();
/// shading.shade_query(&query, Threshold::relative(0.01), Unoccluded); // needs .with_view(..)
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Query<M = NoView> {
    point: Vec3,
    surface: Surface,
    mode: PhantomData<M>,
}

impl Query<NoView> {
    /// A shading point with its normal (any non-zero finite length; it is
    /// normalized in `f64`).
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`] (zero,
    /// NaN or infinite normal).
    pub fn new(point: Vec3, normal: Vec3) -> Result<Self, ShadeError> {
        Ok(Self {
            point,
            surface: Surface::new(point, normal, None)?,
            mode: PhantomData,
        })
    }

    /// The same point seen from `view`, the direction from the point towards
    /// the eye (any non-zero finite length).
    ///
    /// # Errors
    /// [`ShadeError::InvalidView`] for a zero, NaN or infinite view.
    pub fn with_view(self, view: Vec3) -> Result<Query<WithView>, ShadeError> {
        Ok(Query {
            point: self.point,
            surface: self.surface.with_view(view)?,
            mode: PhantomData,
        })
    }
}

impl<M> Query<M> {
    /// The shading point as given.
    #[must_use]
    pub fn point(&self) -> Vec3 {
        self.point
    }

    /// The point, unit normal and unit view (zero without one) in `f64`, as
    /// the shaders see them.
    #[must_use]
    pub fn surface(&self) -> &Surface {
        &self.surface
    }
}

/// Which queries a shader accepts: every shader a [`Query<WithView>`], only
/// [`ViewIndependent`] ones a [`Query<NoView>`].
#[diagnostic::on_unimplemented(
    message = "`{Self}` depends on the view direction, and this query has none",
    label = "needs a query built with `Query::new(point, normal)?.with_view(view)?`"
)]
pub trait Accepts<M>: Shader {}

impl<S: Shader> Accepts<WithView> for S {}

impl<S: ViewIndependent> Accepts<NoView> for S {}
