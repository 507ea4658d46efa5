//! The shading point as the shaders see it, validated once.

use glam::{DVec3, Vec3};

use crate::ShadeError;

/// The shading point, in `f64`, as the shaders see it.
///
/// Built by [`Surface::new`] (through [`Query`](crate::Query)) from the
/// caller's `f32` values: the point must be finite, the normal (and view,
/// when given) finite and non-zero. The unit vectors are the given ones
/// normalized in `f64` (within a few ulps); the given ones are kept as well,
/// because the model normalizes them exactly and the shaders decide the
/// sign of `n . (x - p)` (and Phong's `r . (x - p)`) exactly from them.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Surface {
    /// Shading point `p` (an `f32` value, exactly).
    pub point: DVec3,
    /// Unit surface normal `n`, `given_normal` normalized in `f64`.
    pub normal: DVec3,
    /// Unit direction from `p` towards the eye, `given_view` normalized in
    /// `f64`, or zero when none was given (only
    /// [`ViewIndependent`](crate::shader::ViewIndependent) shaders are shaded
    /// without a view).
    pub view: DVec3,
    /// The caller's normal, exactly as given (any non-zero length).
    pub given_normal: Vec3,
    /// The caller's view direction, exactly as given, or zero.
    pub given_view: Vec3,
}

impl Surface {
    /// Validates and normalizes a shading point, its normal and an optional
    /// view direction.
    ///
    /// # Errors
    /// [`ShadeError::NonFinitePoint`], [`ShadeError::InvalidNormal`] (zero or
    /// non-finite), [`ShadeError::InvalidView`] (zero or non-finite).
    pub fn new(point: Vec3, normal: Vec3, view: Option<Vec3>) -> Result<Self, ShadeError> {
        if !point.is_finite() {
            return Err(ShadeError::NonFinitePoint);
        }
        let unit_normal = unit(normal).ok_or(ShadeError::InvalidNormal)?;
        let unit_view = match view {
            Some(v) => unit(v).ok_or(ShadeError::InvalidView)?,
            None => DVec3::ZERO,
        };
        Ok(Self {
            point: point.as_dvec3(),
            normal: unit_normal,
            view: unit_view,
            given_normal: normal,
            given_view: view.unwrap_or(Vec3::ZERO),
        })
    }
}

impl Surface {
    /// The same surface seen from `view` (towards the eye; normalized).
    ///
    /// # Errors
    /// [`ShadeError::InvalidView`] for a zero or non-finite view.
    pub fn with_view(self, view: Vec3) -> Result<Self, ShadeError> {
        Ok(Self {
            view: unit(view).ok_or(ShadeError::InvalidView)?,
            given_view: view,
            ..self
        })
    }
}

/// `v / |v|` in `f64`, or `None` for a zero or non-finite `v`. Any non-zero
/// finite `f32` vector, subnormal ones included, has a finite non-zero `f64`
/// length, so it normalizes exactly as well as a large one.
fn unit(v: Vec3) -> Option<DVec3> {
    let v = v.as_dvec3();
    let len = v.length();
    (len.is_finite() && len > 0.0).then(|| v / len)
}
