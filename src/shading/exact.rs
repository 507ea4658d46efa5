//! The exact reference: the model summed over every light.

use glam::{DVec3, Vec3};

use crate::geometry::Surface;
use crate::numeric::CompensatedSum;
use crate::shader::Shader;
use crate::tree::LightTree;
use crate::visibility::Visibility;

/// The model (crate docs, "The model") summed over the lights of `tree`
/// in `f64` with compensated summation, asking `visibility` point-to-point
/// for each light: each light's term times its emission profile's value.
pub(crate) fn exact_sum<S: Shader, V: Visibility>(
    shader: &S,
    surface: &Surface,
    point: Vec3,
    tree: &LightTree,
    mut visibility: V,
) -> DVec3 {
    let per_point = shader.prepare(surface);
    let mut sum = CompensatedSum::default();
    for (i, light) in tree.lights.iter().enumerate() {
        if !V::ALWAYS_VISIBLE && !visibility.visible(point, light.position) {
            continue;
        }
        let term = shader.eval(
            &per_point,
            surface,
            light.position.as_dvec3(),
            light.intensity.as_dvec3(),
        );
        sum.add(if tree.is_oriented() {
            term * tree.profile(i).factor(light.position, surface.point)
        } else {
            term
        });
    }
    sum.value()
}
