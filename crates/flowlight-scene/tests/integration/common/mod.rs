//! Helpers for building small glTF files in tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

pub use flowlight_testkit::gltf::{base64, TempDir};

/// A fresh empty temporary directory for one test, removed when dropped (unless the test
/// fails).
pub fn temp_dir(tag: &str) -> TempDir {
    static N: AtomicUsize = AtomicUsize::new(0);
    TempDir::new(&format!(
        "flowlight-scene-test-{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}

/// Little-endian bytes of positions (VEC3 f32) followed by indices (u32).
pub fn mesh_bytes(positions: &[[f32; 3]], indices: &[u32]) -> Vec<u8> {
    let mut b = Vec::new();
    for p in positions {
        for c in p {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in indices {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

/// A one-mesh glTF whose buffer is `uri` (a data URI or a file name), with `positions` then
/// `indices` packed in it. `material` is JSON for materials[0] (or empty for none);
/// `node_extra` is spliced into the mesh node (e.g. a transform).
pub fn gltf_json(
    uri: &str,
    positions: &[[f32; 3]],
    indices: &[u32],
    material: &str,
    node_extra: &str,
) -> String {
    let pbytes = positions.len() * 12;
    let ibytes = indices.len() * 4;
    let (mat_ref, materials) = if material.is_empty() {
        (String::new(), String::new())
    } else {
        (
            ", \"material\": 0".to_string(),
            format!(", \"materials\": [{material}]"),
        )
    };
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0{node_extra}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1{mat_ref}}}]}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {np}, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5125, "count": {ni}, "type": "SCALAR"}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pbytes}}},
    {{"buffer": 0, "byteOffset": {pbytes}, "byteLength": {ibytes}}}
  ],
  "buffers": [{{"uri": "{uri}", "byteLength": {total}}}]{materials}
}}"#,
        np = positions.len(),
        ni = indices.len(),
        total = pbytes + ibytes,
    )
}

/// `gltf_json` with the buffer embedded as a base64 data URI.
pub fn embedded_gltf(
    positions: &[[f32; 3]],
    indices: &[u32],
    material: &str,
    node_extra: &str,
) -> String {
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64(&mesh_bytes(positions, indices))
    );
    gltf_json(&uri, positions, indices, material, node_extra)
}

pub fn scenes_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes"))
}
