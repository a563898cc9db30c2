//! glTF material extensions reach `Material` with their values, and bad values are errors that
//! name the field.

use crate::common;

use common::*;
use flowlight_scene::load_gltf;
use std::collections::BTreeMap;

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn load(tag: &str, material: &str) -> Result<flowlight_scene::Scene, String> {
    let dir = temp_dir(tag);
    let p = dir.join("m.gltf");
    std::fs::write(&p, embedded_gltf(&TRI, &[0, 1, 2], material, "")).unwrap();
    load_gltf(&p, &BTreeMap::new()).map_err(|e| e.to_string())
}

#[test]
fn extension_parameters_are_read() {
    let mat = r#"{"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.8, 0.7, 1], "metallicFactor": 0.25, "roughnessFactor": 0.3},
        "extensions": {
            "KHR_materials_ior": {"ior": 1.4},
            "KHR_materials_specular": {"specularFactor": 0.5, "specularColorFactor": [1.0, 0.5, 2.0]},
            "KHR_materials_transmission": {"transmissionFactor": 0.8},
            "KHR_materials_volume": {"thicknessFactor": 0.2, "attenuationDistance": 3.0, "attenuationColor": [0.5, 0.6, 0.7]},
            "KHR_materials_clearcoat": {"clearcoatFactor": 0.7, "clearcoatRoughnessFactor": 0.2},
            "KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1]}
        }}"#;
    let s = load("ext", mat).unwrap();
    let m = &s.materials[0];
    assert_eq!((m.metallic, m.roughness, m.ior), (0.25, 0.3, 1.4));
    assert_eq!(m.transmission, 0.8);
    assert_eq!(m.specular, 0.5);
    assert_eq!(m.specular_color.to_array(), [1.0, 0.5, 2.0]);
    assert_eq!(m.thickness, 0.2);
    assert_eq!(m.attenuation_distance, 3.0);
    assert_eq!(m.attenuation_color.to_array(), [0.5, 0.6, 0.7]);
    assert_eq!((m.clearcoat, m.clearcoat_roughness), (0.7, 0.2));
}

#[test]
fn absent_extensions_give_the_spec_defaults() {
    let s = load("def", r#"{"name": "plain"}"#).unwrap();
    let m = &s.materials[0];
    assert_eq!(
        (m.ior, m.specular, m.transmission, m.thickness),
        (1.5, 1.0, 0.0, 0.0)
    );
    assert_eq!(m.specular_color.to_array(), [1.0; 3]);
    assert_eq!(m.attenuation_color.to_array(), [1.0; 3]);
    assert!(m.attenuation_distance.is_infinite());
    assert_eq!((m.clearcoat, m.clearcoat_roughness), (0.0, 0.0));
    // ior 0 (the specular-glossiness conversion of KHR_materials_specular) is allowed.
    let s = load(
        "ior0",
        r#"{"name": "sg", "extensions": {"KHR_materials_ior": {"ior": 0}}}"#,
    )
    .unwrap();
    assert_eq!(s.materials[0].ior, 0.0);
}

#[test]
fn bad_extension_values_name_the_field() {
    for (ext, field) in [
        (
            r#""KHR_materials_specular": {"specularFactor": 2.0}"#,
            "specularFactor",
        ),
        (
            r#""KHR_materials_specular": {"specularColorFactor": [1, -1, 1]}"#,
            "specularColorFactor.g",
        ),
        (
            r#""KHR_materials_volume": {"thicknessFactor": -1}"#,
            "thicknessFactor",
        ),
        (
            r#""KHR_materials_volume": {"attenuationDistance": 0}"#,
            "attenuationDistance",
        ),
        (
            r#""KHR_materials_volume": {"attenuationColor": [1, 2, 1]}"#,
            "attenuationColor.g",
        ),
        (
            r#""KHR_materials_clearcoat": {"clearcoatFactor": 1.5}"#,
            "clearcoatFactor",
        ),
        (
            r#""KHR_materials_clearcoat": {"clearcoatRoughnessFactor": "rough"}"#,
            "clearcoatRoughnessFactor",
        ),
        (r#""KHR_materials_ior": {"ior": 0.5}"#, "ior"),
    ] {
        let mat = format!(r#"{{"name": "bad", "extensions": {{{ext}}}}}"#);
        let e = load("bad", &mat).expect_err(ext);
        assert!(e.contains(field) && e.contains("bad"), "{ext}: {e}");
        assert!(!e.contains('\n'), "one line: {e}");
    }
}

/// The layer extensions reach `Material::layers` through the loader, and a file that
/// requires them loads.
#[test]
fn layer_extensions_reach_the_material() {
    let mat = r#"{"name": "velvet", "extensions": {
            "KHR_materials_sheen": {"sheenColorFactor": [0.5, 0.25, 1], "sheenRoughnessFactor": 0.4},
            "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.3},
            "KHR_materials_iridescence": {"iridescenceFactor": 1, "iridescenceThicknessMaximum": 250},
            "KHR_materials_anisotropy": {"anisotropyStrength": 0.7, "anisotropyRotation": 1.0}
        }}"#;
    let s = load("layers", mat).unwrap();
    let l = &s.materials[0].layers;
    assert_eq!(l.sheen_color.to_array(), [0.5, 0.25, 1.0]);
    assert_eq!(l.sheen_roughness, 0.4);
    assert_eq!(l.diffuse_transmission, 0.3);
    assert_eq!(l.diffuse_transmission_color.to_array(), [1.0; 3]);
    assert_eq!((l.iridescence, l.iridescence_thickness_max), (1.0, 250.0));
    assert_eq!((l.anisotropy_strength, l.anisotropy_rotation), (0.7, 1.0));
    let e = load(
        "badlayer",
        r#"{"name": "v", "extensions": {"KHR_materials_sheen": {"sheenRoughnessFactor": 2}}}"#,
    )
    .unwrap_err();
    assert!(
        e.contains("KHR_materials_sheen.sheenRoughnessFactor = 2 is outside [0, 1]"),
        "{e}"
    );
}
