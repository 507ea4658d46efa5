//! The checks of the lights before a build or refit touches anything:
//! every coordinate finite and within [`PointLight::MAX_COORDINATE`], every
//! intensity channel finite and not negative; the first light that fails
//! is named. A build takes the scene's box from the same read.

use glam::Vec3;

use super::pool::Pool;
use crate::geometry::Aabb;
use crate::{BuildError, PointLight};

/// `0..n` cut into [`Pool::parts`] ranges of nearly equal length (one when
/// the pool is the calling thread).
fn chunks(n: usize, pool: Pool) -> Vec<core::ops::Range<usize>> {
    let parts = pool.parts().clamp(1, n.max(1));
    (0..parts)
        .map(|k| k * n / parts..(k + 1) * n / parts)
        .collect()
}

/// The first light that cannot be built, as [`BuildError`], checked in
/// parts on `pool` (the first failing part's first error).
pub(super) fn check_lights(lights: &[PointLight], pool: Pool) -> Result<(), BuildError> {
    check_and_bound(lights, pool).map(|_| ())
}

/// [`check_lights`], and the box of the lights when they can be built: one
/// read of the lights, in parts on `pool`.
pub(super) fn check_and_bound(lights: &[PointLight], pool: Pool) -> Result<Aabb, BuildError> {
    let parts = pool.map(&chunks(lights.len(), pool), |r| {
        let part = &lights[r.clone()];
        let (aabb, valid) = bound_part(part);
        if valid {
            Ok(aabb)
        } else {
            // Some light is bad: the slower check names the first.
            check_range(part).map_err(|e| shifted(e, r.start))?;
            debug_assert!(false, "bound_part accepts exactly what check_range accepts");
            Ok(aabb)
        }
    });
    parts
        .into_iter()
        .try_fold(Aabb::EMPTY, |b, part| Ok(b.union(part?)))
}

/// Lights [`bound_part`] reads at once: their positions and intensities,
/// 24 values, as six vectors of four.
const BOUND_LIGHTS: usize = 4;

/// The box of `lights` and whether every light passes [`check_range`],
/// without a branch per light: a coordinate passes when its magnitude is
/// at most [`PointLight::MAX_COORDINATE`] (false for NaN and infinities),
/// an intensity channel when it lies in `[0, f32::MAX]` (false for NaN,
/// infinities and negative values; `-0` passes, as there).
///
/// [`BOUND_LIGHTS`] lights at a time, as one array of their 24 values
/// (which the compiler keeps as six vectors): per value, its smallest and
/// largest so far, and whether some value was NaN. Every value passes when
/// there was no NaN and each value's extremes lie in its range; the box is
/// the positions' extremes. The lights left over are taken one by one.
/// The same box as light by light but perhaps for the sign of a zero
/// bound (`-0` and `0` compare equal, and which of them a minimum keeps
/// depends on the order), which the Morton grid over the box does not
/// see. Branch-free groups take a fraction of the instructions of light
/// by light (`docs/tuning.md` records the counts); `cargo run --release -p
/// manylights-report -- bounds` times the build it is part of.
fn bound_part(lights: &[PointLight]) -> (Aabb, bool) {
    const VALUES: usize = 6 * BOUND_LIGHTS;
    // Per value of a group, the ends of its range.
    const LOW: [f32; VALUES] = {
        let mut out = [0.0; VALUES];
        let mut k = 0;
        while k < VALUES {
            out[k] = if k % 6 < 3 {
                -PointLight::MAX_COORDINATE
            } else {
                0.0
            };
            k += 1;
        }
        out
    };
    const HIGH: [f32; VALUES] = {
        let mut out = [0.0; VALUES];
        let mut k = 0;
        while k < VALUES {
            out[k] = if k % 6 < 3 {
                PointLight::MAX_COORDINATE
            } else {
                f32::MAX
            };
            k += 1;
        }
        out
    };
    let mut lo = [f32::INFINITY; VALUES];
    let mut hi = [f32::NEG_INFINITY; VALUES];
    let mut nan = [0u32; 4];
    let groups = lights.chunks_exact(BOUND_LIGHTS);
    let rest = groups.remainder();
    for group in groups {
        let mut v = [0.0f32; VALUES];
        for (v, l) in v.chunks_exact_mut(6).zip(group) {
            v[..3].copy_from_slice(&l.position.to_array());
            v[3..].copy_from_slice(&l.intensity.to_array());
        }
        // Four lanes at a time, so that the NaN flags are one vector.
        for q in 0..VALUES / 4 {
            for (k, nan) in nan.iter_mut().enumerate() {
                let i = 4 * q + k;
                let x = v[i];
                // As `Vec3::min` and `Vec3::max` compare (a NaN is not
                // kept: the flags see it).
                lo[i] = if lo[i] < x { lo[i] } else { x };
                hi[i] = if hi[i] > x { hi[i] } else { x };
                *nan |= u32::from(x.is_nan());
            }
        }
    }
    let (mut aabb, mut valid) = bound_each(rest);
    for (lo, hi) in lo.chunks_exact(6).zip(hi.chunks_exact(6)) {
        aabb = aabb.union(Aabb {
            min: Vec3::from_slice(&lo[..3]),
            max: Vec3::from_slice(&hi[..3]),
        });
    }
    valid &= nan == [0; 4];
    for i in 0..VALUES {
        valid &= lo[i] >= LOW[i] && hi[i] <= HIGH[i];
    }
    (aabb, valid)
}

/// [`bound_part`] light by light.
fn bound_each(lights: &[PointLight]) -> (Aabb, bool) {
    let max = Vec3::splat(PointLight::MAX_COORDINATE);
    let mut aabb = Aabb::EMPTY;
    let mut valid = true;
    for l in lights {
        let (p, i) = (l.position, l.intensity);
        valid &= p.abs().cmple(max).all() & i.cmpge(Vec3::ZERO).all() & i.cmple(Vec3::MAX).all();
        aabb = aabb.union_point(p);
    }
    (aabb, valid)
}

/// `error` with the light's index moved up by `by`.
fn shifted(error: BuildError, by: usize) -> BuildError {
    match error {
        BuildError::NonFinitePosition { index } => {
            BuildError::NonFinitePosition { index: index + by }
        }
        BuildError::PositionOutOfRange { index, max } => BuildError::PositionOutOfRange {
            index: index + by,
            max,
        },
        BuildError::NonFiniteIntensity { index } => {
            BuildError::NonFiniteIntensity { index: index + by }
        }
        BuildError::NegativeIntensity { index } => {
            BuildError::NegativeIntensity { index: index + by }
        }
        other => other,
    }
}

/// [`check_lights`] on one part, indices relative to it.
fn check_range(lights: &[PointLight]) -> Result<(), BuildError> {
    for (index, l) in lights.iter().enumerate() {
        if !l.position.is_finite() {
            return Err(BuildError::NonFinitePosition { index });
        }
        if l.position.abs().max_element() > PointLight::MAX_COORDINATE {
            return Err(BuildError::PositionOutOfRange {
                index,
                max: PointLight::MAX_COORDINATE,
            });
        }
        if !l.intensity.is_finite() {
            return Err(BuildError::NonFiniteIntensity { index });
        }
        // `!(x >= 0)` would also catch NaN, already excluded above.
        if l.intensity.min_element() < 0.0 {
            return Err(BuildError::NegativeIntensity { index });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::{bound_each, bound_part, check_range};
    use crate::PointLight;

    /// The branch-free check accepts exactly the lights that the checks
    /// one by one accept, on the edges of each condition, the light at
    /// every place of a group of lights read at once and among the lights
    /// left over; and its box is the box light by light (up to the sign
    /// of a zero bound).
    #[test]
    fn the_fast_check_accepts_what_the_checks_accept() {
        let max = PointLight::MAX_COORDINATE;
        let coordinates = [
            0.0,
            -0.0,
            1.5,
            -max,
            max,
            f32::from_bits(max.to_bits() + 1),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let channels = [
            0.0,
            -0.0,
            2.0,
            f32::MAX,
            -f32::MIN_POSITIVE,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        for (a, &c) in coordinates.iter().enumerate() {
            for (b, &i) in channels.iter().enumerate() {
                for axis in 0..3 {
                    let mut light = PointLight::new(Vec3::ONE, Vec3::ONE);
                    light.position[axis] = c;
                    light.intensity[(axis + a + b) % 3] = i;
                    for len in 1..=9 {
                        for at in 0..len {
                            let mut lights: Vec<PointLight> = (0..len)
                                .map(|k| PointLight::new(Vec3::splat(k as f32 - 2.0), Vec3::ONE))
                                .collect();
                            lights[at] = light;
                            let (aabb, valid) = bound_part(&lights);
                            assert_eq!(
                                valid,
                                check_range(&lights).is_ok(),
                                "coordinate {c}, channel {i}, light {at} of {len}"
                            );
                            if valid {
                                assert_eq!(aabb, bound_each(&lights).0);
                            }
                        }
                    }
                }
            }
        }
    }
}
