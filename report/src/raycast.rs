//! Primary rays through the night city: the nearest hit on the ground or a
//! building, through the BVH over the buildings.

use std::cell::Cell;

use glam::{DVec3, Vec3};

use crate::bvh::{entry_normal, slab};
use crate::camera::Camera;
use crate::scenes::{City, GROUND_ALBEDO};

/// A primary-ray hit: the shading point, its outward normal, its albedo.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Point on the surface.
    pub point: Vec3,
    /// Unit outward normal.
    pub normal: Vec3,
    /// Diffuse albedo.
    pub albedo: Vec3,
}

impl City {
    /// The nearest surface hit by the ray `origin + t * dir`, `t > 0`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
        let inv_dir = dir.recip();
        let ground_t = if dir.z < 0.0 {
            -origin.z / dir.z
        } else {
            f32::INFINITY
        };
        let nearest = Cell::new((ground_t, None::<usize>));
        self.bvh.any(
            |b| {
                let (near, far) = slab(origin, inv_dir, b);
                near <= far && far > 0.0 && near < nearest.get().0
            },
            |i| {
                let (near, far) = slab(origin, inv_dir, &self.buildings[i].bounds);
                if near <= far && near > 0.0 && near < nearest.get().0 {
                    nearest.set((near, Some(i)));
                }
                false
            },
        );
        let (t, building) = nearest.get();
        if !t.is_finite() {
            return None;
        }
        let point = origin + dir * t;
        Some(match building {
            None => Hit {
                point,
                normal: Vec3::Z,
                albedo: GROUND_ALBEDO,
            },
            Some(i) => {
                let b = &self.buildings[i];
                Hit {
                    point,
                    normal: entry_normal(origin, inv_dir, &b.bounds, dir),
                    albedo: b.albedo,
                }
            }
        })
    }

    /// Casts one primary ray per pixel of `camera`'s image: the hit of each
    /// pixel in row-major order, `None` for the sky.
    pub fn trace(&self, camera: &Camera) -> Vec<Option<Hit>> {
        camera.trace(|origin, dir| self.intersect(origin, dir))
    }
}

/// An image from per-pixel unit-albedo `values` (`None` for the sky, black),
/// each times its hit's albedo: Lambert is linear in `kd`, so this equals
/// shading with the albedo.
pub fn albedo_image(
    hits: &[Option<Hit>],
    values: impl Iterator<Item = Option<DVec3>>,
) -> Vec<DVec3> {
    hits.iter()
        .zip(values)
        .map(|(hit, v)| match (hit, v) {
            (Some(h), Some(v)) => v * h.albedo.as_dvec3(),
            _ => DVec3::ZERO,
        })
        .collect()
}
