//! The TOML render configuration.

use crate::common;

use common::*;
use flowlight_scene::{
    load_config, load_gltf, parse_config, ConfigError, Intersector, SampleBudget,
};
use glam::Vec3;
use std::path::Path;

const MINIMAL: &str = "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n";

#[test]
fn cornell_box_config_parses_with_resolved_paths_and_ordered_params() {
    let path = scenes_dir().join("cornell-box/cornell-box.toml");
    let c = load_config(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((c.width, c.height), (512, 512));
    assert_eq!(c.budget, SampleBudget::Spp(64));
    assert_eq!(c.spp(), Some(64));
    assert_eq!(c.integrator_plugin, "mcpt");
    let keys: Vec<&str> = c
        .integrator_params
        .iter()
        .map(|(k, _)| k.as_str())
        .collect();
    assert_eq!(keys, ["variant", "termination", "path_depth"]);
    assert_eq!(
        c.integrator_param("variant").and_then(|v| v.as_str()),
        Some("entangled")
    );
    assert_eq!(
        c.integrator_param("path_depth")
            .and_then(|v| v.as_integer()),
        Some(8)
    );
    assert!(c.scene.is_absolute() && c.scene.ends_with("cornell-box/cornell-box.gltf"));
    assert!(c.scene.exists());
    assert!(c.output_exr.ends_with("cornell-box/cornell-box.exr"));
    assert!(c
        .output_png
        .as_ref()
        .unwrap()
        .ends_with("cornell-box/cornell-box.png"));

    let scene = load_gltf(&c.scene, &c.material_overrides).unwrap();
    let cam = c.camera(&scene).unwrap();
    assert_eq!((cam.width, cam.height), (512, 512));
    assert!((cam.position - Vec3::new(0.278, 0.273, -0.8)).length() < 1e-6);
    assert!((cam.forward - Vec3::Z).length() < 1e-6);
    assert!((cam.tan_half_fov_y - (39.3077f32.to_radians() / 2.0).tan()).abs() < 1e-5);
}

#[test]
fn integrator_params_keep_file_order() {
    let text =
        "scene = \"s.gltf\"\n[integrator]\nzeta = 1\nplugin = \"p\"\nalpha = \"x\"\nmid = 2.5\n";
    let c = parse_config(Path::new("/tmp/a/b.toml"), text).unwrap();
    let keys: Vec<&str> = c
        .integrator_params
        .iter()
        .map(|(k, _)| k.as_str())
        .collect();
    assert_eq!(keys, ["zeta", "alpha", "mid"]);
    assert_eq!(c.scene, Path::new("/tmp/a/s.gltf"));
    assert_eq!(c.output_exr, Path::new("/tmp/a/b.exr"));
    assert_eq!(c.budget, SampleBudget::Spp(16));
    assert_eq!(c.intersector, Intersector::Auto);
}

fn parse_err(text: &str) -> (ConfigError, String) {
    let e = parse_config(Path::new("/cfg/render.toml"), text).expect_err("should fail");
    let m = e.to_string();
    assert!(
        m.contains("/cfg/render.toml"),
        "message does not name the file: {m}"
    );
    (e, m)
}

#[test]
fn unknown_key_names_key_and_line() {
    let (e, m) = parse_err(&format!("{MINIMAL}[render]\nwidth = 64\nwidht = 64\n"));
    match e {
        ConfigError::Parse { line, key, .. } => {
            assert_eq!(line, 6, "{m}");
            assert_eq!(key, "render.widht", "{m}");
        }
        other => panic!("{other}"),
    }
    assert!(m.contains("unknown field `widht`"), "{m}");
    let (_, m) = parse_err(&format!("{MINIMAL}[rendr]\nwidth = 64\n"));
    assert!(m.contains("rendr"), "{m}");
}

#[test]
fn wrong_type_names_the_key() {
    let (e, m) = parse_err(&format!("{MINIMAL}[render]\nwidth = \"wide\"\n"));
    match e {
        ConfigError::Parse { line, key, .. } => {
            assert_eq!((line, key.as_str()), (5, "render.width"), "{m}")
        }
        other => panic!("{other}"),
    }
}

#[test]
fn validation_errors_name_the_key() {
    let cases = [
        ("[render]\nspp = 4\ntime = 2.0\n", "render.spp"),
        ("[render]\nspp = 0\n", "render.spp"),
        ("[render]\ntime = -1.0\n", "render.time"),
        ("[render]\nwidth = 0\n", "render.width"),
        ("[render]\nheight = 0\n", "render.height"),
        ("[render]\ntile_size = 0\n", "render.tile_size"),
        ("[render]\nintersector = \"optix\"\n", "render.intersector"),
        ("[camera]\nfov_y = 180.0\n", "camera.fov_y"),
        (
            "[materials.white]\ndiffuse = \"oren-nayar\"\n",
            "materials.white",
        ),
    ];
    for (extra, key) in cases {
        let (e, m) = parse_err(&format!("{MINIMAL}{extra}"));
        assert!(matches!(e, ConfigError::Invalid { .. }), "{extra}: {m}");
        assert!(m.contains(&format!("`{key}`")), "{extra}: {m}");
    }
    let (_, m) = parse_err("[integrator]\nplugin = \"x\"\n");
    assert!(m.contains("scene"), "{m}");
}

#[test]
fn camera_override_and_missing_camera() {
    let dir = temp_dir("cam");
    let gltf = dir.join("s.gltf");
    std::fs::write(
        &gltf,
        embedded_gltf(
            &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            &[0, 1, 2],
            "",
            "",
        ),
    )
    .unwrap();
    let scene = load_gltf(&gltf, &Default::default()).unwrap();
    // Neither the file nor the config places a camera: the automatic one looks at the
    // bounding box's centre (the triangle's box is [0,1]² × {0}).
    let c = parse_config(&dir.join("r.toml"), MINIMAL).unwrap();
    let auto = c.camera(&scene).unwrap();
    let to_centre = (Vec3::new(0.5, 0.5, 0.0) - auto.position).normalize();
    assert!((to_centre - auto.forward).length() < 1e-5);
    let text = format!("{MINIMAL}[render]\nwidth = 40\nheight = 20\n[camera]\nposition = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\nfov_y = 30.0\n");
    let c = parse_config(&dir.join("r.toml"), &text).unwrap();
    let cam = c.camera(&scene).unwrap();
    assert_eq!((cam.width, cam.height), (40, 20));
    assert!((cam.forward + Vec3::Z).length() < 1e-6);
    assert!((cam.up - Vec3::Y).length() < 1e-6);
    let text = format!("{MINIMAL}[camera]\nposition = [0.0, 0.0, 5.0]\n");
    let c = parse_config(&dir.join("r.toml"), &text).unwrap();
    let m = c.camera(&scene).unwrap_err().to_string();
    assert!(m.contains("camera.look_at"), "{m}");
}

#[test]
fn d16_a_cache_beyond_its_limit_says_so() {
    let (_, m) = parse_err(
        "scene = \"s.gltf\"\n[render]\naccumulation_cache_mib = 1e12\n[integrator]\nplugin = \"mcpt\"\n",
    );
    assert!(
        m.contains("accumulation_cache_mib") && m.contains("limit") && !m.contains("positive"),
        "{m}"
    );
}
