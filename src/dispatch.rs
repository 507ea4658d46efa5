//! Which compiled copy of the hot code runs (the build's statistics, the
//! cut and its sums of lights, the batch call's shared cuts and sums): on
//! `x86_64` processors with AVX2 (or AVX-512F, for the batch call's sums),
//! copies compiled for them (wider vectors, three-operand instructions),
//! picked at run time, so that a default build gets them. The build's statistics have a copy for AVX2
//! with FMA, its Morton codes one for AVX2 (four lights' integer and
//! conversion operations side by side).
//! Rust never fuses a multiply and an add on its own; where the code asks
//! for a fused one (`f64::mul_add`, in the build's moments) it is rounded
//! once in every copy (an instruction where the processor has FMA, the
//! correctly rounded library `fma` elsewhere), and every other operation is
//! exactly rounded the same way in all copies, so the results are the same
//! bits (the tests compare them). [`Lambert`](crate::Lambert)'s sum of a
//! leaf's lights is written with AVX2 instructions themselves (the
//! compiler's own vectors for it gathered the lights' coordinates one by
//! one), the same operations lane by lane as its baseline copy; so are the
//! build's direct sums of a leaf's moments (the same fused multiply-adds,
//! and the lanes' sums in the same order).
//!
//! Two ways in, and every `unsafe` call of a copy is in this file:
//!
//! * [`with_avx2`] (and [`with_avx512f_or_avx2`]) runs an
//!   `#[inline(always)]` closure from a function compiled for the feature:
//!   the closure and the `#[inline(always)]` code it calls are compiled
//!   again there. A whole hot path gets its copy this way: a point's cut,
//!   a group's cut, a group's points' sums.
//! * [`avx2_or!`] (and [`copy_or!`] for another check) calls one of two
//!   functions given by name: a kernel written with the feature's
//!   instructions themselves beside its baseline (a leaf's sums, Morton
//!   codes, a leaf's moments), or a function that calls itself (the
//!   build's recursive pass), which a closure cannot.

/// Whether the processor has `$feature` (a literal), unless a test asked
/// for the baseline copies on this thread.
macro_rules! detected {
    ($feature:tt) => {{
        #[cfg(test)]
        if BASELINE.with(core::cell::Cell::get) {
            return false;
        }
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!($feature)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }};
}

/// Runs `f`, compiled for AVX2 where the processor has it: the one way the
/// crate's hot paths (a point's cut, a group's cut, the build's passes)
/// get their AVX2 copy. `f` is called once from a function compiled with
/// AVX2 enabled; a closure called once from one place is inlined there, and
/// the `#[inline(always)]` code it calls with it, so the whole of it is
/// compiled again for AVX2 (the same operations, so the same bits).
#[inline(always)]
pub(crate) fn with_avx2<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        if avx2() {
            // SAFETY: the processor has AVX2 (`avx2` checked).
            #[allow(unsafe_code)]
            return unsafe { run_avx2(f) };
        }
    }
    f()
}

/// [`with_avx2`]'s copy compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2<T>(f: impl FnOnce() -> T) -> T {
    f()
}

/// `$avx2(args)` where the processor has AVX2, else `$baseline(args)`:
/// the runtime choice between a function compiled for AVX2
/// (`#[target_feature(enable = "avx2,fma")]`) and its baseline copy (the same
/// bits). For the copies written with AVX2 instructions themselves
/// (`_mm256_*`), and for large bodies, which [`with_avx2`] does not compile
/// for AVX2: the compiler keeps a large closure out of line, one function
/// without AVX2 that both of its callers call; an `#[inline(always)]` body
/// called from a `$avx2` of its own is inlined there. A macro rather than a
/// function taking closures: calling a function compiled for AVX2 from code
/// that is not is unsafe, so the unsafe block would stay at every caller;
/// here it is written once, after the check. The arguments are evaluated
/// in the unsafe block with the call: callers pass plain values (names,
/// fields), nothing that needs `unsafe` itself. Written as an early exit
/// from a block, the shape the compiler keeps closest to a hand-written
/// `if` and `return` where the caller is inlined (the same instructions,
/// measured; a `match` on the check took 0.4% more instructions to shade
/// a point).
macro_rules! avx2_or {
    ($avx2:path, $baseline:path, $($arg:expr),+ $(,)?) => {
        $crate::dispatch::copy_or!(avx2, $avx2, $baseline, $($arg),+)
    };
}
pub(crate) use avx2_or;

/// [`avx2_or!`] for any check of [this module](self): `$check` names one
/// of [`avx2`], [`avx2_fma`], [`avx512f`].
macro_rules! copy_or {
    ($check:ident, $fast:path, $baseline:path, $($arg:expr),+ $(,)?) => {
        'choice: {
            #[cfg(target_arch = "x86_64")]
            if $crate::dispatch::$check() {
                // SAFETY: the processor has the features `$fast` is compiled
                // for (`$check` checked).
                #[allow(unsafe_code)]
                break 'choice unsafe { $fast($($arg),+) };
            }
            $baseline($($arg),+)
        }
    };
}
pub(crate) use copy_or;

/// Runs `f` compiled for AVX-512F where the processor has it, else for
/// AVX2 where it has that, else as the baseline build (see
/// [`with_avx2`]; `f` must be an `#[inline(always)]` closure).
#[inline(always)]
pub(crate) fn with_avx512f_or_avx2<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        if avx512f() {
            // SAFETY: the processor has AVX-512F (`avx512f` checked).
            #[allow(unsafe_code)]
            return unsafe { run_avx512f(f) };
        }
    }
    with_avx2(f)
}

/// [`with_avx512f_or_avx2`]'s copy compiled for AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn run_avx512f<T>(f: impl FnOnce() -> T) -> T {
    f()
}

/// Whether the copies compiled for AVX2 may run: they are compiled with
/// FMA too (every processor with AVX2 this crate meets has it), so that a
/// fused multiply-add asked for (`f64::mul_add`, in the exact products of
/// the error-free dot products behind a term's sign) is one instruction
/// there rather than the library's `fma`.
#[inline]
pub(crate) fn avx2() -> bool {
    detected!("avx2") && detected!("fma")
}

/// Whether the copies compiled for AVX2 and FMA may run.
#[inline]
pub(crate) fn avx2_fma() -> bool {
    detected!("avx2") && detected!("fma")
}

/// Whether the copies compiled for AVX-512F may run.
#[inline]
pub(crate) fn avx512f() -> bool {
    detected!("avx512f")
}

/// Lane `i` of an AVX2 vector of four `f64`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn lane_of(v: core::arch::x86_64::__m256d, i: usize) -> f64 {
    use core::arch::x86_64::{
        _mm_cvtsd_f64, _mm_unpackhi_pd, _mm256_castpd256_pd128, _mm256_extractf128_pd,
    };
    let half = if i < 2 {
        _mm256_castpd256_pd128(v)
    } else {
        _mm256_extractf128_pd::<1>(v)
    };
    let half = if i.is_multiple_of(2) {
        half
    } else {
        _mm_unpackhi_pd(half, half)
    };
    _mm_cvtsd_f64(half)
}

/// Lane `i` of an AVX vector of eight `f32`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn lane_of_ps(v: core::arch::x86_64::__m256, i: usize) -> f32 {
    use core::arch::x86_64::{
        _mm_cvtss_f32, _mm_shuffle_ps, _mm256_castps256_ps128, _mm256_extractf128_ps,
    };
    let half = if i < 4 {
        _mm256_castps256_ps128(v)
    } else {
        _mm256_extractf128_ps::<1>(v)
    };
    let lane = match i % 4 {
        0 => half,
        1 => _mm_shuffle_ps::<1>(half, half),
        2 => _mm_shuffle_ps::<2>(half, half),
        _ => _mm_shuffle_ps::<3>(half, half),
    };
    _mm_cvtss_f32(lane)
}

#[cfg(test)]
std::thread_local! {
    /// Set by tests on their own thread to run the baseline copies.
    static BASELINE: core::cell::Cell<bool> = const { core::cell::Cell::new(false) };
}

/// Runs `f` on this thread with the baseline copies only.
#[cfg(test)]
pub(crate) fn baseline<T>(f: impl FnOnce() -> T) -> T {
    BASELINE.with(|b| b.set(true));
    let out = f();
    BASELINE.with(|b| b.set(false));
    out
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::baseline;
    use crate::testing::uniform;
    use crate::{
        BoundKind, Combined, Lambert, LightTree, Phong, PointLight, Query, ShadeResult, Threshold,
        Unoccluded,
    };

    fn lights(count: usize) -> Vec<PointLight> {
        let mut state = 7;
        (0..count)
            .map(|_| {
                let mut u = || uniform(&mut state);
                let p = Vec3::new(u() * 40.0 - 20.0, u() * 40.0 - 20.0, u() * 6.0 + 0.5);
                PointLight::new(p, Vec3::new(u(), u() * 2.0, u() * 0.5))
            })
            .collect()
    }

    fn bits(r: &ShadeResult) -> ([u64; 3], [u64; 3], u32, u32) {
        (
            r.radiance.to_array().map(f64::to_bits),
            r.error_bound.to_array().map(f64::to_bits),
            r.nodes_evaluated,
            r.lights_evaluated,
        )
    }

    /// Single points: the copy compiled for AVX2 (where the processor has
    /// it) and the baseline give the same bits, for both bounds, a sum of
    /// shaders and thresholds with and without interpolation.
    #[test]
    fn both_copies_of_the_cut_give_the_same_bits() {
        let tree = LightTree::build(&lights(3000)).unwrap();
        let thresholds = [
            Threshold::relative(0.01),
            Threshold::relative(0.05).with_interpolation(2.0),
            Threshold::absolute(1e-3),
        ];
        let mut state = 11;
        let mut lambert = tree.shading(Lambert::new(Vec3::new(0.8, 0.5, 0.3)));
        let mut taylor = tree.shading(Lambert::new(Vec3::splat(0.5)).with_bound(BoundKind::Taylor));
        let mut glossy = tree.shading(Combined::new(
            Lambert::new(Vec3::splat(0.4)),
            Phong::new(Vec3::splat(0.3), 30.0),
        ));
        for _ in 0..200 {
            let mut u = || uniform(&mut state);
            let point = Vec3::new(u() * 44.0 - 22.0, u() * 44.0 - 22.0, u() * 2.0 - 1.0);
            let normal = Vec3::new(u() - 0.5, u() - 0.5, u() + 0.2);
            let view = Vec3::new(u() - 0.5, u() - 0.5, u() + 0.1);
            let query = Query::new(point, normal).unwrap();
            let with_view = query.with_view(view).unwrap();
            for t in thresholds {
                let a = lambert.shade_query(&query, t, Unoccluded).unwrap();
                let b = baseline(|| lambert.shade_query(&query, t, Unoccluded).unwrap());
                assert_eq!(bits(&a), bits(&b), "{a:?} {b:?}");
                let a = taylor.shade_query(&query, t, Unoccluded).unwrap();
                let b = baseline(|| taylor.shade_query(&query, t, Unoccluded).unwrap());
                assert_eq!(bits(&a), bits(&b), "{a:?} {b:?}");
                let a = glossy.shade_query(&with_view, t, Unoccluded).unwrap();
                let b = baseline(|| glossy.shade_query(&with_view, t, Unoccluded).unwrap());
                assert_eq!(bits(&a), bits(&b), "{a:?} {b:?}");
            }
        }
    }

    /// The batch call: shared cuts and points alone, both copies, the same
    /// bits.
    #[test]
    fn both_copies_of_the_batch_call_give_the_same_bits() {
        let tree = LightTree::build(&lights(3000)).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));
        let mut queries = Vec::new();
        for y in 0..48 {
            for x in 0..48 {
                let point = Vec3::new(x as f32 * 0.8 - 19.0, y as f32 * 0.8 - 19.0, 0.0);
                queries.push(Query::new(point, Vec3::Z).unwrap());
            }
        }
        for t in [
            Threshold::relative(0.01),
            Threshold::relative(0.05).with_interpolation(2.0),
        ] {
            let start = shading
                .shade(Vec3::ZERO, Vec3::Z, Threshold::absolute(f64::INFINITY))
                .unwrap();
            let mut a = vec![start; queries.len()];
            let mut b = a.clone();
            let stats_a = shading
                .shade_batch(&queries, t, Unoccluded, &mut a)
                .unwrap();
            let stats_b = baseline(|| {
                shading
                    .shade_batch(&queries, t, Unoccluded, &mut b)
                    .unwrap()
            });
            assert!(stats_a.shared_points > 0, "{stats_a:?}");
            assert_eq!(stats_a, stats_b);
            for (a, b) in a.iter().zip(&b) {
                assert_eq!(bits(a), bits(b), "{a:?} {b:?}");
            }
        }
    }
}
