//! Tests of the module this file is the `tests` child of.

use glam::{DVec3, Vec3};

use super::*;
use crate::testing::uniform;
use crate::tree::groups::{Group, with_block};
use crate::{LightTree, PointLight};

/// The largest ratio of an observed error to its allowance, per
/// quantity, over every lane checked.
#[derive(Debug, Default)]
struct Worst {
    /// The exact `R / D` over the computed `sigma` (at most 1).
    sigma: f64,
    /// `|o_k|_1 / D` over its bound `1.75 sigma` (at most 1).
    offsets: f64,
    c0: f64,
    sin_c: f64,
    height: f64,
    estimate: f64,
    remainder: f64,
    lanes: usize,
}

/// One lane's `f32` quantities against the same formulas in `f64` at
/// the point `p'` the rounded offset stands for (module docs): each
/// within its allowance.
fn check_lane<const N: usize, const R: usize, const M: usize>(
    block: &Block<N, R, M>,
    lane: usize,
    point: Vec3,
    normal: DVec3,
    worst: &mut Worst,
) {
    let at32 = PointView {
        p: point.to_array(),
        n: normal.as_vec3().to_array(),
    };
    let g32 = geometry::<f32, N, R, M>(block, &at32);
    let (d2, sigma) = (f64::from(g32.d2.0[lane]), f64::from(g32.sigma.0[lane]));
    if !(d2 >= D2_RANGE.0 && d2 <= D2_RANGE.1 && sigma < SIGMA_MAX) {
        return;
    }
    // p' = c - fl(c - p), in f64 (exact for these magnitudes).
    let c = DVec3::new(
        f64::from(block.rows[CENTROID][lane]),
        f64::from(block.rows[CENTROID + 1][lane]),
        f64::from(block.rows[CENTROID + 2][lane]),
    );
    let d32 = DVec3::new(
        f64::from(block.rows[CENTROID][lane] - point.x),
        f64::from(block.rows[CENTROID + 1][lane] - point.y),
        f64::from(block.rows[CENTROID + 2][lane] - point.z),
    );
    let moved = c - d32;
    let at64 = PointView {
        p: moved.to_array(),
        n: normal.to_array(),
    };
    let mut g64 = geometry::<f64, N, R, M>(block, &at64);
    // The exact R / D at p' (to f64 precision), without the f32 path's
    // upward nudge.
    g64.sigma = Wide(g64.sigma.0.map(|s| s / SIGMA_UP));
    let dist = g64.dist.0[lane];
    let l32 = |w: Wide<f32, N>| f64::from(w.0[lane]);
    let l64 = |w: Wide<f64, N>| w.0[lane];
    let ratio = |err: f64, allowance: f64| err / allowance;
    let up = |r: &mut f64, x: f64| *r = r.max(x);
    up(
        &mut worst.sigma,
        l64(g64.sigma) / l32(g32.sigma).max(f64::MIN_POSITIVE),
    );
    up(
        &mut worst.c0,
        ratio((l32(g32.c0) - l64(g64.c0)).abs(), C0 * U),
    );
    up(
        &mut worst.sin_c,
        ratio((l32(g32.sin_c) - l64(g64.sin_c)).abs(), SIN * U),
    );
    // Heights for the true point p, from the f32 values at p.
    let at_p = PointView {
        p: point.as_dvec3().to_array(),
        n: normal.to_array(),
    };
    let gp = geometry::<f64, N, R, M>(block, &at_p);
    let top = |g: &Geometry<f64, N>| l64(g.height) + l64(g.box_mid) + l64(g.box_reach);
    let top32 = l32(g32.height) + l32(g32.box_mid) + l32(g32.box_reach);
    let size = dist + l64(gp.box_size);
    up(
        &mut worst.height,
        ratio((top32 - top(&gp)).abs(), HEIGHT * U * size),
    );
    // The estimate, per channel.
    let w32 = series_weights(&at32, &g32);
    let w64 = series_weights(&at64, &g64);
    let inv_d = 1.0 / dist;
    let offset = |k: usize, a: usize| Block::<N, R, M>::offset_row(k, a);
    let covariance = |k: usize, e: usize| Block::<N, R, M>::covariance_row(k, e);
    for k in 0..Block::<N, R, M>::CHANNELS {
        let e32 = l32(estimate(block, &g32, &w32, k));
        let e64 = l64(estimate(block, &g64, &w64, k));
        let x: f64 = (0..3)
            .map(|a| f64::from(block.rows[offset(k, a)][lane]).abs())
            .sum::<f64>()
            * inv_d;
        let y: f64 = (0..6)
            .map(|e| f64::from(block.rows[covariance(k, e)][lane]).abs())
            .sum::<f64>()
            * inv_d
            * inv_d;
        // The kernel's bound on x.
        up(&mut worst.offsets, x / (1.75 * l32(g32.sigma)));
        let allowance = U * (ESTIMATE[0] + ESTIMATE[1] * x + ESTIMATE[2] * y);
        up(&mut worst.estimate, ratio((e32 - e64).abs(), allowance));
        // The remainder from the widened f32 inputs, widened, against
        // the f64 one from the exact inputs: at least as large.
        let u = |units: f64| Wide::<f32, N>::of(units * U);
        let nu = g32.sin_c + u(SIN);
        let one = Wide::of(1.0);
        let t32 = remainder_terms(
            &g32,
            g32.c0.abs() + u(C0),
            nu * nu,
            (g32.across + u(ACROSS) * g32.box_size) * g32.inv_d * (one + u(8.0)),
        );
        let trace = |scale: f64| {
            (0..3)
                .map(|e| f64::from(block.rows[covariance(k, e)][lane]))
                .sum::<f64>()
                * scale
        };
        let mu2_32 = {
            let s = |e: usize| Wide::<f32, N>::from_f32(&block.rows[covariance(k, e)]);
            (s(0) + s(1) + s(2)) * g32.inv_d * g32.inv_d
        };
        let r32 = l32(remainder(block, &g32, &t32, mu2_32, k)) * (1.0 + REMAINDER * U);
        let t64 = remainder_terms(
            &g64,
            g64.c0.abs(),
            g64.sin_c * g64.sin_c,
            g64.across * g64.inv_d,
        );
        let mu2_64 = Wide::<f64, N>::splat(trace(inv_d * inv_d));
        let r64 = l64(remainder(block, &g64, &t64, mu2_64, k));
        // Below 1 when the f32 remainder covers the f64 one.
        if r64 > 0.0 {
            up(&mut worst.remainder, r64 / r32.max(f64::MIN_POSITIVE));
        }
    }
    worst.lanes += 1;
}

/// Random light sets (balls, slabs, lines; near the origin and far
/// from it), every group of their trees, seen from random points at
/// distances from just outside a child's ball to far away, with random,
/// grazing and facing normals: every quantity of the `f32` kernel is
/// within its allowance of its `f64` value.
#[test]
fn f32_quantities_stay_within_their_allowances() {
    let mut state = 17u64;
    let mut u = move || f64::from(uniform(&mut state));
    let mut worst = Worst::default();
    let mut monos = 0;
    for scene in 0..40 {
        let shape = scene % 4;
        let centre = DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * [0.0, 1e2, 1e4, 3e5][scene % 4];
        let extent = 10f64.powf(4.0 * u() - 2.0);
        let lights: Vec<PointLight> = (0..1200)
            .map(|_| {
                let a = DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5);
                let offset = match shape {
                    0 => a,
                    1 => DVec3::new(a.x, a.y, 1e-3 * a.z),
                    2 => DVec3::new(a.x, 1e-4 * a.y, 1e-4 * a.z),
                    _ => a.normalize_or_zero(),
                };
                // Every fifth scene white: one-colour blocks.
                let colour = if scene % 5 == 4 {
                    Vec3::splat(u() as f32)
                } else {
                    Vec3::new(u() as f32, u() as f32 * 2.0, u() as f32 * 0.1)
                };
                PointLight::new((centre + offset * extent).as_vec3(), colour)
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        for (index, parent) in tree.nodes().iter().enumerate() {
            let Some(group) = tree.groups.children(index) else {
                continue;
            };
            let children = &tree.nodes()[parent.children()];
            for (lane, child) in children.iter().enumerate() {
                let c = child.centroid().as_dvec3();
                let r = f64::from(child.radius()).max(extent * 1e-6);
                let dir = DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize_or(DVec3::X);
                // Just outside the f32 path's limit (sigma just below
                // 1 - 2^-6), or 10^-3 to 10^3 radii beyond the ball.
                let gap = if u() < 0.2 {
                    0.0159 + 0.002 * u()
                } else {
                    10f64.powf(6.0 * u() - 3.0)
                };
                let point = (c + dir * r * (1.0 + gap)).as_vec3();
                let uh = (c - point.as_dvec3()).normalize_or(DVec3::X);
                let side = uh.any_orthonormal_vector();
                let normal = match (scene + lane) % 3 {
                    0 => DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize_or(DVec3::Z),
                    1 => (side + uh * 1e-4 * (u() - 0.5)).normalize(),
                    _ => (uh + side * 0.3 * (u() - 0.5)).normalize(),
                };
                with_block!(group, block => check_lane(block, lane, point, normal, &mut worst));
                monos += usize::from(matches!(group, Group::MonoFour(_) | Group::MonoEight(_)));
            }
        }
    }
    assert!(worst.lanes > 2000 && monos > 200, "{monos} {worst:?}");
    for (what, r) in [
        ("sigma", worst.sigma),
        ("offsets", worst.offsets),
        ("c0", worst.c0),
        ("sin_c", worst.sin_c),
        ("height", worst.height),
        ("estimate", worst.estimate),
        ("remainder", worst.remainder),
    ] {
        assert!(r <= 1.0, "{what}: {r} of its allowance ({worst:?})");
    }
}

/// A one-colour block's bounds: for white or grey lights of any
/// intensity, the very bits of those of the block of three channels
/// made of the same children; for lights of one colour scaled by
/// random factors, intervals holding each channel's exact sum over the
/// child's lights. Seen from random points and normals.
#[test]
fn one_colour_blocks_bound_each_channel() {
    let mut state = 23u64;
    let mut u = move || uniform(&mut state);
    let (mut compared, mut contained) = (0, 0);
    for scene in 0..12 {
        let extent = [1.0, 1e3, 1e-2][scene % 3];
        let white = scene % 2 == 0;
        let lights: Vec<PointLight> = (0..5000)
            .map(|_| {
                let p = Vec3::new(u() - 0.5, u() - 0.5, (u() - 0.5) * 0.3) * extent;
                // Sodium, tinted by up to 2^-12 from one side to the
                // other.
                let tint = (p.x / extent + 0.5) / 4096.0;
                let colour = if white {
                    Vec3::ONE
                } else {
                    Vec3::new(1.0, 0.55 * (1.0 + tint), 0.2 * (1.0 - tint))
                };
                PointLight::new(p, colour * 10f32.powf(4.0 * u() - 2.0))
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let spreads = crate::tree::groups::colour_spreads(tree.nodes(), tree.lights());
        for (index, parent) in tree.nodes().iter().enumerate() {
            if parent.is_leaf() {
                continue;
            }
            let range = parent.children();
            let (children, spreads) = (&tree.nodes()[range.clone()], &spreads[range]);
            let dir = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize_or(Vec3::Z);
            let p = dir * extent * (0.3 + 3.0 * u());
            let n = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize_or(Vec3::Z);
            let at = PointView {
                p: p.to_array(),
                n: n.to_array(),
            };
            let kd = [0.7, 1.1, 0.2];
            let mut scales = LaneScales {
                intensity: [[0.0; 8]; 3],
                moment_error: [0.0; 8],
            };
            for i in 0..8 {
                let child = &children[i.min(children.len() - 1)];
                for (k, &kd) in kd.iter().enumerate() {
                    scales.intensity[k][i] = child.intensity[k] * kd;
                }
                scales.moment_error[i] = child.moment_error();
            }
            let (mono, colour) = match tree.groups.children(index) {
                Some(Group::MonoEight(mono)) => (
                    lane_bounds(mono, &at, &scales),
                    Block::<8>::of(children, spreads),
                ),
                Some(Group::MonoFour(_)) | None => continue,
                Some(_) => panic!("lights of one colour in a block of three channels"),
            };
            if white {
                let colour = lane_bounds(&colour, &at, &scales);
                let bits = |x: &[[f64; 8]; 3]| x.map(|c| c.map(f64::to_bits));
                assert_eq!(bits(&mono.lower), bits(&colour.lower));
                assert_eq!(bits(&mono.upper), bits(&colour.upper));
                assert_eq!(bits(&mono.estimate), bits(&colour.estimate));
                compared += 1;
                continue;
            }
            for (i, child) in children.iter().enumerate() {
                if !matches!(mono.state(i), Lane::Bounded | Lane::Reaching) {
                    continue;
                }
                for (k, &kd) in kd.iter().enumerate() {
                    let exact: f64 = tree.lights()[child.lights()]
                        .iter()
                        .map(|l| {
                            let v = l.position.as_dvec3() - p.as_dvec3();
                            let cos = n.as_dvec3().dot(v).max(0.0);
                            f64::from(l.intensity[k]) * kd * cos / v.length().powi(3)
                        })
                        .sum();
                    let (lo, hi) = (mono.lower[k][i], mono.upper[k][i]);
                    let slack = 1e-12 * hi;
                    assert!(
                        lo <= exact + slack && exact <= hi + slack,
                        "channel {k}: {lo} <= {exact} <= {hi}"
                    );
                    contained += 1;
                }
            }
        }
    }
    assert!(compared > 100 && contained > 1000, "{compared} {contained}");
}
