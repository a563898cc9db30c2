//! `[render] multiscatter` in the white furnace: a closed sphere of a white *rough metal*
//! emitting Le = 1, seen from inside. glTF's single-scattering GGX loses the light its
//! microfacets reflect onto each other, so at path depth N the radiance is below N + 1
//! (1 + E + E², E ≈ 0.4 the average albedo at roughness 1); with the multiple-scattering
//! lobe a white metal reflects everything and the furnace reads N + 1.

use crate::common;

use common::{mean_and_stderr, render, renderer_at, scene_config, scratch};

/// The furnace with a white metal of roughness `roughness`, `[render] multiscatter` as given.
fn white_metal_furnace(tag: &str, roughness: f32, multiscatter: bool) -> common::InTempDir<String> {
    let dir = scratch(&format!("multiscatter-furnace-{tag}"));
    let gltf = std::fs::read_to_string(scene_config("furnace/furnace.gltf")).unwrap();
    let pbr = r#""pbrMetallicRoughness": {
    "baseColorFactor": [
     0.5,
     0.5,
     0.5,
     1
    ],
    "metallicFactor": 0,
    "roughnessFactor": 1
   },"#;
    assert!(gltf.contains(pbr), "furnace.gltf changed");
    let patched = gltf.replace(
        pbr,
        &format!(
            r#""pbrMetallicRoughness": {{"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 1, "roughnessFactor": {roughness}}},"#
        ),
    );
    std::fs::write(dir.join("furnace.gltf"), patched).unwrap();
    let toml = std::fs::read_to_string(scene_config("furnace/furnace.toml")).unwrap();
    assert!(toml.contains("[render]\n"), "furnace.toml changed");
    let toml = toml.replace(
        "[render]\n",
        &format!("[render]\nmultiscatter = {multiscatter}\n"),
    );
    std::fs::write(dir.join("furnace.toml"), toml).unwrap();
    let value = dir.join("furnace.toml").display().to_string();
    common::InTempDir { dir, value }
}

fn furnace_mean(roughness: f32, multiscatter: bool) -> (f64, f64) {
    let cfg = white_metal_furnace(
        &format!("{roughness}-{multiscatter}"),
        roughness,
        multiscatter,
    );
    let s = renderer_at(
        &cfg,
        32,
        32,
        128,
        &[
            ("termination", "equi".into()),
            ("path_depth", toml::Value::Integer(2)),
        ],
    );
    let out = render(&s);
    assert_eq!(out.stats.invalid_deposits, 0);
    mean_and_stderr(&out.frame.image(), |c| c.g)
}

#[test]
fn a_white_rough_metal_reads_n_plus_one_only_with_multiscatter() {
    for roughness in [0.6f32, 1.0] {
        let (single, _) = furnace_mean(roughness, false);
        let (multi, stderr) = furnace_mean(roughness, true);
        assert!(
            single < 2.9,
            "roughness {roughness}: single scattering {single:.4}"
        );
        assert!(
            (multi / 3.0 - 1.0).abs() < 0.01 + 3.0 * stderr / 3.0,
            "roughness {roughness}: with multiscatter {multi:.4} ± {stderr:.4}, expected 3"
        );
    }
}
