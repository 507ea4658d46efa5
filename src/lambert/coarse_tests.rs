//! Tests of the module this file is the `tests` child of.

use glam::{DVec3, Vec3};

use super::{COARSE_MAX, U, sum_baseline};
use crate::dispatch::baseline;
use crate::geometry::Surface;
use crate::shader::{Seal, Shader};
use crate::{Lambert, PointLight};

/// Both copies, which must agree bit for bit.
fn coarse(lambert: &Lambert, surface: &Surface, lights: &[PointLight]) -> Option<(DVec3, DVec3)> {
    let sum = lambert.sum_lights_coarse(Seal, &(), surface, lights);
    let base = baseline(|| lambert.sum_lights_coarse(Seal, &(), surface, lights));
    assert_eq!(bits(sum), bits(base));
    sum
}

/// The bits of a sum and its bound.
fn bits(r: Option<(DVec3, DVec3)>) -> Option<([u64; 3], [u64; 3])> {
    r.map(|(s, e)| {
        (
            s.to_array().map(f64::to_bits),
            e.to_array().map(f64::to_bits),
        )
    })
}

/// Puts `light` out of a coarse sum's range for `odd` of 1 (on the
/// point `p`), 2 (at `2^31` of it) or 3 (an intensity past `2^40`);
/// leaves it as it is otherwise.
fn out_of_range(light: &mut PointLight, p: Vec3, odd: usize) {
    match odd {
        1 => light.position = p,
        2 => light.position = p + Vec3::X * 2_147_483_648.0,
        3 => light.intensity.y = 2.0e12,
        _ => {}
    }
}

/// The sum of lights side by side gives the bits of the sum of the
/// same lights, in both copies, for 0 to 64 lights (a last group full
/// or not), in range or not (a light on the point, one at `2^31` of it,
/// an intensity past `2^40`), above, in and below the tangent plane,
/// and `None` alike where there are fewer groups than lights need.
#[test]
fn sums_of_lanes_match_sums_of_lights() {
    let mut state = 31u64;
    let mut uniform = move || crate::testing::uniform(&mut state);
    let lambert = Lambert::new(Vec3::new(0.9, 0.5, 0.25));
    let mut kept = 0;
    for round in 0..1300 {
        let p = Vec3::new(uniform() * 8.0, uniform() * 8.0, uniform() * 2.0);
        let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0);
        let surface = Surface::new(p, normal, None).unwrap();
        let count = round % (COARSE_MAX + 1);
        let odd = (round / (COARSE_MAX + 1)) % 4;
        let lights: Vec<PointLight> = (0..count)
            .map(|i| {
                let offset = Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * 20.0;
                let mut light =
                    PointLight::new(p + offset, Vec3::new(uniform(), uniform(), uniform()));
                if i == count / 2 {
                    out_of_range(&mut light, p, odd);
                }
                light
            })
            .collect();
        let lanes = crate::LightLanes::of(&lights);
        assert_eq!(lanes.len(), count.div_ceil(8));
        let aos = bits(coarse(&lambert, &surface, &lights));
        let soa = lambert.sum_lanes_coarse(Seal, &(), &surface, &lanes, count);
        let base = baseline(|| lambert.sum_lanes_coarse(Seal, &(), &surface, &lanes, count));
        assert_eq!(bits(soa), aos, "round {round}, {count} lights");
        assert_eq!(bits(base), aos, "round {round}, {count} lights");
        kept += usize::from(aos.is_some());
        if count > 8 {
            let short = &lanes[..lanes.len() - 1];
            assert_eq!(
                lambert.sum_lanes_coarse(Seal, &(), &surface, short, count),
                None
            );
        }
    }
    // A quarter of the rounds has every light in range.
    assert!(kept > 250 && kept < 1050, "{kept} sums in range");
}

/// `count` lights within 10 of `p` (a point of `surface`, whose normal
/// is `normal`): by `round + i`, in the tangent plane, a hair off it or
/// anywhere, a seventh of them dark, the others of intensity up to 100
/// (red), 400 (green) and 10 (blue).
fn plane_lights(
    uniform: &mut impl FnMut() -> f32,
    (p, normal): (Vec3, Vec3),
    count: usize,
    round: usize,
) -> Vec<PointLight> {
    let n = normal.normalize();
    (0..count)
        .map(|i| {
            let offset = Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * 20.0;
            let flat = offset - n * offset.dot(n);
            let position = match (round + i) % 5 {
                0 => p + flat,
                1 => p + flat + n * (i as f32 - 3.0) * 1e-6,
                _ => p + offset,
            };
            let dark = (round + i).is_multiple_of(7);
            let i = Vec3::new(uniform(), uniform() * 4.0, uniform() * 0.1);
            PointLight::new(position, if dark { Vec3::ZERO } else { i * 100.0 })
        })
        .collect()
}

/// Asserts that `(sum, error)` for `lights` at `surface` (with
/// `Lambert` of `kd`) is within `error` of the compensated sum of `eval`
/// (within `2^-40` relative of the exact terms), and `error` within
/// `33 * 2^-24 kd sum max_k I_k / d^2`; returns the largest ratio of a
/// channel's actual error to its bound (0 where the bound is 0).
fn assert_within_bound(
    kd: Vec3,
    surface: &Surface,
    lights: &[PointLight],
    (sum, error): (DVec3, DVec3),
    what: &str,
) -> f64 {
    let lambert = Lambert::new(kd);
    let mut exact = crate::numeric::CompensatedSum::default();
    let mut envelope = 0.0;
    for light in lights {
        let (x, i) = (light.position.as_dvec3(), light.intensity.as_dvec3());
        exact.add(lambert.eval(&(), surface, x, i));
        envelope += i.max_element() / (x - surface.point).length_squared();
    }
    let exact = exact.value();
    let kd = kd.as_dvec3();
    let mut worst = 0.0f64;
    for k in 0..3 {
        let off = (sum[k] - exact[k]).abs();
        assert!(
            off <= error[k] + 1e-12 * exact[k],
            "{what}: {sum} against {exact}, bound {error}"
        );
        assert!(error[k] <= 33.0 * U * kd[k] * envelope * (1.0 + 1e-6) + 1e-15 * sum[k] + 1e-30);
        if error[k] > 0.0 {
            worst = worst.max(off / error[k]);
        }
    }
    worst
}

/// The coarse sum against the compensated sum of `eval` over 0 to 64
/// lights, above, below, in and a hair off the tangent plane, dark and
/// bright: within its bound, the bound within `33 * 2^-24 kd sum max_k
/// I_k / d^2`, and the AVX2 copy the same bits as the baseline.
#[test]
fn coarse_sums_stay_within_their_bounds() {
    let mut state = 29u64;
    let mut uniform = move || crate::testing::uniform(&mut state);
    let kd = Vec3::new(0.9, 0.5, 0.25);
    let lambert = Lambert::new(kd);
    let mut worst = 0.0f64;
    for round in 0..1300 {
        let p = Vec3::new(uniform() * 8.0, uniform() * 8.0, uniform() * 2.0);
        let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0) * (0.1 + 3.0 * uniform());
        let surface = Surface::new(p, normal, None).unwrap();
        let count = round % (COARSE_MAX + 1);
        let lights = plane_lights(&mut uniform, (p, normal), count, round);
        let Some(sum) = coarse(&lambert, &surface, &lights) else {
            // Only a light on the point itself is out of range here.
            assert!(
                lights
                    .iter()
                    .any(|l| (l.position - p).length_squared() < 1e-12)
            );
            continue;
        };
        let what = format!("round {round}, {count} lights");
        worst = worst.max(assert_within_bound(kd, &surface, &lights, sum, &what));
    }
    assert!(worst > 0.0, "no sum was off at all");
}

/// A whole scene's sum in blocks ([`Shader::sum_scene_coarse`]): the
/// same bits in both copies, within its bound of the compensated sum of
/// `eval` for 0 to 200 lights and 768 (blocks full or not; above, in,
/// a hair off and below the tangent plane, dark and bright), the bound
/// within `33 * 2^-24 kd sum max_k I_k / d^2`, and `None` out of range
/// (a light on the point, one at `2^31` of it, an intensity past
/// `2^40`) or for fewer groups than the lights need.
#[test]
fn whole_scene_sums_stay_within_their_bounds() {
    let mut state = 37u64;
    let mut uniform = move || crate::testing::uniform(&mut state);
    let kd = Vec3::new(0.9, 0.5, 0.25);
    let lambert = Lambert::new(kd);
    let (mut kept, mut worst) = (0, 0.0f64);
    for round in 0..1000 {
        let p = Vec3::new(uniform() * 8.0, uniform() * 8.0, uniform() * 2.0);
        let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0) * (0.1 + 3.0 * uniform());
        let surface = Surface::new(p, normal, None).unwrap();
        let count = if round % 50 == 49 { 768 } else { round % 201 };
        let odd = (round / 7) % 8;
        let mut lights = plane_lights(&mut uniform, (p, normal), count, round);
        if let Some(light) = lights.get_mut(count / 2) {
            out_of_range(light, p, odd);
        }
        let lanes = crate::LightLanes::of(&lights);
        let sum = lambert.sum_scene_coarse(Seal, &(), &surface, &lanes, count);
        let base = baseline(|| lambert.sum_scene_coarse(Seal, &(), &surface, &lanes, count));
        assert_eq!(bits(sum), bits(base), "round {round}, {count} lights");
        if count > 8 {
            let short = &lanes[..lanes.len() - 1];
            assert_eq!(
                lambert.sum_scene_coarse(Seal, &(), &surface, short, count),
                None
            );
        }
        let refused = count > 0 && (1..=3).contains(&odd);
        assert_eq!(sum.is_none(), refused, "round {round}, {count} lights");
        let Some(sum) = sum else {
            continue;
        };
        kept += 1;
        let what = format!("round {round}, {count} lights");
        worst = worst.max(assert_within_bound(kd, &surface, &lights, sum, &what));
    }
    assert!(kept > 500 && kept < 1000, "{kept} sums in range");
    assert!(worst > 0.0, "no sum was off at all");
}

/// Out of range: a light on the point, squared distances beyond
/// `2^60`, intensities beyond `2^40`, more than 64 lights, a point that
/// is not an `f32` value; in range at the edges.
#[test]
fn coarse_sums_refuse_what_they_cannot_bound() {
    let lambert = Lambert::new(Vec3::ONE);
    let surface = Surface::new(Vec3::new(1.0, 2.0, 3.0), Vec3::Z, None).unwrap();
    let above = |h: f32, i: f32| PointLight::new(Vec3::new(1.0, 2.0, 3.0 + h), Vec3::splat(i));
    assert!(coarse(&lambert, &surface, &[above(1.0, 1.0), above(0.0, 1.0)]).is_none());
    assert!(
        coarse(
            &lambert,
            &surface,
            &[above(1.0, 1.0), above(2f32.powi(31), 1.0)]
        )
        .is_none()
    );
    assert!(coarse(&lambert, &surface, &[above(2f32.powi(29), 1.0)]).is_some());
    // Near the point: at the origin, where tiny offsets are exact.
    let origin = Surface::new(Vec3::ZERO, Vec3::Z, None).unwrap();
    let near = |h: f32| PointLight::new(Vec3::new(0.0, 0.0, h), Vec3::ONE);
    assert!(coarse(&lambert, &origin, &[near(1.0), near(2f32.powi(-31))]).is_none());
    assert!(coarse(&lambert, &origin, &[near(2f32.powi(-29))]).is_some());
    assert!(coarse(&lambert, &surface, &[above(1.0, 2f32.powi(41))]).is_none());
    assert!(coarse(&lambert, &surface, &[above(1.0, 2f32.powi(40))]).is_some());
    assert!(coarse(&lambert, &surface, &vec![above(1.0, 1.0); COARSE_MAX + 1]).is_none());
    let full = coarse(&lambert, &surface, &vec![above(1.0, 1.0); COARSE_MAX]).unwrap();
    assert_eq!(full.0, DVec3::splat(COARSE_MAX as f64));
    let mut moved = surface;
    moved.point.x += 1e-12;
    assert!(sum_baseline(DVec3::ONE, &moved, &[above(1.0, 1.0)]).is_none());
    assert!(coarse(&lambert, &moved, &[above(1.0, 1.0)]).is_none());
}

/// Lights behind the surface, near it and bright, leave the sum and its
/// bound the very bits they are without them (alone: 0 and 0), while
/// lights a hair below the plane (within the rounding of the height)
/// still count in the bound.
#[test]
fn lights_below_the_plane_add_nothing_to_the_bound() {
    let lambert = Lambert::new(Vec3::new(0.9, 0.5, 0.25));
    let p = Vec3::new(3.0, -2.0, 1.5);
    let surface = Surface::new(p, Vec3::Z, None).unwrap();
    let at =
        |x: f32, y: f32, z: f32, i: f32| PointLight::new(p + Vec3::new(x, y, z), Vec3::splat(i));
    let lit: Vec<PointLight> = (0..13).map(|k| at(k as f32, 1.0, 5.0, 1.0)).collect();
    let behind: Vec<PointLight> = (0..13)
        .map(|k| at(0.1 * k as f32, 0.2, -0.25, 1e3))
        .collect();
    let (sum, error) = coarse(&lambert, &surface, &lit).unwrap();
    let mixed: Vec<PointLight> = lit.iter().chain(&behind).copied().collect();
    let (mixed_sum, mixed_error) = coarse(&lambert, &surface, &mixed).unwrap();
    assert_eq!((mixed_sum, mixed_error), (sum, error));
    // Alone they are exactly 0, with a bound of 0.
    assert_eq!(
        coarse(&lambert, &surface, &behind),
        Some((DVec3::ZERO, DVec3::ZERO))
    );
    // A hair below: counted, its term rounding to 0 or not.
    let hair = [at(1.0, 0.0, -1e-9, 1.0)];
    let (_, hair_error) = coarse(&lambert, &surface, &hair).unwrap();
    assert!(hair_error.x > 16.0 * U * 0.9, "{hair_error}");
}
