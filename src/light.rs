//! Point lights, the input of the hierarchy.

use glam::Vec3;

/// An isotropic point light: a position and an RGB intensity.
///
/// The intensity is radiant intensity per channel (radiance units times
/// squared distance): a light at distance `d` straight above a diffuse surface
/// of albedo `kd` contributes `intensity * kd / d^2` (see the crate docs for the
/// full model). Every channel must be finite and `>= 0`, and every coordinate
/// finite with magnitude at most [`PointLight::MAX_COORDINATE`];
/// [`LightTree::build`](crate::LightTree::build) rejects anything else with a
/// [`BuildError`](crate::BuildError) naming the light.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointLight {
    /// World-space position.
    pub position: Vec3,
    /// RGB radiant intensity, each channel `>= 0`.
    pub intensity: Vec3,
}

impl PointLight {
    /// Largest supported magnitude of a light coordinate. It keeps squared
    /// distances between lights (at most `(2e18)^2 * 3 = 1.2e37`) within
    /// `f32`, where node second moments are stored.
    pub const MAX_COORDINATE: f32 = 1e18;

    /// A light at `position` with RGB `intensity`.
    pub const fn new(position: Vec3, intensity: Vec3) -> Self {
        Self {
            position,
            intensity,
        }
    }

    /// The scalar weight this crate gives the light when it averages positions:
    /// its largest channel.
    ///
    /// The largest channel is used (rather than luminance or the channel sum)
    /// because it dominates every channel (`intensity[k] <= weight()` for each
    /// `k`): a node's centroid then stays where every channel has weight.
    /// Per-channel first and second moments and harmonic norms (see
    /// [`Node`](crate::shader::Node)) carry what one scalar weight cannot. For grey
    /// lights it is the common channel value.
    #[must_use]
    pub fn weight(&self) -> f32 {
        self.intensity.max_element()
    }
}

/// Eight lights side by side, one array of eight per quantity: what a
/// shader's [`sum_lanes_coarse`](crate::shader::Shader::sum_lanes_coarse) reads in
/// place of eight [`PointLight`]s, so that a vector register loads each
/// quantity of all eight at once.
///
/// Lane `k` of a group holds one light; in the last group of a run of
/// lights, the lanes past the last light repeat it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub struct LightLanes {
    /// Position, x.
    pub x: [f32; 8],
    /// Position, y.
    pub y: [f32; 8],
    /// Position, z.
    pub z: [f32; 8],
    /// Intensity, red.
    pub red: [f32; 8],
    /// Intensity, green.
    pub green: [f32; 8],
    /// Intensity, blue.
    pub blue: [f32; 8],
}

impl LightLanes {
    /// `lights` side by side, eight a group (the last group's spare lanes
    /// repeating the last light); empty for no lights.
    #[must_use]
    pub fn of(lights: &[PointLight]) -> Vec<Self> {
        lights
            .chunks(8)
            .map(|chunk| {
                let at = |k: usize| chunk[k.min(chunk.len() - 1)];
                let lane = |f: fn(&PointLight) -> f32| core::array::from_fn(|k| f(&at(k)));
                Self {
                    x: lane(|l| l.position.x),
                    y: lane(|l| l.position.y),
                    z: lane(|l| l.position.z),
                    red: lane(|l| l.intensity.x),
                    green: lane(|l| l.intensity.y),
                    blue: lane(|l| l.intensity.z),
                }
            })
            .collect()
    }
}
