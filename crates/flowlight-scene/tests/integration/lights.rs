//! `KHR_lights_punctual` loading, the emitter table and the `[environment]` config.

use crate::common;

use common::{embedded_gltf, temp_dir};
use flowlight_core::light::{Environment, PunctualKind};
use flowlight_core::Rgb;
use flowlight_scene::lights::{light_power_cdf, load_environment};
use flowlight_scene::{load_gltf, parse_config, ConfigError};
use glam::Vec3;
use std::collections::BTreeMap;
use std::path::Path;

const QUAD: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];
const QUAD_IDX: [u32; 6] = [0, 1, 2, 0, 2, 3];

/// A quad plus light nodes `nodes` (JSON objects) and the lights array `lights`.
fn with_lights(material: &str, nodes: &[&str], lights: &str) -> String {
    let g = embedded_gltf(&QUAD, &QUAD_IDX, material, "");
    let mut all = vec![r#"{"mesh": 0}"#.to_string()];
    all.extend(nodes.iter().map(|n| n.to_string()));
    let ids: Vec<String> = (0..all.len()).map(|i| i.to_string()).collect();
    let g = g
        .replace(
            r#""nodes": [{"mesh": 0}]"#,
            &format!(r#""nodes": [{}]"#, all.join(", ")),
        )
        .replace(
            r#""scenes": [{"nodes": [0]}]"#,
            &format!(r#""scenes": [{{"nodes": [{}]}}]"#, ids.join(", ")),
        );
    let end = g.rfind('}').unwrap();
    format!(
        r#"{}, "extensionsUsed": ["KHR_lights_punctual"], "extensions": {{"KHR_lights_punctual": {{"lights": {lights}}}}}}}"#,
        &g[..end]
    )
}

fn load_str(tag: &str, json: &str) -> Result<flowlight_scene::Scene, flowlight_scene::SceneError> {
    let d = temp_dir(tag);
    let p = d.join("s.gltf");
    std::fs::write(&p, json).unwrap();
    load_gltf(&p, &BTreeMap::new())
}

#[test]
fn punctual_lights_take_their_node_transforms() {
    // Spot: rotated 90° about +X, so its −Z axis points along −Y; translated to (1, 2, 3).
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let spot_node = format!(
        r#"{{"translation": [1.0, 2.0, 3.0], "rotation": [{}, 0.0, 0.0, {s}], "extensions": {{"KHR_lights_punctual": {{"light": 0}}}}}}"#,
        -s
    );
    // A parent scaled by 2 and moved: the child point light sits at (4, 0, 0) + 2·(1, 0, 0).
    let parent = r#"{"translation": [4.0, 0.0, 0.0], "scale": [2.0, 2.0, 2.0], "children": [3]}"#;
    let child =
        r#"{"translation": [1.0, 0.0, 0.0], "extensions": {"KHR_lights_punctual": {"light": 1}}}"#;
    let json = with_lights(
        "",
        &[&spot_node, parent, child],
        r#"[{"type": "spot", "intensity": 5.0, "color": [1.0, 0.5, 0.0], "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
            {"type": "point", "intensity": 2.0, "range": 10.0},
            {"type": "directional"}]"#,
    );
    // Scene nodes: 0 mesh, 1 spot, 2 parent (3 is its child); light 2 is unused.
    let json = json.replace(
        r#""scenes": [{"nodes": [0, 1, 2, 3]}]"#,
        r#""scenes": [{"nodes": [0, 1, 2]}]"#,
    );
    let sc = load_str("punctual", &json).unwrap();
    assert_eq!(sc.punctual_lights.len(), 2, "{:?}", sc.punctual_lights);
    let spot = sc
        .punctual_lights
        .iter()
        .find(|l| l.kind == PunctualKind::Spot)
        .unwrap();
    assert!(spot.position.distance(Vec3::new(1.0, 2.0, 3.0)) < 1e-5);
    assert!(
        spot.direction.distance(-Vec3::Y) < 1e-5,
        "{:?}",
        spot.direction
    );
    // Candela to W/sr: divided by 683 lm/W.
    assert_eq!(spot.intensity, Rgb::new(5.0, 2.5, 0.0) / 683.0);
    assert!((spot.cos_inner - 0.2f32.cos()).abs() < 1e-6);
    assert!((spot.cos_outer - 0.6f32.cos()).abs() < 1e-6);
    let point = sc
        .punctual_lights
        .iter()
        .find(|l| l.kind == PunctualKind::Point)
        .unwrap();
    assert!(point.position.distance(Vec3::new(6.0, 0.0, 0.0)) < 1e-5);
    assert_eq!(point.intensity, Rgb::splat(2.0 / 683.0));
    // No emitter, two punctual lights: a CDF of two entries.
    let cdf = light_power_cdf(&sc, &Environment::none());
    assert_eq!(cdf.len(), 2);
}

#[test]
fn bad_spot_cones_are_refused_with_the_light_index() {
    let json = with_lights(
        "",
        &[r#"{"extensions": {"KHR_lights_punctual": {"light": 0}}}"#],
        r#"[{"type": "spot", "spot": {"innerConeAngle": 0.7, "outerConeAngle": 0.5}}]"#,
    );
    let err = load_str("badspot", &json).unwrap_err().to_string();
    assert!(
        err.contains("KHR_lights_punctual light 0") && err.contains("innerConeAngle"),
        "{err}"
    );
}

#[test]
fn only_emitting_triangles_are_lights_and_power_includes_pi() {
    let json = embedded_gltf(
        &QUAD,
        &QUAD_IDX,
        r#"{"emissiveFactor": [1.0, 1.0, 1.0], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 2.0}}}"#,
        "",
    );
    let sc = load_str("emit", &json).unwrap();
    assert_eq!(sc.emitters.len(), 2);
    for e in &sc.emitters {
        assert_eq!(e.radiance, Rgb::splat(2.0));
        assert!((e.power() - std::f32::consts::PI * 0.5 * 2.0).abs() < 1e-4);
        assert_eq!(e.material, 0);
    }
    let none = embedded_gltf(&QUAD, &QUAD_IDX, r#"{"name": "dark"}"#, "");
    let sc = load_str("dark", &none).unwrap();
    assert!(sc.emitters.is_empty() && sc.punctual_lights.is_empty());
    assert!(light_power_cdf(&sc, &Environment::none()).is_empty());
    // A constant sky is a light of its own.
    let cdf = light_power_cdf(&sc, &Environment::constant(Rgb::ONE));
    assert_eq!(cdf, vec![1.0]);
}

fn cfg(tail: &str) -> Result<flowlight_scene::RenderConfig, ConfigError> {
    parse_config(
        Path::new("/tmp/x/render.toml"),
        &format!("scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n{tail}"),
    )
}

#[test]
fn environment_config_is_validated() {
    let c = cfg("[environment]\ncolor = [0.5, 1.0, 2.0]\nstrength = 2.0\n").unwrap();
    let e = c.environment.unwrap();
    assert_eq!(e.color, Some([0.5, 1.0, 2.0]));
    let data = load_environment(&c.path, &e).unwrap();
    assert_eq!(data.view().radiance(Vec3::X), Rgb::new(1.0, 2.0, 4.0));
    let m = cfg("[environment]\nmap = \"sky.hdr\"\nrotation_degrees = 90\n").unwrap();
    let e = m.environment.unwrap();
    assert_eq!(e.map.as_deref(), Some(Path::new("/tmp/x/sky.hdr")));
    assert_eq!((e.strength, e.rotation_degrees), (1.0, 90.0));
    for (tail, key) in [
        (
            "[environment]\ncolor = [1, 1, 1]\nmap = \"a.exr\"\n",
            "environment.map",
        ),
        ("[environment]\nstrength = 2.0\n", "environment"),
        ("[environment]\nmap = \"sky.png\"\n", "environment.map"),
        ("[environment]\ncolor = [1, -1, 1]\n", "environment.color"),
        (
            "[environment]\ncolor = [1, 1, 1]\nstrength = -1\n",
            "environment.strength",
        ),
    ] {
        let err = cfg(tail).unwrap_err().to_string();
        assert!(err.contains(key), "{tail}: {err}");
    }
    let err = cfg("[environment]\ncolour = [1, 1, 1]\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("colour"), "{err}");
}

#[test]
fn hdr_maps_load_and_missing_maps_name_the_file() {
    let d = temp_dir("hdr");
    let path = d.join("sky.hdr");
    // 4×2 map: bright top row, dim bottom row.
    let (w, h) = (4usize, 2usize);
    let px: Vec<image::Rgb<f32>> = (0..w * h)
        .map(|i| {
            if i < w {
                image::Rgb([4.0, 2.0, 1.0])
            } else {
                image::Rgb([0.25, 0.25, 0.25])
            }
        })
        .collect();
    let f = std::fs::File::create(&path).unwrap();
    image::codecs::hdr::HdrEncoder::new(f)
        .encode(&px, w, h)
        .unwrap();
    let c = parse_config(
        &d.join("r.toml"),
        "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n[environment]\nmap = \"sky.hdr\"\nstrength = 2.0\n",
    )
    .unwrap();
    let data = load_environment(&c.path, c.environment.as_ref().unwrap()).unwrap();
    assert_eq!((data.width, data.height), (4, 2));
    let env = data.view();
    let up = env.radiance(Vec3::Y);
    let down = env.radiance(-Vec3::Y);
    assert!(
        (up.r - 8.0).abs() < 0.1 && (up.g - 4.0).abs() < 0.1,
        "{up:?}"
    );
    assert!((down.r - 0.5).abs() < 0.02, "{down:?}");
    // Importance sampling favours the bright upper hemisphere.
    assert!(
        env.pdf(Vec3::new(0.0, 0.7, 0.7).normalize())
            > env.pdf(Vec3::new(0.0, -0.7, 0.7).normalize())
    );

    let missing = parse_config(
        &d.join("r.toml"),
        "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n[environment]\nmap = \"nope.exr\"\n",
    )
    .unwrap();
    let err = load_environment(&missing.path, missing.environment.as_ref().unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("environment.map") && err.contains("nope.exr"),
        "{err}"
    );
}
