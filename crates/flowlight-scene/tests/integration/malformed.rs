//! Malformed inputs give errors that name the file and the cause, never a panic.

use crate::common;

use common::*;
use flowlight_scene::{load_gltf, SceneError};
use std::collections::BTreeMap;
use std::path::Path;

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn err(p: &Path) -> (SceneError, String) {
    match load_gltf(p, &BTreeMap::new()) {
        Ok(_) => panic!("{} loaded but should not", p.display()),
        Err(e) => {
            let m = e.to_string();
            assert!(
                m.contains(&p.display().to_string()),
                "message does not name the file: {m}"
            );
            (e, m)
        }
    }
}

#[test]
fn nonexistent_file() {
    let p = temp_dir("missing").join("nope.gltf");
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Io { .. }), "{m}");
}

#[test]
fn every_truncation_of_the_cornell_glb_is_an_error() {
    let data = std::fs::read(scenes_dir().join("cornell-box/cornell-box.glb")).unwrap();
    let dir = temp_dir("trunc");
    // Every cut inside the header and chunk headers, and a spread of cuts elsewhere.
    let cuts: Vec<usize> = (0..40)
        .chain((40..data.len()).step_by(97))
        .chain([data.len() - 1])
        .collect();
    for n in cuts {
        let p = dir.join(format!("cut{n}.glb"));
        std::fs::write(&p, &data[..n]).unwrap();
        let (e, m) = err(&p);
        assert!(
            matches!(e, SceneError::Glb { .. } | SceneError::Json { .. }),
            "cut at {n}: {m}"
        );
        if n >= 12 {
            assert!(m.contains("truncated"), "cut at {n}: {m}");
        }
    }
}

#[test]
fn invalid_json() {
    let dir = temp_dir("json");
    let p = dir.join("bad.gltf");
    std::fs::write(&p, r#"{"asset": {"version": "2.0"}, "nodes": [ "#).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Json { .. }), "{m}");
    assert!(m.contains("JSON"), "{m}");
}

#[test]
fn accessor_index_out_of_range() {
    let dir = temp_dir("acc");
    let p = dir.join("acc.gltf");
    let json =
        embedded_gltf(&TRI, &[0, 1, 2], "", "").replace(r#""indices": 1"#, r#""indices": 7"#);
    std::fs::write(&p, json).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Validation { .. }), "{m}");
    assert!(
        m.contains("indices") && m.to_lowercase().contains("out of bounds"),
        "{m}"
    );
}

#[test]
fn accessor_running_past_its_buffer_view() {
    let dir = temp_dir("acc2");
    let p = dir.join("acc2.gltf");
    let json = embedded_gltf(&TRI, &[0, 1, 2], "", "").replace(
        r#""count": 3, "type": "SCALAR""#,
        r#""count": 30, "type": "SCALAR""#,
    );
    std::fs::write(&p, json).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Accessor { accessor: 1, .. }), "{m}");
}

#[test]
fn vertex_index_out_of_range() {
    let dir = temp_dir("idx");
    let p = dir.join("idx.gltf");
    std::fs::write(&p, embedded_gltf(&TRI, &[0, 1, 3], "", "")).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Accessor { .. }), "{m}");
    assert!(m.contains("index 3 is out of range"), "{m}");
}

#[test]
fn float_indices_are_rejected() {
    let dir = temp_dir("ftype");
    let p = dir.join("ftype.gltf");
    let json = embedded_gltf(&TRI, &[0, 1, 2], "", "")
        .replace(r#""componentType": 5125"#, r#""componentType": 5126"#);
    std::fs::write(&p, json).unwrap();
    let (_, m) = err(&p);
    assert!(m.contains("indices") || m.contains("componentType"), "{m}");
}

#[test]
fn missing_bin_buffer_names_the_missing_file() {
    let dir = temp_dir("bin");
    let p = dir.join("scene.gltf");
    std::fs::write(&p, gltf_json("scene-data.bin", &TRI, &[0, 1, 2], "", "")).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::MissingBuffer { .. }), "{m}");
    assert!(m.contains("scene-data.bin"), "{m}");
    // With the file present it loads.
    std::fs::write(dir.join("scene-data.bin"), mesh_bytes(&TRI, &[0, 1, 2])).unwrap();
    assert_eq!(load_gltf(&p, &BTreeMap::new()).unwrap().triangles.len(), 1);
    // A short file is reported too.
    std::fs::write(dir.join("scene-data.bin"), [0u8; 10]).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Buffer { .. }), "{m}");
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let dir = temp_dir("degen");
    let p = dir.join("degen.gltf");
    let pos = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 0.0, 0.0],      // collinear with 0 and 1
        [f32::NAN, 0.0, 0.0], // JSON cannot say NaN, but the buffer can
        [0.0, 0.0, 0.0],      // coincides with vertex 0
    ];
    let idx = [
        0, 1, 2, // fine
        0, 1, 3, // zero area (collinear)
        0, 1, 4, // NaN vertex
        0, 0, 2, // repeated index
        0, 5, 2, // zero area (coincident vertices)
        2, 1, 0, // fine (back side)
    ];
    std::fs::write(
        &p,
        embedded_gltf(&pos, &idx, r#"{"emissiveFactor": [1, 1, 1]}"#, ""),
    )
    .unwrap();
    let s = load_gltf(&p, &BTreeMap::new()).unwrap();
    assert_eq!(s.triangles.len(), 2);
    assert_eq!(s.stats.degenerate_dropped, 4);
    assert_eq!(s.stats.dropped_zero_area, 2);
    assert_eq!(s.stats.dropped_non_finite, 1);
    assert_eq!(s.stats.dropped_repeated_index, 1);
    assert_eq!(s.stats.dropped_emitters, 4);
    assert_eq!(s.emitters.len(), 2);
    assert!(s.emitters.iter().all(|e| e.area > 0.0));
    // Only degenerate triangles: an error, not an empty scene.
    std::fs::write(&p, embedded_gltf(&pos, &idx[3..15], "", "")).unwrap();
    let (e, _) = err(&p);
    assert!(matches!(e, SceneError::NoTriangles { .. }));
}

#[test]
fn orthographic_camera_with_zero_magnification_is_rejected() {
    let dir = temp_dir("ortho");
    let p = dir.join("ortho.gltf");
    let json = embedded_gltf(&TRI, &[0, 1, 2], "", "").replace(
        r#""nodes": [{"mesh": 0}]"#,
        r#""nodes": [{"mesh": 0, "camera": 0}], "cameras": [{"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 0, "znear": 0.1, "zfar": 10}}]"#,
    );
    std::fs::write(&p, json).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Camera { .. }), "{m}");
    assert!(m.contains("cameras[0].orthographic.ymag"), "{m}");
}

#[test]
fn no_scene_and_node_cycles() {
    let dir = temp_dir("noscene");
    let p = dir.join("noscene.gltf");
    std::fs::write(&p, r#"{"asset": {"version": "2.0"}}"#).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::NoScene { .. }), "{m}");
    let p = dir.join("cycle.gltf");
    std::fs::write(
        &p,
        r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"children": [1]}, {"children": [0]}]}"#,
    )
    .unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Node { node: 0, .. }), "{m}");
}

#[test]
fn bad_material_values_are_rejected() {
    let dir = temp_dir("mat");
    let p = dir.join("mat.gltf");
    // 1e39 overflows f32 to infinity.
    let mat = r#"{"name": "hot", "pbrMetallicRoughness": {"roughnessFactor": 1e39}}"#;
    std::fs::write(&p, embedded_gltf(&TRI, &[0, 1, 2], mat, "")).unwrap();
    let (_, m) = err(&p);
    assert!(m.contains("roughness"), "{m}");
}

#[test]
fn corrupt_data_uri() {
    let dir = temp_dir("uri");
    let p = dir.join("uri.gltf");
    let json = gltf_json(
        "data:application/octet-stream;base64,!!!!",
        &TRI,
        &[0, 1, 2],
        "",
        "",
    );
    std::fs::write(&p, json).unwrap();
    let (e, m) = err(&p);
    assert!(matches!(e, SceneError::Buffer { .. }), "{m}");
    assert!(m.contains("base64"), "{m}");
}
