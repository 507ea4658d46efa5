//! The exact reference: the model summed over every light.

use glam::{DVec3, Vec3};

use crate::PointLight;
use crate::geometry::Surface;
use crate::numeric::CompensatedSum;
use crate::shader::Shader;
use crate::visibility::Visibility;

/// The model (crate docs, "The model") summed over `lights` in `f64` with
/// compensated summation, asking `visibility` point-to-point for each light.
pub(crate) fn exact_sum<S: Shader, V: Visibility>(
    shader: &S,
    surface: &Surface,
    point: Vec3,
    lights: &[PointLight],
    mut visibility: V,
) -> DVec3 {
    let per_point = shader.prepare(surface);
    let mut sum = CompensatedSum::default();
    for light in lights {
        if !V::ALWAYS_VISIBLE && !visibility.visible(point, light.position) {
            continue;
        }
        sum.add(shader.eval(
            &per_point,
            surface,
            light.position.as_dvec3(),
            light.intensity.as_dvec3(),
        ));
    }
    sum.value()
}
