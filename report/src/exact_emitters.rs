//! The exact sum of Lambert's model over emitters (isotropic lights,
//! cosine lobes of exponent 1, glTF spots; one- or two-sided), written to
//! vectorize as [`SoaLights`](crate::exact::SoaLights) is: structure of
//! arrays in `f32`, chunks of [`LANES`] lights with no data-dependent
//! branch (each profile's value is a select), lane sums flushed to `f64`
//! every 128 chunks, and a copy compiled for AVX2 picked at run
//! time. It is the yardstick the `emitters` part of the report times the
//! tree against; it agrees with the crate's `f64` `exact_query` to about
//! `1e-5` relative (checked there).
//!
//! Cosine lobes other than `k = 1` (a diffuse virtual point light) would
//! need `powf`, which does not vectorize; the scenes measured use `k = 1`,
//! and [`SoaEmitters::new`] refuses others.

use glam::{DVec3, Vec3};
use manylights::{Emission, Emitter};

/// Lights per chunk.
pub const LANES: usize = 8;
/// Chunks accumulated in `f32` before the lane sums join the `f64` total.
const FLUSH_CHUNKS: usize = 128;
/// `1 / (cos_inner - cos_outer)` of a spot with a hard edge: large enough
/// that the ramp is a step at `f32` precision, finite so that it never
/// makes a NaN.
const HARD_EDGE: f32 = 1e30;

type Lanes = [f32; LANES];

/// [`LANES`] emitters as structure of arrays.
#[derive(Clone, Copy, Debug, Default)]
struct Chunk {
    position: [Lanes; 3],
    intensity: [Lanes; 3],
    /// Unit axis (zero for an isotropic light).
    axis: [Lanes; 3],
    /// 1 for an isotropic light, else 0.
    isotropic: Lanes,
    /// 1 for a cosine lobe, else 0.
    lobe: Lanes,
    /// 1 for a spot, else 0.
    spot: Lanes,
    /// 1 for a two-sided profile, else 0.
    two_sided: Lanes,
    /// A spot's `cos(outer_angle)`.
    cos_outer: Lanes,
    /// A spot's `1 / (cos(inner_angle) - cos(outer_angle))`.
    inv_ramp: Lanes,
}

/// Emitters as structure of arrays in chunks of [`LANES`].
#[derive(Clone, Debug)]
pub struct SoaEmitters {
    chunks: Vec<Chunk>,
}

impl SoaEmitters {
    /// Converts `emitters` (any order); `None` for a cosine lobe whose
    /// exponent is not 1.
    pub fn new(emitters: &[Emitter]) -> Option<Self> {
        let mut chunks = vec![Chunk::default(); emitters.len().div_ceil(LANES)];
        for (i, e) in emitters.iter().enumerate() {
            let (c, l) = (&mut chunks[i / LANES], i % LANES);
            for k in 0..3 {
                c.position[k][l] = e.light.position[k];
                c.intensity[k][l] = e.light.intensity[k];
            }
            let (axis, two) = match e.emission {
                Emission::Isotropic => {
                    c.isotropic[l] = 1.0;
                    (Vec3::ZERO, false)
                }
                Emission::Cosine {
                    axis,
                    exponent,
                    two_sided,
                } => {
                    if exponent != 1.0 {
                        return None;
                    }
                    c.lobe[l] = 1.0;
                    (axis, two_sided)
                }
                Emission::Spot {
                    axis,
                    inner_angle,
                    outer_angle,
                    two_sided,
                } => {
                    c.spot[l] = 1.0;
                    let (co, ci) = (
                        f64::from(outer_angle).cos() as f32,
                        f64::from(inner_angle).cos() as f32,
                    );
                    c.cos_outer[l] = co;
                    c.inv_ramp[l] = if ci > co { 1.0 / (ci - co) } else { HARD_EDGE };
                    (axis, two_sided)
                }
                _ => return None,
            };
            let axis = axis.normalize_or_zero();
            for k in 0..3 {
                c.axis[k][l] = axis[k];
            }
            c.two_sided[l] = if two { 1.0 } else { 0.0 };
        }
        Some(Self { chunks })
    }

    /// Lambert's exact radiance (albedo `kd`) at `point` with unit `normal`,
    /// each light's term times its profile's value.
    #[allow(unsafe_code)]
    pub fn shade(&self, kd: Vec3, point: Vec3, normal: Vec3) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked just above).
            return unsafe { self.sum_avx2(kd, point, normal) };
        }
        self.sum_body(kd, point, normal)
    }

    /// [`sum_body`](Self::sum_body) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sum_avx2(&self, kd: Vec3, point: Vec3, normal: Vec3) -> DVec3 {
        self.sum_body(kd, point, normal)
    }

    #[inline(always)]
    fn sum_body(&self, kd: Vec3, point: Vec3, normal: Vec3) -> DVec3 {
        let mut total = DVec3::ZERO;
        for block in self.chunks.chunks(FLUSH_CHUNKS) {
            let mut acc = [[0.0f32; LANES]; 3];
            for c in block {
                chunk(point, normal, c, &mut acc);
            }
            let lane_sum = |a: &Lanes| a.iter().map(|&v| f64::from(v)).sum::<f64>();
            total += DVec3::new(lane_sum(&acc[0]), lane_sum(&acc[1]), lane_sum(&acc[2]));
        }
        total * kd.as_dvec3()
    }
}

/// One chunk added to the lane accumulators, every statement lane-wise
/// (indexed loops over fixed-size arrays, which the compiler vectorizes).
#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn chunk(p: Vec3, n: Vec3, c: &Chunk, acc: &mut [Lanes; 3]) {
    let mut weight = [0.0f32; LANES];
    for l in 0..LANES {
        let dx = c.position[0][l] - p.x;
        let dy = c.position[1][l] - p.y;
        let dz = c.position[2][l] - p.z;
        let d2 = dx * dx + dy * dy + dz * dz;
        let inv_d = if d2 > 0.0 { 1.0 / d2.sqrt() } else { 0.0 };
        let height = n.x * dx + n.y * dy + n.z * dz;
        let lambert = height.max(0.0) * inv_d * inv_d * inv_d;
        // The cosine at the light between its axis and the direction to
        // the point (from the light: minus the offset).
        let along = -(c.axis[0][l] * dx + c.axis[1][l] * dy + c.axis[2][l] * dz) * inv_d;
        let cosine = if c.two_sided[l] > 0.0 {
            along.abs()
        } else {
            along
        };
        let lobe = cosine.max(0.0);
        let t = ((cosine - c.cos_outer[l]) * c.inv_ramp[l]).clamp(0.0, 1.0);
        let profile = c.isotropic[l] + c.lobe[l] * lobe + c.spot[l] * (t * t);
        weight[l] = lambert * profile;
    }
    for k in 0..3 {
        for l in 0..LANES {
            acc[k][l] += c.intensity[k][l] * weight[l];
        }
    }
}
