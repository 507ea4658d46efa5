//! A pinhole camera with `+z` up.

use glam::Vec3;
use rayon::prelude::*;

/// A pinhole camera.
pub struct Camera {
    /// Position of the pinhole.
    pub eye: Vec3,
    /// Direction through the image centre.
    forward: Vec3,
    /// Half the image width at unit distance, pointing right.
    right: Vec3,
    /// Half the image height at unit distance, pointing up.
    up: Vec3,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// A camera at `eye` looking at `target` (with `+z` up) with a vertical
    /// field of view of `fov_degrees`, for a `width x height` image.
    pub fn new(eye: Vec3, target: Vec3, fov_degrees: f32, width: u32, height: u32) -> Camera {
        let forward = (target - eye).normalize();
        let half_height = (0.5 * fov_degrees.to_radians()).tan();
        let half_width = half_height * width as f32 / height as f32;
        let right = forward.cross(Vec3::Z).normalize();
        let up = right.cross(forward);
        Camera {
            eye,
            forward,
            right: right * half_width,
            up: up * half_height,
            width,
            height,
        }
    }

    /// The unit direction through the centre of pixel `(x, y)`, `y` down.
    pub fn ray(&self, x: u32, y: u32) -> Vec3 {
        let u = 2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0;
        let v = 1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32;
        (self.forward + u * self.right + v * self.up).normalize()
    }
}

impl Camera {
    /// Casts one primary ray per pixel (rows in parallel) through
    /// `intersect(eye, unit direction)`: the hit of each pixel in row-major
    /// order, `None` where the ray escapes.
    pub fn trace<H: Send>(
        &self,
        intersect: impl Fn(Vec3, Vec3) -> Option<H> + Sync,
    ) -> Vec<Option<H>> {
        (0..self.width * self.height)
            .into_par_iter()
            .map(|i| intersect(self.eye, self.ray(i % self.width, i / self.width)))
            .collect()
    }
}
