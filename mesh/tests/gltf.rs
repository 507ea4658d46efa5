//! The `gltf` example's scene reader, on small glTF files written in code:
//! meshes, point and spot lights and a camera come back as written; a scene
//! read from a file shades through the batch call with the mesh host,
//! certified against the exact shadowed sum; and bad files (not glTF,
//! truncated, accessors past their buffers, indices out of range,
//! non-finite vertices, nothing but degenerate triangles, no lights) get an
//! error, never a panic.

#[path = "../examples/gltf/scene.rs"]
#[allow(dead_code)]
mod scene;

use glam::Vec3;
use manylights::{Aabb, Lambert, LightTree, Query, ShadeResult, Threshold};
use manylights_mesh::{Occluders, box_mesh};
use scene::{LightSpec, LoadError, MeshSpec, View, load, write_glb};
use serde_json::Value;

/// A ground quad and a box standing on it.
fn meshes() -> Vec<MeshSpec> {
    let (corners, indices) = box_mesh(&Aabb {
        min: Vec3::new(-1.0, -1.0, 0.0),
        max: Vec3::new(1.0, 1.0, 2.0),
    });
    vec![
        MeshSpec {
            positions: vec![
                Vec3::new(-8.0, -8.0, 0.0),
                Vec3::new(8.0, -8.0, 0.0),
                Vec3::new(8.0, 8.0, 0.0),
                Vec3::new(-8.0, 8.0, 0.0),
            ],
            indices: vec![0, 1, 2, 0, 2, 3],
            colour: Vec3::new(0.5, 0.5, 0.5),
        },
        MeshSpec {
            positions: corners.to_vec(),
            indices: indices.to_vec(),
            colour: Vec3::new(0.8, 0.2, 0.1),
        },
    ]
}

/// A ring of lights around the box, every third a spot light.
fn lights(count: usize) -> Vec<LightSpec> {
    (0..count)
        .map(|k| {
            let angle = std::f32::consts::TAU * k as f32 / count as f32;
            LightSpec {
                position: Vec3::new(4.0 * angle.cos(), 4.0 * angle.sin(), 1.0 + (k % 5) as f32),
                colour: Vec3::new(1.0, 0.9, 0.7),
                intensity: 2.0,
                spot: k % 3 == 0,
            }
        })
        .collect()
}

fn view() -> View {
    View {
        eye: Vec3::new(-6.0, -7.0, 5.0),
        target: Vec3::new(0.0, 0.0, 1.0),
        up: Vec3::Z,
        yfov: 0.8,
    }
}

/// The `.glb` bytes of the test scene with its JSON changed by `edit`.
fn edited(edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let glb = write_glb(&meshes(), &lights(6), Some(view()));
    let parsed = gltf::binary::Glb::from_slice(&glb).unwrap();
    let mut json: Value = serde_json::from_slice(&parsed.json).unwrap();
    edit(&mut json);
    let mut text = serde_json::to_vec(&json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let bin = parsed.bin.unwrap().into_owned();
    gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: (12 + 8 + text.len() + 8 + bin.len()) as u32,
        },
        json: text.into(),
        bin: Some(bin.into()),
    }
    .to_vec()
    .unwrap()
}

#[test]
fn a_written_scene_reads_back() {
    let glb = write_glb(&meshes(), &lights(9), Some(view()));
    let scene = load(&glb, None).unwrap();
    assert_eq!(scene.triangles.len(), 2 + 12);
    assert_eq!(scene.albedo.len(), scene.triangles.len());
    assert!(scene.albedo.contains(&Vec3::new(0.8, 0.2, 0.1)));
    assert_eq!((scene.lights.len(), scene.spots), (9, 3));
    for e in &scene.lights {
        // In the order the nodes are visited: compare as sets of positions.
        let light = e.light;
        let written = lights(9)
            .into_iter()
            .find(|l| l.position == light.position)
            .unwrap_or_else(|| panic!("{light:?}"));
        assert_eq!(light.intensity, Vec3::new(2.0, 1.8, 1.4));
        // Spots come back as spots, shining down (a node without rotation
        // points its -z), with the written cone angles.
        match e.emission {
            manylights::Emission::Spot {
                axis,
                inner_angle,
                outer_angle,
                ..
            } => {
                assert!(written.spot);
                assert!(axis.normalize().dot(Vec3::NEG_Z) > 0.9999, "{axis}");
                assert_eq!((inner_angle, outer_angle), (0.3, 0.6));
            }
            manylights::Emission::Isotropic => assert!(!written.spot),
            other => panic!("{other:?}"),
        }
    }
    let v = scene.view.expect("a camera");
    assert!(v.eye.distance(view().eye) < 1e-4, "{:?}", v.eye);
    let forward = (view().target - view().eye).normalize();
    assert!((v.target - v.eye).normalize().dot(forward) > 0.9999);
    assert!(v.up.dot(Vec3::Z) > 0.0);
}

/// The batch call over points of the file's surfaces, shadowed by its own
/// triangles and lit by its point and spot lights, certifies against the
/// exact shadowed sum.
#[test]
fn a_scene_from_a_file_shades_certified() {
    let scene = load(&write_glb(&meshes(), &lights(60), None), None).unwrap();
    let occluders = Occluders::builder()
        .triangles(&scene.triangles)
        .unwrap()
        .build();
    let tree = LightTree::build_emitters(&scene.lights).unwrap();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    // Points on the ground around the box (some in its shadow) and on its
    // faces.
    let mut queries = Vec::new();
    for i in 0..8 {
        for j in 0..8 {
            let p = Vec3::new(i as f32 - 3.5, j as f32 - 3.5, 0.0);
            if p.x.abs() > 1.0 || p.y.abs() > 1.0 {
                queries.push(Query::new(p, Vec3::Z).unwrap());
            }
        }
    }
    for k in 0..8 {
        let z = 0.1 + 0.2 * k as f32;
        queries.push(Query::new(Vec3::new(1.0, 0.1 * k as f32 - 0.4, z), Vec3::X).unwrap());
        queries.push(Query::new(Vec3::new(-0.3, -1.0, z), -Vec3::Y).unwrap());
    }
    let mut results = vec![ShadeResult::default(); queries.len()];
    let mut host = occluders.host();
    shading
        .shade_batch(&queries, Threshold::relative(0.01), &mut host, &mut results)
        .unwrap();
    let mut shadowed = 0;
    for (q, r) in queries.iter().zip(&results) {
        let exact = shading.exact_query(q, occluders.host());
        let unoccluded = shading.exact_query(q, manylights::Unoccluded);
        shadowed += usize::from(exact.max_element() < unoccluded.max_element());
        assert!(r.certifies(exact), "{r:?} against {exact}");
    }
    assert!(shadowed > 0, "the box shadows nothing");
}

#[test]
fn bad_files_get_errors() {
    // Not glTF at all, and a truncated file.
    assert!(matches!(
        load(b"not a scene", None),
        Err(LoadError::Gltf(_))
    ));
    let glb = write_glb(&meshes(), &lights(6), None);
    assert!(matches!(
        load(&glb[..glb.len() / 2], None),
        Err(LoadError::Gltf(_))
    ));
    assert!(matches!(load(&glb[..40], None), Err(LoadError::Gltf(_))));
    // JSON that is not a glTF document.
    assert!(matches!(
        load(br#"{"asset": 3}"#, None),
        Err(LoadError::Gltf(_))
    ));
    // An accessor past the end of its buffer view.
    let long = edited(|j| j["accessors"][0]["count"] = 1_000_000.into());
    assert!(
        matches!(load(&long, None), Err(LoadError::BadAccessor(0))),
        "{:?}",
        load(&long, None).err()
    );
    // A huge count that would overflow the accessor's byte range.
    let huge = edited(|j| j["accessors"][1]["count"] = (u64::MAX / 2).into());
    assert!(load(&huge, None).is_err());
    // Positions of the wrong type.
    let ints = edited(|j| j["accessors"][0]["componentType"] = 5125.into());
    assert!(load(&ints, None).is_err());
    // An index past the positions.
    let bin_index = edited(|j| {
        j["accessors"][0]["count"] = 3.into();
        j["accessors"][0]["max"] = serde_json::json!([8.0, 8.0, 0.0]);
    });
    assert!(matches!(
        load(&bin_index, None),
        Err(LoadError::IndexOutOfRange {
            index: 3,
            vertices: 3,
            ..
        })
    ));
    // No lights, or only a directional one.
    let dark = write_glb(&meshes(), &[], None);
    assert!(matches!(load(&dark, None), Err(LoadError::NoLights)));
    let sun = edited(|j| {
        j["extensions"]["KHR_lights_punctual"]["lights"] =
            serde_json::json!([{"type": "directional", "intensity": 1.0}]);
        for node in j["nodes"].as_array_mut().unwrap() {
            if node.get("extensions").is_some() {
                node["extensions"]["KHR_lights_punctual"]["light"] = 0.into();
            }
        }
    });
    assert!(matches!(load(&sun, None), Err(LoadError::NoLights)));
    // A light of negative intensity.
    let negative = edited(|j| {
        j["extensions"]["KHR_lights_punctual"]["lights"][1]["intensity"] = (-1.0).into()
    });
    assert!(load(&negative, None).is_err());
    // Nothing but degenerate triangles, and no meshes at all.
    let line = MeshSpec {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
        indices: vec![0, 1, 2, 2, 1, 0],
        colour: Vec3::ONE,
    };
    let flat = write_glb(&[line], &lights(3), None);
    assert!(matches!(load(&flat, None), Err(LoadError::NoTriangles)));
    let empty = write_glb(&[], &lights(3), None);
    assert!(matches!(load(&empty, None), Err(LoadError::NoTriangles)));
    // A non-finite vertex: an overflowing node scale.
    let overflow = edited(|j| j["nodes"][1]["scale"] = serde_json::json!([3e38, 3e38, 3e38]));
    assert!(load(&overflow, None).is_err());
    // A mangled binary chunk length.
    let mut bytes = glb.clone();
    bytes[8] ^= 0x55;
    assert!(load(&bytes, None).is_err());
}

/// Every truncation and a sweep of corrupted bytes of a valid file: an
/// answer (scene or error) each time, never a panic.
#[test]
fn corrupted_files_never_panic() {
    let glb = write_glb(&meshes(), &lights(6), Some(view()));
    for end in (0..glb.len()).step_by(7) {
        let _ = load(&glb[..end], None);
    }
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for _ in 0..2_000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let mut bytes = glb.clone();
        let at = (state % bytes.len() as u64) as usize;
        bytes[at] = (state >> 32) as u8;
        let _ = load(&bytes, None);
    }
}
