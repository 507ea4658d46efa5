//! The shading point as the shaders see it, validated once.

use glam::{DVec3, Vec3};

use crate::ShadeError;

/// The shading point, in `f64`, as the shaders see it.
///
/// Built by [`Query`](crate::Query) from the caller's `f32` values: the
/// point must be finite, the normal (and view, when given) finite and
/// non-zero; they are normalized in `f64`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Shading point `p`.
    pub point: DVec3,
    /// Unit surface normal `n`.
    pub normal: DVec3,
    /// Unit direction from `p` towards the eye, or zero when none was given
    /// (only [`ViewIndependent`](crate::ViewIndependent) shaders are shaded
    /// without a view).
    pub view: DVec3,
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
        let normal = unit(normal).ok_or(ShadeError::InvalidNormal)?;
        let view = match view {
            Some(v) => unit(v).ok_or(ShadeError::InvalidView)?,
            None => DVec3::ZERO,
        };
        Ok(Self {
            point: point.as_dvec3(),
            normal,
            view,
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
