//! Baseline (a): the exact sum ("standard ray tracing" without shadows),
//! written to vectorize.
//!
//! Lights are stored as structure-of-arrays in `f32`, in chunks of
//! [`LANES`] (the last chunk padded with zero-intensity lights). The inner
//! loop over one chunk has no data-dependent branch (the `d = 0` and
//! below-the-horizon cases are selects) and no cross-lane dependency, so the
//! compiler turns it into SIMD code; the lane accumulators are flushed to
//! `f64` every `FLUSH_CHUNKS` chunks so that the `f32` sums never run over
//! more than a thousand terms. The Phong power `max(0, r.w)^e` is taken by
//! repeated squaring with the (integer, shared) exponent's bits, which
//! vectorizes where `powf` would not. The result agrees with the crate's
//! `f64` `exact_query` to about `1e-6` relative (checked by the report).
//!
//! Like the crate's own kernels, the sum has a copy compiled for AVX2
//! (eight lanes in one vector), picked at run time where the processor has
//! it, so that the yardstick gets the instructions the tree gets; it gives
//! the same bits as the build's baseline copy (SSE2 in a default `x86_64`
//! build), which [`SoaLights::baseline`] runs for comparison.

use glam::{DVec3, Vec3};
use manylights::PointLight;

use crate::scenes::Material;

/// Lights per chunk: the width the inner loop is written for.
pub const LANES: usize = 8;
/// Chunks accumulated in `f32` before the lane sums are added to `f64`.
const FLUSH_CHUNKS: usize = 128;

type Lanes = [f32; LANES];

/// [`LANES`] lights as structure-of-arrays: the six arrays of one chunk are
/// contiguous (192 bytes), so a chunk is read in one sweep.
#[derive(Clone, Copy, Debug, Default)]
struct Chunk {
    position: [Lanes; 3],
    intensity: [Lanes; 3],
}

/// Lights as structure-of-arrays in chunks of [`LANES`].
#[derive(Clone, Debug)]
pub struct SoaLights {
    chunks: Vec<Chunk>,
    /// Whether to run the build's baseline copy even where the processor
    /// has AVX2 (see [`baseline`](Self::baseline)).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    baseline: bool,
}

/// The shading point and material as the inner loop reads them.
struct Receiver {
    p: Vec3,
    n: Vec3,
    /// Mirror direction of the view about the normal (zero when diffuse).
    mirror: Vec3,
    kd: Vec3,
    ks: Vec3,
    exponent: u32,
}

impl SoaLights {
    /// Converts `lights` (any order).
    pub fn new(lights: &[PointLight]) -> Self {
        let mut chunks = vec![Chunk::default(); lights.len().div_ceil(LANES)];
        for (i, light) in lights.iter().enumerate() {
            let (chunk, l) = (&mut chunks[i / LANES], i % LANES);
            for k in 0..3 {
                chunk.position[k][l] = light.position[k];
                chunk.intensity[k][l] = light.intensity[k];
            }
        }
        Self {
            chunks,
            baseline: false,
        }
    }

    /// These lights summed by the copy compiled for the build's target
    /// only (SSE2 in a default `x86_64` build), never the AVX2 copy: for
    /// comparing the two.
    #[must_use]
    pub fn baseline(mut self) -> Self {
        self.baseline = true;
        self
    }

    /// The exact radiance at `point` (unit `normal`, unit `view`) for
    /// `material`: the crate's model, summed over every light.
    pub fn shade(&self, material: &Material, point: Vec3, normal: Vec3, view: Vec3) -> DVec3 {
        match material.specular {
            None => self.sum::<false>(&Receiver {
                p: point,
                n: normal,
                mirror: Vec3::ZERO,
                kd: material.kd,
                ks: Vec3::ZERO,
                exponent: 0,
            }),
            Some(spec) => self.sum::<true>(&Receiver {
                p: point,
                n: normal,
                mirror: 2.0 * normal.dot(view) * normal - view,
                kd: material.kd,
                ks: spec.ks,
                exponent: spec.exponent,
            }),
        }
    }

    /// The sum over every chunk: the copy compiled for AVX2 where the
    /// processor has it (picked at run time, as the crate picks its own
    /// kernels), else the build's baseline. Neither fuses a multiply and
    /// an add, so both give the same bits.
    // Calling the AVX2 copy after the check is this module's one unsafe
    // block.
    #[allow(unsafe_code)]
    fn sum<const GLOSSY: bool>(&self, rx: &Receiver) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && !self.baseline {
            // SAFETY: the processor has AVX2 (checked just above).
            return unsafe { self.sum_avx2::<GLOSSY>(rx) };
        }
        self.sum_body::<GLOSSY>(rx)
    }

    /// [`sum_body`](Self::sum_body) compiled for AVX2: eight lanes in one
    /// vector, three-operand instructions.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sum_avx2<const GLOSSY: bool>(&self, rx: &Receiver) -> DVec3 {
        self.sum_body::<GLOSSY>(rx)
    }

    #[inline(always)]
    fn sum_body<const GLOSSY: bool>(&self, rx: &Receiver) -> DVec3 {
        let mut total = DVec3::ZERO;
        for block in self.chunks.chunks(FLUSH_CHUNKS) {
            let mut acc = [[0.0f32; LANES]; 3];
            for c in block {
                chunk::<GLOSSY>(rx, c, &mut acc);
            }
            let lane_sum = |a: &Lanes| a.iter().map(|&v| f64::from(v)).sum::<f64>();
            total += DVec3::new(lane_sum(&acc[0]), lane_sum(&acc[1]), lane_sum(&acc[2]));
        }
        total
    }
}

/// One chunk of [`LANES`] lights added to the lane accumulators. Every
/// statement is a lane-wise operation on fixed-size arrays, so it compiles to
/// SIMD instructions.
#[inline(always)]
fn chunk<const GLOSSY: bool>(rx: &Receiver, lights: &Chunk, acc: &mut [Lanes; 3]) {
    let (pos, intensity) = (&lights.position, &lights.intensity);
    let mut diffuse = [0.0f32; LANES];
    let mut cos = [0.0f32; LANES];
    let mut inv_d2 = [0.0f32; LANES];
    for l in 0..LANES {
        let dx = pos[0][l] - rx.p.x;
        let dy = pos[1][l] - rx.p.y;
        let dz = pos[2][l] - rx.p.z;
        let d2 = dx * dx + dy * dy + dz * dz;
        // A light on the shading point contributes 0 (the crate's model).
        let inv_d = if d2 > 0.0 { 1.0 / d2.sqrt() } else { 0.0 };
        inv_d2[l] = inv_d * inv_d;
        let z = rx.n.x * dx + rx.n.y * dy + rx.n.z * dz;
        diffuse[l] = z.max(0.0) * inv_d * inv_d2[l];
        if GLOSSY {
            cos[l] = (rx.mirror.x * dx + rx.mirror.y * dy + rx.mirror.z * dz) * inv_d;
        }
    }
    let mut specular = [0.0f32; LANES];
    if GLOSSY {
        // max(0, cos)^e by repeated squaring. The exponent is the same in
        // every lane, so the loop over its bits does not diverge.
        let mut lobe = [1.0f32; LANES];
        let mut base = cos.map(|c| c.max(0.0));
        let mut e = rx.exponent;
        while e > 0 {
            if e & 1 == 1 {
                for l in 0..LANES {
                    lobe[l] *= base[l];
                }
            }
            for b in &mut base {
                *b *= *b;
            }
            e >>= 1;
        }
        for l in 0..LANES {
            // max(0, c)^e is 0 for c <= 0, also when e = 0.
            specular[l] = if cos[l] > 0.0 {
                lobe[l] * inv_d2[l]
            } else {
                0.0
            };
        }
    }
    let kd = rx.kd.to_array();
    let ks = rx.ks.to_array();
    for k in 0..3 {
        for l in 0..LANES {
            let mut w = kd[k] * diffuse[l];
            if GLOSSY {
                w += ks[k] * specular[l];
            }
            acc[k][l] += intensity[k][l] * w;
        }
    }
}

/// A GGX microfacet material for [`SoaLights::shade_ggx`]: the crate's
/// `Ggx` model (GGX `D`, height-correlated Smith `G2`, Schlick `F`).
#[derive(Clone, Copy, Debug)]
pub struct GgxMaterial {
    /// Specular colour `F0`.
    pub f0: Vec3,
    /// Roughness `alpha`.
    pub alpha: f32,
}

/// The shading point and GGX material as [`ggx_chunk`] reads them.
struct GgxReceiver {
    p: Vec3,
    n: Vec3,
    v: Vec3,
    /// `n.v`, at least 0.
    nv: f32,
    /// `sqrt(alpha^2 + (1 - alpha^2) (n.v)^2)`.
    m_v: f32,
    alpha2: f32,
    /// `1 - alpha^2`.
    k: f32,
    f0: Vec3,
}

impl SoaLights {
    /// The exact GGX radiance at `point` (unit `normal`, unit `view`): the
    /// crate's `Ggx` model summed over every light in `f32` lanes, as
    /// [`shade`](Self::shade) sums Lambert and Phong. Zero for a view at
    /// or below the surface.
    pub fn shade_ggx(
        &self,
        material: &GgxMaterial,
        point: Vec3,
        normal: Vec3,
        view: Vec3,
    ) -> DVec3 {
        let nv = normal.dot(view);
        if !(nv > 0.0) {
            return DVec3::ZERO;
        }
        let alpha2 = material.alpha * material.alpha;
        let k = 1.0 - alpha2;
        let rx = GgxReceiver {
            p: point,
            n: normal,
            v: view,
            nv,
            m_v: (alpha2 + k * nv * nv).sqrt(),
            alpha2,
            k,
            f0: material.f0,
        };
        self.sum_ggx(&rx)
    }

    /// [`sum`](Self::sum) for GGX: the AVX2 copy where the processor has
    /// it, else the build's baseline.
    #[allow(unsafe_code)]
    fn sum_ggx(&self, rx: &GgxReceiver) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && !self.baseline {
            // SAFETY: the processor has AVX2 (checked just above).
            return unsafe { self.sum_ggx_avx2(rx) };
        }
        self.sum_ggx_body(rx)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sum_ggx_avx2(&self, rx: &GgxReceiver) -> DVec3 {
        self.sum_ggx_body(rx)
    }

    #[inline(always)]
    fn sum_ggx_body(&self, rx: &GgxReceiver) -> DVec3 {
        let mut total = DVec3::ZERO;
        for block in self.chunks.chunks(FLUSH_CHUNKS) {
            let mut acc = [[0.0f32; LANES]; 3];
            for c in block {
                ggx_chunk(rx, c, &mut acc);
            }
            let lane_sum = |a: &Lanes| a.iter().map(|&v| f64::from(v)).sum::<f64>();
            total += DVec3::new(lane_sum(&acc[0]), lane_sum(&acc[1]), lane_sum(&acc[2]));
        }
        total
    }
}

/// One chunk of GGX terms added to the lane accumulators, branch-free:
/// `sin^2 theta_h` from the cross product `n x (l + v)` (no cancellation
/// near the lobe's axis), `Vis = G2 / (4 (n.l)(n.v))` in its closed form.
#[inline(always)]
fn ggx_chunk(rx: &GgxReceiver, lights: &Chunk, acc: &mut [Lanes; 3]) {
    let (pos, intensity) = (&lights.position, &lights.intensity);
    let mut weight = [0.0f32; LANES];
    let mut schlick = [0.0f32; LANES];
    for l in 0..LANES {
        let dx = pos[0][l] - rx.p.x;
        let dy = pos[1][l] - rx.p.y;
        let dz = pos[2][l] - rx.p.z;
        let d2 = dx * dx + dy * dy + dz * dz;
        let inv_d = if d2 > 0.0 { 1.0 / d2.sqrt() } else { 0.0 };
        let nl = (rx.n.x * dx + rx.n.y * dy + rx.n.z * dz) * inv_d;
        let (hx, hy, hz) = (
            dx * inv_d + rx.v.x,
            dy * inv_d + rx.v.y,
            dz * inv_d + rx.v.z,
        );
        let h2 = hx * hx + hy * hy + hz * hz;
        let cx = rx.n.y * hz - rx.n.z * hy;
        let cy = rx.n.z * hx - rx.n.x * hz;
        let cz = rx.n.x * hy - rx.n.y * hx;
        let s2 = ((cx * cx + cy * cy + cz * cz) / h2).min(1.0);
        let t = rx.alpha2 + rx.k * s2;
        let distribution = rx.alpha2 / (std::f32::consts::PI * t * t);
        let nl_c = nl.max(0.0);
        let vis = 0.5 / (rx.nv * (rx.alpha2 + rx.k * nl_c * nl_c).sqrt() + nl_c * rx.m_v);
        let w = distribution * vis * nl_c * inv_d * inv_d;
        weight[l] = if nl > 0.0 { w } else { 0.0 };
        let c = (1.0 - 0.5 * h2.sqrt()).max(0.0);
        schlick[l] = c * c * c * c * c;
    }
    let f0 = rx.f0.to_array();
    for k in 0..3 {
        for l in 0..LANES {
            let fresnel = f0[k] + (1.0 - f0[k]) * schlick[l];
            acc[k][l] += intensity[k][l] * fresnel * weight[l];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenes::{Specular, city};
    use manylights::{Lambert, LightTree, Unoccluded};

    /// The AVX2 copy and the baseline give the same bits, diffuse and
    /// glossy, and the diffuse sums agree with the crate's `f64`
    /// `exact_query`.
    #[test]
    fn both_copies_give_the_same_bits() {
        let scene = city(3_000, 16, 7);
        let fast = SoaLights::new(&scene.lights);
        let base = SoaLights::new(&scene.lights).baseline();
        let tree = LightTree::build(&scene.lights).expect("valid lights");
        let diffuse = Material::diffuse(Vec3::splat(0.5));
        let glossy = Material {
            kd: Vec3::splat(0.4),
            specular: Some(Specular {
                ks: Vec3::splat(0.3),
                exponent: 37,
            }),
        };
        for material in [diffuse, glossy] {
            for p in &scene.points {
                let a = fast.shade(&material, p.point, p.normal, p.view);
                let b = base.shade(&material, p.point, p.normal, p.view);
                assert_eq!(
                    a.to_array().map(f64::to_bits),
                    b.to_array().map(f64::to_bits)
                );
                if material.specular.is_none() {
                    let exact = tree
                        .shading(Lambert::new(material.kd))
                        .exact_query(&crate::sweep::query(p), Unoccluded);
                    let scale = exact.max_element().max(1e-30);
                    assert!(
                        (a - exact).abs().max_element() <= 1e-5 * scale,
                        "{a} against {exact}"
                    );
                }
            }
        }
    }
}
