//! `[textures] missing`: a texture whose image file is missing refuses the file by default,
//! and with `"warn"` is dropped alone (the other textures and the material stay).

use flowlight_scene::{load_gltf, load_gltf_with, LoadOptions, MissingTextures};
use flowlight_testkit::gltf::{png8, temp_dir, Quad, TempDir};
use std::collections::BTreeMap;

/// A quad whose base colour texture is embedded and whose emissive texture's image is the
/// file `missing.png`, which does not exist; the directory (kept alive) and the file.
fn quad_with_a_missing_image(tag: &str) -> (TempDir, std::path::PathBuf) {
    let q = Quad {
        images: vec![png8(1, 1, 1, &[128]), png8(1, 1, 1, &[255])],
        textures: r#"{"source": 0}, {"source": 1}"#.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
            "emissiveTexture": {"index": 1}, "emissiveFactor": [1, 1, 1]}"#
            .into(),
        ..Quad::default()
    };
    let mut doc: gltf::json::Value = gltf::json::deserialize::from_str(&q.json()).unwrap();
    doc["images"][1]["uri"] = "missing.png".into();
    let dir = temp_dir(tag);
    let path = dir.join("q.gltf");
    std::fs::write(&path, gltf::json::serialize::to_string(&doc).unwrap()).unwrap();
    (dir, path)
}

#[test]
fn a_missing_texture_file_refuses_the_asset_by_default() {
    let (_dir, path) = quad_with_a_missing_image("missing-default");
    let e = load_gltf(&path, &BTreeMap::new()).unwrap_err().to_string();
    assert!(
        e.contains("missing.png") && e.contains("cannot read") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn warn_drops_only_the_texture_whose_file_is_missing() {
    let (_dir, path) = quad_with_a_missing_image("missing-warn");
    let options = LoadOptions {
        missing_textures: MissingTextures::Warn,
        ..LoadOptions::default()
    };
    let s = load_gltf_with(&path, &options).unwrap_or_else(|e| panic!("{e}"));
    let m = &s.materials[0];
    assert!(m.base_color_texture.is_some(), "the embedded texture stays");
    assert!(!m.emissive_texture.is_some(), "the missing one is dropped");
    // Its factor stays as it is: the quad emits the emissive factor alone.
    assert_eq!(m.emission, flowlight_core::Rgb::ONE);
    assert_eq!(s.stats.textures_dropped, 1);
    assert_eq!(s.stats.images_decoded, 1);
}

#[test]
fn an_undecodable_image_is_an_error_even_with_warn() {
    let (_dir, path) = quad_with_a_missing_image("missing-garbage");
    std::fs::write(path.with_file_name("missing.png"), b"not a png").unwrap();
    let options = LoadOptions {
        missing_textures: MissingTextures::Warn,
        ..LoadOptions::default()
    };
    assert!(load_gltf_with(&path, &options).is_err());
}

#[test]
fn the_config_reads_textures_missing_and_names_a_bad_value() {
    let path = std::path::Path::new("/tmp/c.toml");
    let base = "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n";
    let c = flowlight_scene::parse_config(path, base).unwrap();
    assert_eq!(c.missing_textures, MissingTextures::Error);
    assert_eq!(c.load_options().missing_textures, MissingTextures::Error);
    let c = flowlight_scene::parse_config(path, &format!("{base}[textures]\nmissing = \"warn\"\n"))
        .unwrap();
    assert_eq!(c.load_options().missing_textures, MissingTextures::Warn);
    let e = flowlight_scene::parse_config(path, &format!("{base}[textures]\nmissing = \"skip\"\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("textures.missing") && e.contains("skip"), "{e}");
}
