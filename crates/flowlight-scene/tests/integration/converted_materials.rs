//! The shading models converted to the metallic-roughness material and the WebP images,
//! end to end through the loader: `KHR_materials_pbrSpecularGlossiness` (also when the file
//! requires it), `KHR_materials_unlit`, `EXT_texture_webp` (a texture with no other source).

use flowlight_scene::gltf_loader::load_gltf;
use flowlight_scene::texture::srgb_to_linear;
use flowlight_scene::Scene;
use flowlight_testkit::gltf::{png8, temp_dir, Attribute, Quad};
use glam::Vec2;
use std::collections::BTreeMap;

/// Loads `q` with `required` added to `extensionsUsed` and `extensionsRequired`.
fn load_requiring(q: &Quad, required: &[&str], tag: &str) -> Scene {
    let mut doc: gltf::json::Value = gltf::json::deserialize::from_str(&q.json()).unwrap();
    let names: Vec<gltf::json::Value> = required.iter().map(|&n| n.into()).collect();
    doc["extensionsRequired"] = names.clone().into();
    let used = doc["extensionsUsed"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    doc["extensionsUsed"] = used.into_iter().chain(names).collect::<Vec<_>>().into();
    let dir = temp_dir(tag);
    let path = dir.join("q.gltf");
    std::fs::write(&path, gltf::json::serialize::to_string(&doc).unwrap()).unwrap();
    load_gltf(&path, &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"))
}

fn uv(u: f32, v: f32) -> [Vec2; 2] {
    [Vec2::new(u, v); 2]
}

#[test]
fn a_required_specular_glossiness_material_loads_converted() {
    // One RGBA texel: specular (sRGB) 255, 128, 0 and glossiness A = 102 (0.4).
    let q = Quad {
        images: vec![png8(1, 1, 4, &[255, 128, 0, 102])],
        textures: r#"{"source": 0}"#.into(),
        material:
            r#"{"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1], "metallicFactor": 1},
            "extensions": {"KHR_materials_pbrSpecularGlossiness": {
                "diffuseFactor": [0.5, 0.25, 0.125, 0.75], "specularFactor": [1, 0.5, 0.5],
                "glossinessFactor": 0.5, "specularGlossinessTexture": {"index": 0}}}}"#
                .into(),
        ..Quad::default()
    };
    let s = load_requiring(&q, &["KHR_materials_pbrSpecularGlossiness"], "specgloss");
    let m = &s.materials[0];
    assert_eq!(
        (m.metallic, m.ior, m.specular, m.roughness),
        (0.0, 0.0, 1.0, 1.0)
    );
    assert_eq!(m.base_alpha, 0.75);
    let r = m.resolve(uv(0.5, 0.5), [1.0; 4], &s.texture_table);
    assert_eq!(r.base, flowlight_core::Rgb::new(0.5, 0.25, 0.125));
    // Roughness 1 − g·A = 1 − 0.5 · 0.4 = 0.8 (16-bit derived texture).
    assert!(
        (r.material.roughness - 0.8).abs() < 1e-4,
        "{}",
        r.material.roughness
    );
    assert_eq!(r.material.metallic, 0.0);
    // Specular colour: factor × sRGB-decoded texture.
    let c = r.material.specular_color;
    assert!((c.r - 1.0).abs() < 1e-6, "{c:?}");
    assert!(
        (c.g - 0.5 * srgb_to_linear(128.0 / 255.0)).abs() < 1e-6,
        "{c:?}"
    );
    assert_eq!(c.b, 0.0);
}

#[test]
fn an_unlit_material_emits_its_base_colour_and_is_a_light() {
    let q = Quad {
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1]},
            "doubleSided": true, "extensions": {"KHR_materials_unlit": {}}}"#
            .into(),
        ..Quad::default()
    };
    let s = load_requiring(&q, &["KHR_materials_unlit"], "unlit");
    let m = &s.materials[0];
    assert_eq!(m.emission, flowlight_core::Rgb::new(0.2, 0.4, 0.6));
    assert_eq!(m.two_sided_emission, 1);
    assert_eq!(m.base_color, flowlight_core::Rgb::ZERO);
    assert_eq!(s.emitters.len(), 2, "both triangles are lights");
}

/// Red vertex colours at x = 0, blue at x = 1 (the quad's vertices 1 and 2).
const RED_TO_BLUE: [[f32; 3]; 4] = [
    [1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 0.0],
];

#[test]
fn an_unlit_materials_emission_takes_the_vertex_colours() {
    use flowlight_core::Rgb;
    let q = Quad {
        extra: vec![Attribute::floats("COLOR_0", RED_TO_BLUE)],
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1]},
            "extensions": {"KHR_materials_unlit": {}}}"#
            .into(),
        ..Quad::default()
    };
    let s = load_requiring(&q, &["KHR_materials_unlit"], "unlit-colors");
    assert_eq!(s.emitters.len(), 2);
    // The spec's unlit colour, base colour × COLOR_0, at every corner, on the hit side and
    // the light side alike (both read `Emitter::emission_at`).
    let corner = |x: f32| {
        if x < 0.5 {
            Rgb::new(0.5, 0.0, 0.0)
        } else {
            Rgb::new(0.0, 0.0, 1.0)
        }
    };
    for e in &s.emitters {
        assert_eq!(e.vertex_colored, 1);
        for (k, p) in [e.p0, e.p1, e.p2].into_iter().enumerate() {
            let mut b = [0.0; 3];
            b[k] = 1.0;
            assert_eq!(
                e.emission_at(b, &s.materials, &s.texture_table),
                corner(p.x)
            );
        }
        // The power is from the mean over the triangle: the corners' mean, as the colour is
        // linear across it, up to the loader's 16 stratified points (the power only chooses
        // lights; the emission itself is exact).
        let mean = (corner(e.p0.x) + corner(e.p1.x) + corner(e.p2.x)) / 3.0;
        for (got, want) in e.radiance.to_array().into_iter().zip(mean.to_array()) {
            assert!(
                (got - want).abs() < 0.02 * want.max(0.1),
                "{:?} against {mean:?}",
                e.radiance
            );
        }
    }
    // An emissive material that is not unlit ignores the vertex colours (glTF multiplies
    // only the base colour by COLOR_0).
    let lit = Quad {
        extra: vec![Attribute::floats("COLOR_0", RED_TO_BLUE)],
        material: r#"{"emissiveFactor": [0.5, 1, 1]}"#.into(),
        ..Quad::default()
    };
    let s = load_requiring(&lit, &[], "emissive-colors");
    for e in &s.emitters {
        assert_eq!(e.vertex_colored, 0);
        assert_eq!(
            e.emission_at([1.0, 0.0, 0.0], &s.materials, &s.texture_table),
            Rgb::new(0.5, 1.0, 1.0)
        );
    }
}

#[test]
fn a_webp_only_texture_is_decoded() {
    // A 2×1 lossless WebP: a red and a blue texel.
    let img = image::RgbaImage::from_raw(2, 1, vec![255, 0, 0, 255, 0, 0, 255, 255]).unwrap();
    let mut webp = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut webp)
        .encode(img.as_raw(), 2, 1, image::ExtendedColorType::Rgba8)
        .unwrap();
    let q = Quad {
        images: vec![webp],
        textures: r#"{"sampler": 0, "extensions": {"EXT_texture_webp": {"source": 0}}}"#.into(),
        samplers: r#"{"magFilter": 9728}"#.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}"#.into(),
        ..Quad::default()
    };
    let s = load_requiring(&q, &["EXT_texture_webp"], "webp");
    let m = &s.materials[0];
    let left = m.base_rgba_at(uv(0.25, 0.5), [1.0; 4], &s.texture_table).0;
    let right = m.base_rgba_at(uv(0.75, 0.5), [1.0; 4], &s.texture_table).0;
    assert_eq!((left.r, left.b), (1.0, 0.0));
    assert_eq!((right.r, right.b), (0.0, 1.0));
}
