//! A glTF 2.0 scene as the `gltf` example renders it: triangles (occluders
//! and shading surfaces, with their base colours), `KHR_lights_punctual`
//! point and spot lights (spots with their cones, as `Emission::spot`),
//! and a camera.
//! Read with the `gltf` crate from a `.glb` file, or a `.gltf` file whose
//! buffers are files beside it; written to `.glb` bytes by
//! [`write_glb`] (the built-in scene and the tests).

use std::path::Path;

use glam::{Mat4, Vec3};
use gltf::khr_lights_punctual::Kind;
use manylights::{Emission, Emitter, PointLight};
use serde_json::json;

/// A camera: eye, a point it looks at, up, vertical field of view in
/// radians.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub yfov: f32,
}

/// What the example renders.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// World-space triangles and each one's base colour.
    pub triangles: Vec<[Vec3; 3]>,
    pub albedo: Vec<Vec3>,
    /// The triangles of each mesh instance (a node's mesh, all its
    /// primitives), as ranges of `triangles`.
    pub meshes: Vec<std::ops::Range<usize>>,
    /// The point lights (isotropic) and spot lights (glTF spots along
    /// their node's `-z`), in the order the nodes are visited.
    pub lights: Vec<Emitter>,
    /// How many of `lights` are spot lights, and directional lights
    /// skipped.
    pub spots: usize,
    pub directional: usize,
    /// Triangles of zero area, dropped (they block and reflect nothing).
    pub degenerate: usize,
    /// The first camera of the scene, if any.
    pub view: Option<View>,
}

/// Why a scene could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    #[error("not a valid glTF 2.0 file: {0}")]
    Gltf(#[from] gltf::Error),
    #[error("buffer {0}: data URIs are not read; convert the scene to .glb")]
    DataUri(usize),
    #[error("buffer {index}: {uri:?} could not be read: {source}")]
    Buffer {
        index: usize,
        uri: String,
        source: std::io::Error,
    },
    #[error("buffer {index} holds {len} bytes, {needed} declared")]
    ShortBuffer {
        index: usize,
        len: usize,
        needed: usize,
    },
    #[error("buffer {0} is the binary chunk, which the file lacks")]
    MissingBinary(usize),
    #[error("mesh {0}: a triangle primitive without positions")]
    NoPositions(usize),
    #[error(
        "accessor {0}: unreadable (sparse, of the wrong type, empty, or past the end of its \
         buffer)"
    )]
    BadAccessor(usize),
    #[error("mesh {mesh}: index {index} out of range ({vertices} vertices)")]
    IndexOutOfRange {
        mesh: usize,
        index: u32,
        vertices: usize,
    },
    #[error("mesh {0}: a vertex is not finite")]
    NonFinite(usize),
    #[error("the scene has no triangles (of non-zero area)")]
    NoTriangles,
    #[error("the scene has no point or spot lights (KHR_lights_punctual)")]
    NoLights,
    #[error("light {0} has a non-finite or negative colour or intensity")]
    BadLight(usize),
    #[error("a node's transform is not finite")]
    BadTransform,
}

/// Checks that `accessor` can be read as `count` elements of the given
/// types from `buffers` without running past its buffer view or buffer, as
/// the `gltf` crate's readers assume (they panic otherwise).
fn check_accessor(
    accessor: &gltf::Accessor,
    types: &[gltf::accessor::DataType],
    dimensions: gltf::accessor::Dimensions,
    buffers: &[Vec<u8>],
) -> Result<(), LoadError> {
    let bad = LoadError::BadAccessor(accessor.index());
    if accessor.sparse().is_some()
        || !types.contains(&accessor.data_type())
        || accessor.dimensions() != dimensions
        || accessor.count() == 0
    {
        return Err(bad);
    }
    let view = accessor
        .view()
        .ok_or(LoadError::BadAccessor(accessor.index()))?;
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    let buffer = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let last = (accessor.count() - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(accessor.offset()))
        .and_then(|n| n.checked_add(size));
    let fits = stride >= size
        && last.is_some_and(|end| end <= view.length())
        && view
            .offset()
            .checked_add(view.length())
            .is_some_and(|end| end <= buffer);
    if fits { Ok(()) } else { Err(bad) }
}

/// Whether a triangle has zero area (in `f64`, as the occluders test it).
fn degenerate(t: &[Vec3; 3]) -> bool {
    let [a, b, c] = t.map(Vec3::as_dvec3);
    (b - a).cross(c - a) == glam::DVec3::ZERO
}

/// Reads a scene from the bytes of a `.glb` or `.gltf` file; `base` is the
/// folder external buffers are read from.
pub fn load(bytes: &[u8], base: Option<&Path>) -> Result<Scene, LoadError> {
    let gltf = gltf::Gltf::from_slice(bytes)?;
    let mut buffers = Vec::new();
    for buffer in gltf.buffers() {
        let index = buffer.index();
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => {
                gltf.blob.clone().ok_or(LoadError::MissingBinary(index))?
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                return Err(LoadError::DataUri(index));
            }
            gltf::buffer::Source::Uri(uri) => {
                let path = base.unwrap_or(Path::new(".")).join(uri);
                std::fs::read(&path).map_err(|source| LoadError::Buffer {
                    index,
                    uri: uri.to_string(),
                    source,
                })?
            }
        };
        if data.len() < buffer.length() {
            return Err(LoadError::ShortBuffer {
                index,
                len: data.len(),
                needed: buffer.length(),
            });
        }
        buffers.push(data);
    }
    let mut scene = Scene::default();
    let roots: Vec<gltf::Node> = match gltf.default_scene().or_else(|| gltf.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => gltf.nodes().collect(),
    };
    let mut stack: Vec<(gltf::Node, Mat4)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    // Bounded by the number of nodes visited, against cyclic hierarchies
    // (which validation rejects, but a file need not be validated).
    let mut budget = 16 * gltf.nodes().len() + 16;
    while let Some((node, parent)) = stack.pop() {
        budget = budget.checked_sub(1).ok_or(LoadError::BadTransform)?;
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(LoadError::BadTransform);
        }
        if let Some(mesh) = node.mesh() {
            let first = scene.triangles.len();
            for primitive in mesh.primitives() {
                if primitive.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                use gltf::accessor::{DataType, Dimensions};
                let positions = primitive
                    .get(&gltf::Semantic::Positions)
                    .ok_or(LoadError::NoPositions(mesh.index()))?;
                check_accessor(&positions, &[DataType::F32], Dimensions::Vec3, &buffers)?;
                let indices = primitive.indices();
                if let Some(indices) = &indices {
                    let types = [DataType::U8, DataType::U16, DataType::U32];
                    check_accessor(indices, &types, Dimensions::Scalar, &buffers)?;
                }
                let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                let positions: Vec<Vec3> = reader
                    .read_positions()
                    .ok_or(LoadError::NoPositions(mesh.index()))?
                    .map(|p| world.transform_point3(Vec3::from(p)))
                    .collect();
                if !positions.iter().all(|p| p.is_finite()) {
                    return Err(LoadError::NonFinite(mesh.index()));
                }
                let indices: Vec<u32> = match (indices, reader.read_indices()) {
                    (None, _) => (0..positions.len() as u32).collect(),
                    (Some(_), Some(i)) => i.into_u32().collect(),
                    (Some(a), None) => return Err(LoadError::BadAccessor(a.index())),
                };
                let colour = primitive
                    .material()
                    .pbr_metallic_roughness()
                    .base_color_factor();
                let albedo = Vec3::new(colour[0], colour[1], colour[2]);
                for t in indices.chunks_exact(3) {
                    let mut corners = [Vec3::ZERO; 3];
                    for (corner, &index) in corners.iter_mut().zip(t) {
                        *corner =
                            *positions
                                .get(index as usize)
                                .ok_or(LoadError::IndexOutOfRange {
                                    mesh: mesh.index(),
                                    index,
                                    vertices: positions.len(),
                                })?;
                    }
                    if degenerate(&corners) {
                        scene.degenerate += 1;
                    } else {
                        scene.triangles.push(corners);
                        scene.albedo.push(albedo);
                    }
                }
            }
            if scene.triangles.len() > first {
                scene.meshes.push(first..scene.triangles.len());
            }
        }
        if let Some(light) = node.light() {
            let index = light.index();
            let colour = Vec3::from(light.color()) * light.intensity();
            if !(colour.is_finite() && colour.cmpge(Vec3::ZERO).all()) {
                return Err(LoadError::BadLight(index));
            }
            let at = world.transform_point3(Vec3::ZERO);
            match light.kind() {
                Kind::Point => scene.lights.push(PointLight::new(at, colour).into()),
                Kind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    // A spot shines down its node's local -z.
                    let axis = world.transform_vector3(-Vec3::Z);
                    let spot = Emission::spot(axis, inner_cone_angle, outer_cone_angle);
                    scene.spots += 1;
                    scene
                        .lights
                        .push(PointLight::new(at, colour).with_emission(spot));
                }
                Kind::Directional => scene.directional += 1,
            }
        }
        if let (Some(camera), None) = (node.camera(), scene.view)
            && let gltf::camera::Projection::Perspective(p) = camera.projection()
        {
            // glTF cameras look down their local -z, +y up.
            scene.view = Some(View {
                eye: world.transform_point3(Vec3::ZERO),
                target: world.transform_point3(-Vec3::Z),
                up: world.transform_vector3(Vec3::Y),
                yfov: p.yfov(),
            });
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    if scene.triangles.is_empty() {
        return Err(LoadError::NoTriangles);
    }
    if scene.lights.is_empty() {
        return Err(LoadError::NoLights);
    }
    Ok(scene)
}

/// A light of a scene to write: position, colour, intensity, and whether
/// it is a spot light (pointing down).
#[derive(Clone, Copy, Debug)]
pub struct LightSpec {
    pub position: Vec3,
    pub colour: Vec3,
    pub intensity: f32,
    pub spot: bool,
}

/// A mesh of a scene to write: positions, indices, base colour.
#[derive(Clone, Debug)]
pub struct MeshSpec {
    pub positions: Vec<Vec3>,
    pub indices: Vec<u32>,
    pub colour: Vec3,
}

/// Writes `.glb` bytes: one node per mesh and per light
/// (`KHR_lights_punctual`), and a perspective camera node if `view` is
/// given, all under one scene.
pub fn write_glb(meshes: &[MeshSpec], lights: &[LightSpec], view: Option<View>) -> Vec<u8> {
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut json_meshes, mut materials, mut nodes) =
        (vec![], vec![], vec![], vec![], vec![]);
    for (m, mesh) in meshes.iter().enumerate() {
        let (min, max) = mesh
            .positions
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let start = bin.len();
        for p in &mesh.positions {
            for v in p.to_array() {
                bin.extend(v.to_le_bytes());
            }
        }
        views.push(json!({"buffer": 0, "byteOffset": start, "byteLength": bin.len() - start}));
        accessors.push(json!({
            "bufferView": views.len() - 1, "componentType": 5126, "count": mesh.positions.len(),
            "type": "VEC3", "min": min.to_array(), "max": max.to_array()
        }));
        let start = bin.len();
        for i in &mesh.indices {
            bin.extend(i.to_le_bytes());
        }
        views.push(json!({"buffer": 0, "byteOffset": start, "byteLength": bin.len() - start}));
        accessors.push(json!({
            "bufferView": views.len() - 1, "componentType": 5125, "count": mesh.indices.len(),
            "type": "SCALAR"
        }));
        let c = mesh.colour;
        materials.push(json!({"pbrMetallicRoughness": {"baseColorFactor": [c.x, c.y, c.z, 1.0]}}));
        json_meshes.push(json!({"primitives": [{
            "attributes": {"POSITION": accessors.len() - 2},
            "indices": accessors.len() - 1, "material": m
        }]}));
        nodes.push(json!({"mesh": m}));
    }
    let json_lights: Vec<_> = lights
        .iter()
        .map(|l| {
            if l.spot {
                json!({"type": "spot", "color": l.colour.to_array(), "intensity": l.intensity,
                       "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}})
            } else {
                json!({"type": "point", "color": l.colour.to_array(), "intensity": l.intensity})
            }
        })
        .collect();
    for (k, l) in lights.iter().enumerate() {
        // A light node without rotation: a spot light shines down its
        // local -z, which is down in these z-up scenes.
        nodes.push(json!({
            "translation": l.position.to_array(),
            "extensions": {"KHR_lights_punctual": {"light": k}}
        }));
    }
    let mut cameras = vec![];
    if let Some(v) = view {
        // The node's rotation turns -z towards the target, +y up.
        let back = (v.eye - v.target).normalize();
        let right = v.up.cross(back).normalize();
        let rotation =
            glam::Quat::from_mat3(&glam::Mat3::from_cols(right, back.cross(right), back));
        cameras.push(json!({"type": "perspective", "perspective": {
            "yfov": v.yfov, "znear": 0.01, "aspectRatio": 16.0 / 9.0
        }}));
        nodes.push(json!({
            "camera": 0, "translation": v.eye.to_array(), "rotation": rotation.to_array()
        }));
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut document = json!({
        "asset": {"version": "2.0", "generator": "manylights-mesh gltf example"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": json_lights}},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": json_meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    if !cameras.is_empty() {
        document["cameras"] = json!(cameras);
    }
    let mut text = serde_json::to_vec(&document).expect("a JSON value serializes");
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: (12 + 8 + text.len() + 8 + bin.len()) as u32,
        },
        json: text.into(),
        bin: Some(bin.into()),
    };
    glb.to_vec().expect("a well-formed GLB writes")
}
