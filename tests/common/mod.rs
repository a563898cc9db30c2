//! Helpers shared by the integration tests. Plugins must have been built first
//! (`cargo build --workspace`, as `.ci/run` does); the host finds them next to the test
//! executable's parent directory (`target/<profile>/`).
#![allow(dead_code)]

use flowlight_core::Rgb;
use flowlight_host::render::RenderOutcome;
use flowlight_host::session::{Overrides, Session};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn scene_config(rel: &str) -> PathBuf {
    repo().join("scenes").join(rel)
}

/// A fresh scratch directory under the system temp dir.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("flowlight-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn toml_params(pairs: &[(&str, toml::Value)]) -> Vec<(String, toml::Value)> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// Prepares a session for a scene config with integrator parameter overrides and no outputs.
pub fn session(config: &str, spp: u32, params: &[(&str, toml::Value)]) -> Session {
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Session::prepare(&scene_config(config), &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

/// Like [`session`], at another resolution.
pub fn session_at(
    config: &str,
    width: u32,
    height: u32,
    spp: u32,
    params: &[(&str, toml::Value)],
) -> Session {
    let mut cfg = flowlight_scene::config::load_config(&scene_config(config))
        .unwrap_or_else(|e| panic!("{e}"));
    cfg.width = width;
    cfg.height = height;
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Session::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

pub fn render(s: &Session) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let out = s.render(&stop, &|_| {}).unwrap();
    if let Some(e) = &out.error {
        panic!("render failed: {e}");
    }
    out
}

/// Mean luminance and its standard error over the pixels of `img` (pixels are independent).
pub fn mean_and_stderr(img: &[Rgb], f: impl Fn(Rgb) -> f32) -> (f64, f64) {
    let n = img.len() as f64;
    let mean = img.iter().map(|&c| f(c) as f64).sum::<f64>() / n;
    let var = img
        .iter()
        .map(|&c| (f(c) as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Standard base64 (for data URIs in synthetic glTF files).
pub use flowlight_scene::testutil::base64;

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

/// Writes `gltf` and a config (`body` is everything after the `scene =` line) into a scratch
/// folder and prepares a session with `spp` samples and no outputs.
pub fn session_from(name: &str, gltf: &str, body: &str, spp: u32) -> Session {
    let dir = scratch(name);
    std::fs::write(dir.join("scene.gltf"), gltf).unwrap();
    let cfg = dir.join("scene.toml");
    std::fs::write(&cfg, format!("scene = \"scene.gltf\"\n{body}")).unwrap();
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        ..Default::default()
    };
    let mut s = Session::prepare(&cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

/// Writes `q.gltf` into `dir`: an emitting square [−1, 1]² in z = 0 facing +Z (radiance 1),
/// with no camera and no other light.
pub fn emitting_square(dir: &std::path::Path) -> PathBuf {
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
