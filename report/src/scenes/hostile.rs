//! Scenes built to defeat a light tree: where every node near the shading
//! point straddles its tangent plane or holds the point, so that a
//! certified cut settles nothing early and walks towards the leaves. The
//! report's `hostile` part and the crate's cost tests run them.

use glam::Vec3;
use manylights::PointLight;
use rand::RngExt;

use super::rng;

/// The point among [`tilted_plane`]'s lights: in the plane.
pub const TILTED_POINT: Vec3 = Vec3::new(0.25, -0.5, 0.25);

/// `count` unit-white lights exactly in the plane `x + y + z = 0`, over a
/// square 400 units wide about the origin: coordinates are multiples of
/// `1/64`, so that `z = -(x + y)` is exact in `f32`. A point in the plane
/// ([`TILTED_POINT`]) with a normal slightly off the plane's
/// ([`tilted_normal`]) has every node at every level straddling its
/// tangent plane; with the plane's own normal the scene is exactly 0.
pub fn tilted_plane(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    (0..count)
        .map(|_| {
            let mut coordinate = || (rng.random_range(-200.0f32..200.0) * 64.0).round() / 64.0;
            let (x, y) = (coordinate(), coordinate());
            PointLight::new(Vec3::new(x, y, -(x + y)), Vec3::new(1.0, 0.8, 0.6))
        })
        .collect()
}

/// The unit normal `(1, 1, 1 + e)`: off the normal of [`tilted_plane`]'s
/// plane by about `0.47 e` radians, as smooth shading gives on a roof.
pub fn tilted_normal(e: f32) -> Vec3 {
    Vec3::new(1.0, 1.0, 1.0 + e).normalize()
}

/// The centre of [`geometric_cluster`].
pub const CLUSTER_CENTRE: Vec3 = Vec3::new(3.0, -2.0, 1.0);

/// `count` unit lights at distances `2^-k` (`k` = 0 to 39 in turn) from
/// [`CLUSTER_CENTRE`] in random directions (from a cube's): shaded at the
/// centre, every node's ball holds the point, or nearly, at every scale.
pub fn geometric_cluster(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    (0..count)
        .map(|i| {
            let k = (i % 40) as i32;
            let mut coordinate = || rng.random_range(-1.0f32..1.0);
            let direction =
                Vec3::new(coordinate(), coordinate(), coordinate()).normalize_or(Vec3::Z);
            PointLight::new(CLUSTER_CENTRE + direction * 2f32.powi(-k), Vec3::ONE)
        })
        .collect()
}

/// `count` unit lights along a logarithmic spiral about the origin, in a
/// plane but for a rise of 1% of the radius: light `i` at angle `0.01 i`
/// and radius `1e-3 e^(1.2e-4 i)`. Shaded at the pole (the origin), the
/// lights' distances span many decades and the nodes near the pole hold
/// it.
pub fn log_spiral(count: usize) -> Vec<PointLight> {
    (0..count)
        .map(|i| {
            let theta = i as f32 * 0.01;
            let r = 1e-3 * (0.012 * theta).exp();
            PointLight::new(
                Vec3::new(r * theta.cos(), r * theta.sin(), 0.01 * r),
                Vec3::ONE,
            )
        })
        .collect()
}

/// `count` unit lights over the square `[-100, 100]^2` of the ground,
/// within `1e-6` of it: points on the ground (normal up) have every node
/// straddling their tangent plane, and so has a group of them.
pub fn thin_layer(count: usize, seed: u64) -> Vec<PointLight> {
    let mut rng = rng(seed);
    (0..count)
        .map(|_| {
            let x = rng.random_range(-100.0f32..100.0);
            let y = rng.random_range(-100.0f32..100.0);
            let z = rng.random_range(-1e-6f32..1e-6);
            PointLight::new(Vec3::new(x, y, z), Vec3::ONE)
        })
        .collect()
}

/// `side^2` points on the ground among [`thin_layer`]'s lights, a quarter
/// unit apart from the origin: one tile of a camera's view.
pub fn thin_layer_points(side: usize) -> Vec<Vec3> {
    (0..side * side)
        .map(|i| Vec3::new((i % side) as f32 * 0.25, (i / side) as f32 * 0.25, 0.0))
        .collect()
}
