//! `[camera]`'s thin lens (crate `config::lens`): aperture and focus keys, the f-number's
//! radius, focusing on a named node, and one-line errors naming the key.

use crate::common;

use common::*;
use flowlight_core::camera::Camera;
use flowlight_scene::{load_gltf, parse_config, Scene};
use glam::Vec3;
use std::path::Path;

const CONFIG: &str = "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n";

/// A unit quad in z = 0 and a named empty node "Target" at (0.5, 0, −2).
fn scene(tag: &str) -> (TempDir, Scene) {
    let dir = temp_dir(tag);
    let positions = [
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ];
    let json = embedded_gltf(&positions, &[0, 1, 2, 0, 2, 3], "", "")
        .replace(
            r#""scenes": [{"nodes": [0]}]"#,
            r#""scenes": [{"nodes": [0, 1]}]"#,
        )
        .replace(
            r#""nodes": [{"mesh": 0}]"#,
            r#""nodes": [{"mesh": 0, "name": "Quad"}, {"name": "Target", "translation": [0.5, 0, -2]}]"#,
        );
    let path = dir.join("s.gltf");
    std::fs::write(&path, json).unwrap();
    let scene = load_gltf(&path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    (dir, scene)
}

fn camera(dir: &Path, scene: &Scene, toml: &str) -> Result<Camera, String> {
    let c =
        parse_config(&dir.join("r.toml"), &format!("{CONFIG}{toml}")).map_err(|e| e.to_string())?;
    c.camera(scene).map_err(|e| e.to_string())
}

const PLACE: &str = "[camera]\nposition = [0, 0, 5]\nlook_at = [0, 0, 0]\nfov_y = 40.0\n";

#[test]
fn named_nodes_are_recorded_with_their_world_position() {
    let (_, s) = scene("lens-nodes");
    let names: Vec<&str> = s.named_nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["Quad", "Target"]);
    assert_eq!(s.named_nodes[1].position, Vec3::new(0.5, 0.0, -2.0));
}

#[test]
fn aperture_and_focus_make_a_thin_lens() {
    let (dir, s) = scene("lens-keys");
    // No lens keys, or a zero radius: the pinhole, identical to a camera without them.
    let pinhole = camera(&dir, &s, PLACE).unwrap();
    assert!(!pinhole.has_lens());
    assert_eq!(pinhole.lens_radius, 0.0);
    let zero = camera(&dir, &s, &format!("{PLACE}aperture_radius = 0.0\n")).unwrap();
    assert_eq!(zero, pinhole);
    let c = camera(
        &dir,
        &s,
        &format!("{PLACE}aperture_radius = 0.05\nfocus_distance = 4.0\n"),
    )
    .unwrap();
    assert!(c.has_lens());
    assert_eq!((c.lens_radius, c.focus_distance), (0.05, 4.0));
    // focus_on: the node's depth along the view axis, 5 − (−2) = 7.
    let c = camera(
        &dir,
        &s,
        &format!("{PLACE}aperture_radius = 0.05\nfocus_on = \"Target\"\n"),
    )
    .unwrap();
    assert!(
        (c.focus_distance - 7.0).abs() < 1e-5,
        "{}",
        c.focus_distance
    );
    // f/2 on a 24 mm sensor at 40°: F = 0.024 / (2 tan 20°) = 32.97 mm, R = F / 4.
    let c = camera(
        &dir,
        &s,
        &format!("{PLACE}f_number = 2.0\nfocus_distance = 5.0\n"),
    )
    .unwrap();
    let f = 0.024 / (2.0 * 20f32.to_radians().tan());
    assert!((c.lens_radius - f / 4.0).abs() < 1e-6, "{}", c.lens_radius);
    let c = camera(
        &dir,
        &s,
        &format!("{PLACE}f_number = 4.0\nsensor_height_mm = 12.0\nfocus_distance = 5.0\n"),
    )
    .unwrap();
    assert!((c.lens_radius - f / 16.0).abs() < 1e-6, "{}", c.lens_radius);
    // The automatic camera takes a lens too.
    let c = camera(
        &dir,
        &s,
        "[camera]\naperture_radius = 0.1\nfocus_distance = 3.0\n",
    )
    .unwrap();
    assert!(c.has_lens());
}

#[test]
fn bad_lens_values_are_one_line_errors_naming_the_key() {
    let (dir, s) = scene("lens-errors");
    for (toml, key, what) in [
        ("aperture_radius = -0.1\nfocus_distance = 2.0\n", "camera.aperture_radius", "≥ 0"),
        ("aperture_radius = nan\nfocus_distance = 2.0\n", "camera.aperture_radius", "≥ 0"),
        ("f_number = 0.0\nfocus_distance = 2.0\n", "camera.f_number", "positive"),
        ("aperture_radius = 0.1\nf_number = 2.0\nfocus_distance = 2.0\n", "camera.f_number", "not both"),
        ("aperture_radius = 0.1\nfocus_distance = -1.0\n", "camera.focus_distance", "positive"),
        ("aperture_radius = 0.1\n", "camera.focus_distance", "needs"),
        ("aperture_radius = 0.1\nfocus_on = \"Nowhere\"\n", "camera.focus_on", "\"Nowhere\""),
        ("aperture_radius = 0.1\nfocus_distance = 1.0\nfocus_on = \"Target\"\n", "camera.focus_on", "not both"),
        ("sensor_height_mm = 24.0\n", "camera.sensor_height_mm", "f_number"),
        ("projection = \"orthographic\"\northo_height = 2.0\naperture_radius = 0.1\nfocus_distance = 1.0\n", "camera.aperture_radius", "perspective"),
    ] {
        let (toml, fov) = if toml.contains("orthographic") {
            (toml.to_string(), "")
        } else {
            (toml.to_string(), "fov_y = 40.0\n")
        };
        let full = format!("[camera]\nposition = [0, 0, 5]\nlook_at = [0, 0, 0]\n{fov}{toml}");
        let e = camera(&dir, &s, &full).expect_err(&full);
        assert!(e.contains(key) && e.contains(what), "{toml}: {e}");
        assert!(!e.contains('\n'), "{toml}: more than one line: {e}");
    }
    // A node behind the camera cannot be focused on.
    let e = camera(
        &dir,
        &s,
        "[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, -10]\naperture_radius = 0.1\nfocus_on = \"Quad\"\n",
    )
    .unwrap_err();
    assert!(
        e.contains("camera.focus_on") && e.contains("in front"),
        "{e}"
    );
}
