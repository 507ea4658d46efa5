//! What the unit tests share.

/// A small linear congruential generator: the next value of `state`, as a
/// number in `[0, 1)`. Tests that compare two runs (two compiled copies,
/// nodes together and alone) draw the same inputs for both.
pub(crate) fn uniform(state: &mut u64) -> f32 {
    *state = state
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    (*state >> 40) as f32 / (1u64 << 24) as f32
}
