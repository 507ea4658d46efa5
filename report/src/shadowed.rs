//! The two baselines that only make sense with occluders: the exact
//! shadowed sum and Ward's adaptive shadow testing.
//!
//! * [`ShadowLights::exact`] is "standard ray tracing" with shadows: every
//!   light's contribution, one shadow ray for each light that can contribute
//!   (above the tangent plane). It equals the crate's `exact_query` with the host
//!   (to `f32` rounding), which the report uses as the reference and which
//!   casts a ray for every light. Both it and Ward compute the unoccluded
//!   terms of all lights in a vectorized `f32` loop, as [`crate::exact`]
//!   does, so that the baselines pay for their shadow rays and not for a
//!   slow loop.
//! * [`Ward`] is Ward's adaptive shadow testing (Ward 1991, "Adaptive Shadow
//!   Testing for Ray Tracing"). Per shading point: every light's unoccluded
//!   contribution; lights in decreasing order of contribution
//!   (largest channel); a shadow ray for each in turn until the sum of the
//!   untested lights' unoccluded contributions (each by its largest channel)
//!   is below `t` times the largest channel of the visible radiance
//!   accumulated so far; the untested remainder is then added times the
//!   hit rate of the tested lights, `visible / tested` counted in lights,
//!   1/2 if none was tested (the contributions are computed in `f32`, which
//!   changes nothing at the errors Ward's thresholds allow). This is the
//!   rule of Radiance's `direct()` with `-dt t -dc 1` (`-dc 1` compares the
//!   whole untested remainder; smaller values compare only the next `n^dc`
//!   lights), without Radiance's per-light hit statistics gathered across
//!   the image (every point here is independent). The order is found in
//!   growing blocks (select the next block's lights in linear time, then
//!   sort the block), so that a point that stops early does not sort every
//!   light; ties are broken by light index.

use glam::{DVec3, Vec3};
use manylights::{PointLight, Visibility};

/// Lights per chunk of [`ShadowLights`]' position arrays.
const LANES: usize = 8;

/// Positions of [`LANES`] lights, structure-of-arrays.
#[derive(Clone, Copy, Debug, Default)]
struct Chunk {
    position: [[f32; LANES]; 3],
}

/// The lights of a Lambert scene as the two occluded baselines read them:
/// positions in `f32` structure-of-arrays chunks, so that the unoccluded
/// geometric term `max(0, n.(x - p)) / d^3` of every light is computed by a
/// vectorized loop (as the exact sum of [`crate::exact`]), and per light the
/// colour `I kd` and its largest channel.
pub struct ShadowLights {
    chunks: Vec<Chunk>,
    /// `I_i * kd` per light.
    colour: Vec<Vec3>,
    /// Largest channel of `colour`: the contribution's largest channel per
    /// unit geometric term.
    weight: Vec<f32>,
    position: Vec<Vec3>,
    /// Scratch: the geometric terms of the last shading point (padded to a
    /// whole number of chunks).
    geometric: Vec<f32>,
}

impl ShadowLights {
    /// The lights, for a Lambert material of albedo `kd`.
    pub fn new(lights: &[PointLight], kd: Vec3) -> Self {
        let mut chunks = vec![Chunk::default(); lights.len().div_ceil(LANES)];
        for (i, light) in lights.iter().enumerate() {
            for k in 0..3 {
                chunks[i / LANES].position[k][i % LANES] = light.position[k];
            }
        }
        let colour: Vec<Vec3> = lights.iter().map(|l| l.intensity * kd).collect();
        Self {
            weight: colour.iter().map(|c| c.max_element()).collect(),
            position: lights.iter().map(|l| l.position).collect(),
            geometric: vec![0.0; chunks.len() * LANES],
            colour,
            chunks,
        }
    }

    /// Fills `self.geometric` with every light's `max(0, n.(x - p)) / d^3`
    /// (0 for a light on the point), `n` the unit normal.
    fn geometric_terms(&mut self, p: Vec3, n: Vec3) {
        for (c, out) in self
            .chunks
            .iter()
            .zip(self.geometric.chunks_exact_mut(LANES))
        {
            for (l, out) in out.iter_mut().enumerate() {
                let dx = c.position[0][l] - p.x;
                let dy = c.position[1][l] - p.y;
                let dz = c.position[2][l] - p.z;
                let d2 = dx * dx + dy * dy + dz * dz;
                let inv_d = if d2 > 0.0 { 1.0 / d2.sqrt() } else { 0.0 };
                let z = n.x * dx + n.y * dy + n.z * dz;
                *out = z.max(0.0) * inv_d * inv_d * inv_d;
            }
        }
    }

    /// The exact shadowed sum at `point` with unit `normal`: every light's
    /// contribution, with one shadow ray for each light above the tangent
    /// plane. Returns the radiance and the number of shadow rays.
    pub fn exact(&mut self, point: Vec3, normal: Vec3, host: &mut impl Visibility) -> (DVec3, u32) {
        self.geometric_terms(point, normal);
        let mut sum = DVec3::ZERO;
        let mut rays = 0;
        for (i, &g) in self.geometric[..self.position.len()].iter().enumerate() {
            if g > 0.0 {
                rays += 1;
                if host.visible(point, self.position[i]) {
                    sum += (self.colour[i] * g).as_dvec3();
                }
            }
        }
        (sum, rays)
    }
}

/// Ward's adaptive shadow testing (see the module comment), with scratch
/// space reused across calls.
#[derive(Default)]
pub struct Ward {
    /// Contributing lights, each as its contribution's largest channel
    /// (`f32` bits, which order as the values do for positive floats) in the
    /// high half and its index in the low half: sorting these sorts the
    /// lights by contribution.
    order: Vec<u64>,
}

/// Ward's candidates are put in order in blocks: the largest [`FIRST_BLOCK`]
/// first (selected in linear time, then sorted), then the next
/// [`BLOCK_GROWTH`] times as many, and so on, so that a point that stops
/// after a few tests does not pay for sorting every light.
const FIRST_BLOCK: usize = 256;
const BLOCK_GROWTH: usize = 4;

impl Ward {
    /// Shades `point` with unit `normal` and threshold `t`: returns the
    /// estimate and the number of shadow rays. `t = 0` tests every
    /// contributing light (the exact shadowed sum).
    pub fn shade(
        &mut self,
        lights: &mut ShadowLights,
        point: Vec3,
        normal: Vec3,
        t: f64,
        host: &mut impl Visibility,
    ) -> (DVec3, u32) {
        lights.geometric_terms(point, normal);
        let order = &mut self.order;
        order.clear();
        let mut total = DVec3::ZERO;
        let mut total_key = 0.0;
        for (i, &g) in lights.geometric[..lights.position.len()].iter().enumerate() {
            if g > 0.0 {
                let key = lights.weight[i] * g;
                order.push((u64::from(key.to_bits()) << 32) | i as u64);
                total += (lights.colour[i] * g).as_dvec3();
                total_key += f64::from(key);
            }
        }
        let descending = |a: &u64, b: &u64| b.cmp(a);
        let mut visible = DVec3::ZERO;
        let mut tested = DVec3::ZERO;
        let mut tested_key = 0.0;
        let (mut rays, mut hits) = (0u32, 0u32);
        let mut start = 0;
        let mut block = FIRST_BLOCK;
        'blocks: while start < order.len() {
            let end = (start + block).min(order.len());
            if end < order.len() {
                order[start..].select_nth_unstable_by(end - start - 1, descending);
            }
            order[start..end].sort_unstable_by(descending);
            for &c in &order[start..end] {
                if total_key - tested_key < t * visible.max_element() {
                    break 'blocks;
                }
                let i = (c & u64::from(u32::MAX)) as usize;
                let f = (lights.colour[i] * lights.geometric[i]).as_dvec3();
                rays += 1;
                tested_key += f64::from(f32::from_bits((c >> 32) as u32));
                tested += f;
                if host.visible(point, lights.position[i]) {
                    hits += 1;
                    visible += f;
                }
            }
            start = end;
            block *= BLOCK_GROWTH;
        }
        let untested = order.len() - rays as usize;
        let radiance = if untested == 0 {
            visible
        } else {
            let rate = if rays > 0 {
                f64::from(hits) / f64::from(rays)
            } else {
                0.5
            };
            visible + (total - tested).max(DVec3::ZERO) * rate
        };
        (radiance, rays)
    }
}
