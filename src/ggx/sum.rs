//! A leaf's lights summed in `f64` lanes: [`Ggx`]'s
//! [`Shader::sum_lights`], eight lights side by side (in a copy compiled
//! for AVX2 where the processor has it), each term the model's as
//! [`eval`](Shader::eval) computes it, with three divisions where `eval`
//! has eight.
//!
//! # The term, rearranged
//!
//! For a light at `x`, `o = x - p`, `d = |o|`, the height `z = N.o` (the
//! plain `f64` dot product, kept where [`NAIVE_DOT_ACCEPT`] accepts it, as
//! `eval`'s exact-sign dot product does), `a = n.l = z / (|N| d)`, `h = l +
//! v` and `c = n x h`, `eval`'s `sin^2 theta_h = |c|^2 / |h|^2` gives
//!
//! ```text
//! D Vis (n.l) / d^2 = (alpha^2 / 2) a / (pi t^2 (n.v m_a + a m_v) d^2),
//!     t = alpha^2 + (1 - alpha^2) |c|^2 / |h|^2,
//! ```
//!
//! the same quantities as `eval`'s (module text (P1), (P2)), with the three
//! quotients `D`, `Vis` and `a / d^2` merged into one, and `l = o (1 / d)`,
//! `a = (z (1 / d)) (1 / |N|)` products by reciprocals computed once.
//!
//! What that moves, with `u = 2^-53`, beside what `eval` itself carries
//! (the height's `2^-40`, the half vector's angle; [`Ggx`]'s docs): `l`
//! by one rounding more per component, so the half vector's angle by at
//! most about `2 u / |l + v|` more, which moves `D` by at most `2 / alpha`
//! times that, relatively; every other factor by at most `16 u` relative
//! in all. Lights with `|l + v|^2 < 1/100` (light and view grazing the
//! surface on opposite sides of the normal) go through `eval`, so at
//! `alpha = 1e-3` a term moves by at most about `5e-12` relative, far
//! inside the crate's
//! [`ROUNDING_ALLOWANCE`](crate::ShadeResult::ROUNDING_ALLOWANCE): what
//! [`Shader::sum_lights`]'s contract asks.
//!
//! The merged quotient neither overflows nor underflows: its denominator
//! is `pi t^2` (in `[pi alpha^4, pi]`, at least `3e-12`) times `n.v m_a +
//! a m_v` (in `(0, 2]`, at least `alpha n.v`, and `n.v` of `f32` inputs is
//! 0 or above `1e-90`) times `d^2` (of `f32` coordinates: above `1e-90`,
//! below `1e79`), so between `1e-195` and `1e80`, and its numerator
//! `alpha^2 a / 2` is at most `1/2` and not below `1e-180` for a lit
//! light (so the quotient is above `1e-260`).
//!
//! Lights whose height is not accepted (within about 0.1 degree of the
//! tangent plane) also go through `eval`, as in [`Lambert`]'s sums.
//!
//! [`Lambert`]: crate::Lambert

use glam::DVec3;

use super::{Ggx, GgxView};
use crate::PointLight;
use crate::dispatch::avx2_or;
use crate::geometry::Surface;
use crate::lanes::{Lanes, Vec3Lanes};
use crate::numeric::NAIVE_DOT_ACCEPT;
use crate::shader::Shader;

/// Lights side by side: two AVX2 vectors of `f64` (two chains of
/// divisions and square roots in flight; one vector left the units idle).
const L: usize = 8;

/// Smallest `|l + v|^2` of a light summed in the lanes; below it, through
/// `eval` (the module's text).
const HALF_SQUARED_MIN: f64 = 1e-2;

impl Ggx {
    /// [`Shader::sum_lights`]: on `x86_64` processors with AVX2, in a copy
    /// compiled for AVX2 (the same bits, see [`dispatch`](crate::dispatch)).
    /// Out of line, compiled once.
    #[inline(never)]
    pub(super) fn sum_group(
        &self,
        view: &GgxView,
        surface: &Surface,
        lights: &[PointLight],
    ) -> DVec3 {
        avx2_or!(
            Self::sum_group_avx2,
            Self::sum_group_inlined,
            self,
            view,
            surface,
            lights
        )
    }

    /// [`sum_group`](Self::sum_group) compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn sum_group_avx2(&self, view: &GgxView, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        self.sum_group_inlined(view, surface, lights)
    }

    /// Lane `i` adds the terms of lights `i`, `i + L`, `i + 2 L`, ..., the
    /// lanes are added in order, then the terms of the lights `eval` takes
    /// (the module's text).
    #[inline(always)]
    fn sum_group_inlined(&self, view: &GgxView, surface: &Surface, lights: &[PointLight]) -> DVec3 {
        if !view.lit || lights.is_empty() {
            return DVec3::ZERO;
        }
        let normal = surface.given_normal.as_dvec3();
        let p = surface.point.to_array();
        let (n, v) = (surface.normal.to_array(), surface.view);
        let inv_normal = 1.0 / view.normal_length;
        let scale = 0.5 * self.alpha2;
        let pi = core::f64::consts::PI;
        let zero = Lanes::<L>::splat(0.0);
        let one = Lanes::<L>::splat(1.0);
        let mut sums = [zero; 3];
        let mut near = DVec3::ZERO;
        for chunk in lights.chunks(L) {
            // A short last chunk repeats its last light in the unused
            // lanes, whose weights are 0 (`keep` below).
            let last = chunk.len() - 1;
            let light = |i: usize| &chunk[i.min(last)];
            let o = Vec3Lanes::<L>::from_fn(|i| light(i).position.as_dvec3().to_array()).minus(p);
            let (height, magnitude) = o.plain_dot(normal.to_array());
            let d2 = o.dot(o);
            let inv_d = one / d2.sqrt();
            let a = (height * inv_d * inv_normal).max(zero).min(one);
            let h = Vec3Lanes {
                x: o.x * inv_d + v.x,
                y: o.y * inv_d + v.y,
                z: o.z * inv_d + v.z,
            };
            let h2 = h.dot(h);
            let c = Vec3Lanes {
                x: n[1] * h.z - h.y * n[2],
                y: n[2] * h.x - h.z * n[0],
                z: n[0] * h.y - h.x * n[1],
            };
            let s2 = (c.dot(c) / h2).min(one);
            let t = self.alpha2 + self.k * s2;
            let m_a = (self.alpha2 + self.k * (a * a)).sqrt();
            let w = scale * a / (pi * (t * t) * (view.nv * m_a + a * view.m_v) * d2);
            let fresnel = (one - (0.5 * h2.sqrt()).min(one)).max(zero);
            let f2 = fresnel * fresnel;
            let schlick = f2 * f2 * fresnel;
            // Per lane: the term's weight where it is lit and summed here,
            // 0 where it is dark (the height's sign certain) or a spare
            // lane; `by_eval` where `eval` takes it.
            let mut keep = [0.0f64; L];
            let mut by_eval = [false; L];
            for i in 0..=last {
                let accepted = height.0[i].abs() >= NAIVE_DOT_ACCEPT * magnitude.0[i];
                if !accepted || (height.0[i] > 0.0 && !(h2.0[i] >= HALF_SQUARED_MIN)) {
                    by_eval[i] = true;
                } else if height.0[i] > 0.0 {
                    keep[i] = w.0[i];
                }
            }
            let w = Lanes::<L>::from_fn(|i| keep[i]);
            for (k, sum) in sums.iter_mut().enumerate() {
                let f0 = self.f0[k];
                let intensity = Lanes::<L>::from_fn(|i| f64::from(light(i).intensity[k]));
                *sum += intensity * ((f0 + (1.0 - f0) * schlick) * w);
            }
            for (light, _) in chunk.iter().zip(by_eval).filter(|(_, e)| *e) {
                near += self.eval(
                    view,
                    surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                );
            }
        }
        let total = |s: Lanes<L>| s.0.iter().sum::<f64>();
        DVec3::new(total(sums[0]), total(sums[1]), total(sums[2])) + near
    }
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::*;
    use crate::testing::uniform;

    /// Relative difference allowed between the lanes' terms and `eval`'s:
    /// the module's `5e-12`.
    const TERM: f64 = 5e-12;

    /// Lights all around a point (some a hair above or below the tangent
    /// plane, some with light and view grazing it on opposite sides of the
    /// normal), views from grazing (`n.v` about 1e-6) to straight up,
    /// `alpha` log-uniform over its range, coloured `F0`: each light's term
    /// alone is within `TERM` of `eval`'s, every sum of up to 40 lights
    /// within `TERM` of the sum of `eval`'s terms, and the baseline copy
    /// gives the same bits as the one that runs.
    #[test]
    fn the_lanes_match_eval() {
        let mut seed = 11u64;
        let mut next = move || uniform(&mut seed);
        let (mut checked, mut lit, mut by_eval) = (0, 0, 0);
        for case in 0..400 {
            let alpha = 10f32.powf(-3.0 * next());
            let f0 = Vec3::new(next(), next(), 0.04);
            let ggx = Ggx::new(f0, alpha);
            let p = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 8.0;
            let normal = Vec3::new(next() - 0.5, next() - 0.5, 1.0);
            let up = if case % 5 == 0 {
                1e-6
            } else {
                (90.0 * next()).to_radians()
            };
            let around = std::f32::consts::TAU * next();
            let (nu, nv) = (
                normal.any_orthonormal_vector(),
                normal.normalize().cross(normal.any_orthonormal_vector()),
            );
            let v =
                normal.normalize() * up.sin() + (nu * around.cos() + nv * around.sin()) * up.cos();
            let surface = Surface::new(p, normal, Some(v)).unwrap();
            let view = ggx.prepare(&surface);
            let n = normal.normalize();
            let lights: Vec<PointLight> = (0..40)
                .map(|k| {
                    let dir = match k % 4 {
                        // A hair off the tangent plane, either side.
                        0 => {
                            (nu * (next() - 0.5) + nv * (next() - 0.5)).normalize()
                                + n * (1e-4 * (next() - 0.5))
                        }
                        // Against the view's tangent part: light and view
                        // grazing on opposite sides of the normal.
                        1 => -(v - n * v.dot(n)).normalize() + n * (0.05 * next()),
                        _ => Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5),
                    };
                    let at = p + dir * (0.01 + 20.0 * next());
                    PointLight::new(at, Vec3::new(next(), next(), next()) + Vec3::splat(0.01))
                })
                .collect();
            let term = |light: &PointLight| {
                ggx.eval(
                    &view,
                    &surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                )
            };
            let close = |a: DVec3, b: DVec3| ((a - b).abs()).cmple(b.abs() * TERM).all();
            for light in &lights {
                let one = ggx.sum_group(&view, &surface, core::slice::from_ref(light));
                let exact = term(light);
                assert!(close(one, exact), "{one} against {exact}, alpha {alpha}");
                checked += 1;
                lit += usize::from(exact != DVec3::ZERO);
                let o = light.position.as_dvec3() - surface.point;
                let h = o.normalize() + surface.view;
                by_eval +=
                    usize::from(exact != DVec3::ZERO && h.length_squared() < HALF_SQUARED_MIN);
            }
            for len in [2, 3, 7, 8, 9, 16, 40] {
                let start = case % (41 - len);
                let chunk = &lights[start..start + len];
                let sum = ggx.sum_group(&view, &surface, chunk);
                let exact: DVec3 = chunk.iter().map(term).sum();
                assert!(close(sum, exact), "{sum} against {exact}");
                let baseline = crate::dispatch::baseline(|| ggx.sum_group(&view, &surface, chunk));
                assert_eq!(
                    sum.to_array().map(f64::to_bits),
                    baseline.to_array().map(f64::to_bits)
                );
            }
        }
        assert!(lit > 4_000 && by_eval > 100, "{checked} {lit} {by_eval}");
    }
}
