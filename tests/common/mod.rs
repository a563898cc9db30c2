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

/// The glTF builders of the conformance kit (one writer for every test).
#[allow(unused_imports)]
pub use flowlight_testkit::gltf::{base64, emitting_square, quads_gltf};

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

/// A Lambertian white of albedo ½ (glTF: metallic 0, roughness 1, and no specular layer, as
/// `KHR_materials_specular.specularFactor = 0` defines it), for scenes with a known answer.
pub const LAMBERT: &str = r#"{"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}, "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}}"#;

/// A 20 × 20 floor quad at y = 0 facing +Y, centred on the origin.
pub const FLOOR: [[f32; 3]; 4] = [
    [-10.0, 0.0, -10.0],
    [-10.0, 0.0, 10.0],
    [10.0, 0.0, 10.0],
    [10.0, 0.0, -10.0],
];

/// A TOML table of `pairs`.
pub fn table(pairs: &[(&str, toml::Value)]) -> toml::Value {
    toml::Value::Table(
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect(),
    )
}

/// `[[integrator.mutations]]` with one entry per (plugin, extra params).
pub fn mutations(entries: &[(&str, &[(&str, toml::Value)])]) -> toml::Value {
    toml::Value::Array(
        entries
            .iter()
            .map(|(plugin, extra)| {
                let mut pairs = vec![("plugin", toml::Value::String(plugin.to_string()))];
                pairs.extend(extra.iter().cloned());
                table(&pairs)
            })
            .collect(),
    )
}

/// Region means of `img` (8×8 blocks of a 32×32 image).
pub fn regions(img: &[Rgb]) -> Vec<f64> {
    let mut out = vec![0.0; 16];
    for (i, c) in img.iter().enumerate() {
        let (x, y) = (i % 32, i / 32);
        out[(y / 8) * 4 + x / 8] += c.luminance() as f64 / 64.0;
    }
    out
}

/// Chromaticity (r, b over r + g + b) of an image's mean.
pub fn chromaticity(img: &[Rgb]) -> (f64, f64) {
    let sum = img.iter().fold([0.0f64; 3], |a, c| {
        [a[0] + c.r as f64, a[1] + c.g as f64, a[2] + c.b as f64]
    });
    let t = sum[0] + sum[1] + sum[2];
    (sum[0] / t, sum[2] / t)
}

/// A directional light node travelling down and tilted by `tilt` degrees towards +Z (it comes
/// from behind the wall): a rotation about +X by −(90° + tilt) of the node's −Z.
pub fn sun_node(tilt: f32) -> String {
    let a = -(90.0 + tilt).to_radians();
    let q = [(a / 2.0).sin(), 0.0, 0.0, (a / 2.0).cos()];
    format!(
        r#"{{"translation": [0.0, 5.0, 0.0], "rotation": {q:?}, "extensions": {{"KHR_lights_punctual": {{"light": 0}}}}}}"#
    )
}
