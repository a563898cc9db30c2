//! Small glTF scenes for tests, written as JSON with an embedded (base64) buffer.
//!
//! [`quads_gltf`] builds a one-mesh scene from quads (the integration tests' scenes);
//! the single textured quad with chosen vertex attributes lives in
//! `flowlight_scene::testutil::Quad` (the scene crate's own tests need it without this
//! crate), and its [`base64`] is the one both use.

pub use flowlight_scene::testutil::base64;
use std::path::{Path, PathBuf};

/// A glTF document with one mesh made of `quads` (each four corners, counter-clockwise seen
/// from its front), material `material` (JSON of materials[0]), and `extra_nodes` (JSON
/// objects, e.g. `KHR_lights_punctual` light nodes) after the mesh node. `lights` is the JSON
/// array of `KHR_lights_punctual` lights (empty: the extension is not used).
pub fn quads_gltf(
    quads: &[[[f32; 3]; 4]],
    material: &str,
    extra_nodes: &[String],
    lights: &str,
) -> String {
    let mut bytes = Vec::new();
    for q in quads {
        for p in q {
            for c in p {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let pbytes = bytes.len();
    let mut indices = Vec::new();
    for k in 0..quads.len() as u32 {
        indices.extend_from_slice(&[4 * k, 4 * k + 1, 4 * k + 2, 4 * k, 4 * k + 2, 4 * k + 3]);
    }
    for i in &indices {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    let nodes: Vec<String> = std::iter::once(r#"{"mesh": 0}"#.to_string())
        .chain(extra_nodes.iter().cloned())
        .collect();
    let node_list: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    let ext = if lights.is_empty() {
        String::new()
    } else {
        format!(
            r#", "extensionsUsed": ["KHR_lights_punctual"], "extensions": {{"KHR_lights_punctual": {{"lights": {lights}}}}}"#
        )
    };
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [{node_list}]}}],
  "nodes": [{nodes}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "materials": [{material}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {np}, "type": "VEC3", "min": [-1e9, -1e9, -1e9], "max": [1e9, 1e9, 1e9]}},
    {{"bufferView": 1, "componentType": 5125, "count": {ni}, "type": "SCALAR"}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pbytes}}},
    {{"buffer": 0, "byteOffset": {pbytes}, "byteLength": {ibytes}}}
  ],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {total}}}]{ext}
}}"#,
        node_list = node_list.join(", "),
        nodes = nodes.join(", "),
        np = quads.len() * 4,
        ni = indices.len(),
        ibytes = indices.len() * 4,
        b64 = base64(&bytes),
        total = bytes.len(),
    )
}

/// Writes `q.gltf` into `dir`: an emitting square [−1, 1]² in z = 0 facing +Z (radiance 1),
/// with no camera and no other light.
pub fn emitting_square(dir: &Path) -> PathBuf {
    let gltf = quads_gltf(
        &[[
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ]],
        r#"{"emissiveFactor": [1, 1, 1]}"#,
        &[],
        "",
    );
    let path = dir.join("q.gltf");
    std::fs::write(&path, gltf).unwrap();
    path
}
