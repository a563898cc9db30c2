//! Camera selection, orthographic cameras, the config's own camera and the automatic camera
//! (crate `config` module docs, "Cameras"), on tiny synthetic glTF files.

use crate::common;

use common::*;
use flowlight_core::camera::{Camera, Projection};
use flowlight_scene::{load_gltf, parse_config, CameraProjection, Scene};
use glam::{Vec2, Vec3};
use std::path::Path;

const CONFIG: &str = "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n";

/// A unit quad in z = 0 ([−1, 1]², as two triangles) plus the extra `nodes` (JSON objects
/// after the mesh node, all roots of the scene) and `cameras` (the JSON array's items).
fn scene_with(tag: &str, nodes: &[&str], cameras: &str) -> (TempDir, Scene) {
    let dir = temp_dir(tag);
    let positions = [
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ];
    let mut json = embedded_gltf(&positions, &[0, 1, 2, 0, 2, 3], "", "");
    if !nodes.is_empty() {
        let roots: Vec<String> = (0..=nodes.len()).map(|i| i.to_string()).collect();
        json = json
            .replace(
                r#""scenes": [{"nodes": [0]}]"#,
                &format!(r#""scenes": [{{"nodes": [{}]}}]"#, roots.join(", ")),
            )
            .replace(
                r#""nodes": [{"mesh": 0}]"#,
                &format!(
                    r#""nodes": [{{"mesh": 0}}, {}], "cameras": [{cameras}]"#,
                    nodes.join(", ")
                ),
            );
    }
    let path = dir.join("s.gltf");
    std::fs::write(&path, json).unwrap();
    let scene = load_gltf(&path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    (dir, scene)
}

/// The camera that `toml` (appended to a minimal config) builds for `scene`.
fn camera(dir: &Path, scene: &Scene, toml: &str) -> Result<Camera, String> {
    let c =
        parse_config(&dir.join("r.toml"), &format!("{CONFIG}{toml}")).map_err(|e| e.to_string())?;
    c.camera(scene).map_err(|e| e.to_string())
}

/// Three camera nodes, in traversal order: node 1 places cameras[1] "Side" (perspective,
/// at x = 5 looking along −X), node 2 places cameras[0] "Top" (orthographic, xmag 2, ymag 1,
/// at y = 4 looking down), node 3 "Front" places the unnamed cameras[2] (perspective at
/// z = 10 looking along −Z, aspectRatio 1).
fn three_cameras(tag: &str) -> (TempDir, Scene) {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    scene_with(
        tag,
        &[
            &format!(r#"{{"camera": 1, "translation": [5, 0, 0], "rotation": [0, {h}, 0, {h}]}}"#),
            &format!(r#"{{"camera": 0, "translation": [0, 4, 0], "rotation": [-{h}, 0, 0, {h}]}}"#),
            r#"{"camera": 2, "name": "Front", "translation": [0, 0, 10]}"#,
        ],
        r#"{"type": "orthographic", "name": "Top", "orthographic": {"xmag": 2, "ymag": 1, "znear": 0.1, "zfar": 100}},
           {"type": "perspective", "name": "Side", "perspective": {"yfov": 0.5, "znear": 0.1}},
           {"type": "perspective", "perspective": {"yfov": 1.0, "aspectRatio": 1.0, "znear": 0.1}}"#,
    )
}

#[test]
fn every_camera_node_is_loaded_in_traversal_order() {
    let (_, s) = three_cameras("load");
    let got: Vec<(usize, usize)> = s.cameras.iter().map(|c| (c.index, c.node)).collect();
    assert_eq!(got, [(1, 1), (0, 2), (2, 3)]);
    assert_eq!(s.cameras[0].name.as_deref(), Some("Side"));
    assert_eq!(s.cameras[2].node_name.as_deref(), Some("Front"));
    // Rotation by +90° about Y turns −Z into −X.
    assert!((s.cameras[0].forward + Vec3::X).length() < 1e-6);
    // Rotation by −90° about X turns −Z into −Y and +Y into −Z.
    assert!((s.cameras[1].forward + Vec3::Y).length() < 1e-6);
    assert!((s.cameras[1].up + Vec3::Z).length() < 1e-6);
    assert_eq!(
        s.cameras[1].projection,
        CameraProjection::Orthographic { half_height: 1.0 }
    );
    assert_eq!(s.cameras[1].aspect, Some(2.0));
}

#[test]
fn selection_by_default_index_and_name() {
    let (dir, s) = three_cameras("select");
    // Default: the first camera node in traversal order (cameras[1], not cameras[0]).
    let c = camera(&dir, &s, "").unwrap();
    assert_eq!(c.kind(), Projection::Perspective);
    assert!((c.position - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-6);
    assert!((c.tan_half_fov_y - 0.25f32.tan()).abs() < 1e-6);
    // index = the glTF camera index.
    let c = camera(&dir, &s, "[camera]\nindex = 0\n").unwrap();
    assert_eq!(c.kind(), Projection::Orthographic);
    assert!((c.position - Vec3::new(0.0, 4.0, 0.0)).length() < 1e-6);
    let c = camera(&dir, &s, "[camera]\nindex = 2\n").unwrap();
    assert!((c.position - Vec3::new(0.0, 0.0, 10.0)).length() < 1e-6);
    // name: the camera's own name, or the name of the node that places it.
    let c = camera(&dir, &s, "[camera]\nname = \"Top\"\n").unwrap();
    assert_eq!(c.kind(), Projection::Orthographic);
    let c = camera(&dir, &s, "[camera]\nname = \"Front\"\n").unwrap();
    assert!((c.forward + Vec3::Z).length() < 1e-6);
    assert!((c.tan_half_fov_y - 0.5f32.tan()).abs() < 1e-6);
    // Other keys replace parts of the selected camera.
    let c = camera(&dir, &s, "[camera]\nname = \"Front\"\nfov_y = 90.0\n").unwrap();
    assert!((c.tan_half_fov_y - 1.0).abs() < 1e-6);
    assert!((c.position - Vec3::new(0.0, 0.0, 10.0)).length() < 1e-6);
    let c = camera(&dir, &s, "[camera]\nindex = 0\northo_height = 6.0\n").unwrap();
    assert_eq!(c.ortho_half_height, 3.0);
}

#[test]
fn a_name_or_index_that_does_not_exist_lists_the_cameras() {
    let (dir, s) = three_cameras("badname");
    let m = camera(&dir, &s, "[camera]\nname = \"Nope\"\n").unwrap_err();
    assert!(m.contains("r.toml") && m.contains("camera.name"), "{m}");
    assert!(m.contains("\"Nope\""), "{m}");
    for c in [
        "1 \"Side\" (node 1",
        "0 \"Top\" (node 2",
        "2 (node 3 \"Front\"",
    ] {
        assert!(m.contains(c), "{c}: {m}");
    }
    let m = camera(&dir, &s, "[camera]\nindex = 7\n").unwrap_err();
    assert!(
        m.contains("camera.index") && m.contains("cameras[7]"),
        "{m}"
    );
    assert!(
        m.contains("orthographic") && m.contains("perspective"),
        "{m}"
    );
    // No camera at all in the file.
    let (dir, s) = scene_with("nocams", &[], "");
    let m = camera(&dir, &s, "[camera]\nindex = 0\n").unwrap_err();
    assert!(m.contains("the scene has no cameras"), "{m}");
    let m = camera(&dir, &s, "[camera]\nname = \"x\"\nindex = 0\n").unwrap_err();
    assert!(m.contains("not both"), "{m}");
}

#[test]
fn orthographic_camera_rays_cover_xmag_ymag() {
    let (dir, s) = three_cameras("ortho");
    // 200×100: the image's aspect 2 equals xmag/ymag, so the view is [−2, 2] × [−1, 1].
    let c = camera(
        &dir,
        &s,
        "[render]\nwidth = 200\nheight = 100\n[camera]\nname = \"Top\"\n",
    )
    .unwrap();
    assert_eq!(c.ortho_half_height, 1.0);
    // Looking down −Y with up −Z: right = forward × up = (−Y) × (−Z) = +X.
    assert!((c.right - Vec3::X).length() < 1e-6, "{}", c.right);
    let corner = c.generate_ray(Vec2::new(0.0, 0.0));
    assert!(
        (corner.origin - Vec3::new(-2.0, 4.0, -1.0)).length() < 1e-5,
        "{}",
        corner.origin
    );
    assert!((corner.dir + Vec3::Y).length() < 1e-6);
    // The quad's corner (1, 0, −1)… seen where x = 1 → u = 0.5, z = −1 → v = 1 (top edge).
    let p = c.project(Vec3::new(1.0, 0.0, -1.0)).unwrap_or(Vec2::NAN);
    assert!((p - Vec2::new(150.0, 0.0)).length() < 1e-3, "{p}");
}

#[test]
fn the_image_size_wins_over_the_gltf_aspect_ratio() {
    let (dir, s) = three_cameras("aspect");
    // cameras[2] asks for aspectRatio 1; the image is 300×100. yfov is kept.
    let c = camera(
        &dir,
        &s,
        "[render]\nwidth = 300\nheight = 100\n[camera]\nindex = 2\n",
    )
    .unwrap();
    assert_eq!((c.width, c.height), (300, 100));
    assert!((c.tan_half_fov_y - 0.5f32.tan()).abs() < 1e-6);
    let right_edge = c.generate_ray(Vec2::new(300.0, 50.0)).dir;
    let half_angle_x = right_edge.dot(c.right).atan2(right_edge.dot(c.forward));
    assert!((half_angle_x.tan() - 3.0 * 0.5f32.tan()).abs() < 1e-5);
}

#[test]
fn config_camera_without_a_gltf_camera() {
    let (dir, s) = scene_with("cfgcam", &[], "");
    let c = camera(
        &dir,
        &s,
        "[camera]\nposition = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\n",
    )
    .unwrap();
    assert_eq!(c.kind(), Projection::Perspective);
    assert!(
        (c.tan_half_fov_y - 20f32.to_radians().tan()).abs() < 1e-6,
        "default 40°"
    );
    let c = camera(
        &dir,
        &s,
        "[camera]\nposition = [0.0, 0.0, 5.0]\nforward = [0.0, 0.0, -1.0]\nprojection = \"orthographic\"\northo_height = 3.0\n",
    )
    .unwrap();
    assert_eq!(c.kind(), Projection::Orthographic);
    assert_eq!(c.ortho_half_height, 1.5);
    // 512×512: the top-left ray starts at (−1.5, 1.5) on the film plane z = 5.
    let r = c.generate_ray(Vec2::ZERO);
    assert!((r.origin - Vec3::new(-1.5, 1.5, 5.0)).length() < 1e-5);
    for (toml, key) in [
        (
            "[camera]\nposition = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\nprojection = \"orthographic\"\n",
            "camera.ortho_height",
        ),
        (
            "[camera]\nprojection = \"orthographic\"\nfov_y = 30.0\n",
            "camera.fov_y",
        ),
        ("[camera]\nprojection = \"fisheye\"\n", "camera.projection"),
        ("[camera]\northo_height = -1.0\n", "camera.ortho_height"),
        ("[camera]\nlook_at = [0.0, 0.0, 0.0]\n", "camera.position"),
    ] {
        let m = camera(&dir, &s, toml).unwrap_err();
        assert!(m.contains(key) && m.contains("r.toml"), "{toml}: {m}");
    }
}

/// Points on a sphere (centre `c`, radius `r`): the poles and rings of a UV sphere.
fn sphere_points(c: Vec3, r: f32) -> Vec<Vec3> {
    let mut pts = vec![c + Vec3::Y * r, c - Vec3::Y * r];
    for i in 1..24 {
        let theta = std::f32::consts::PI * i as f32 / 24.0;
        for j in 0..48 {
            let phi = std::f32::consts::TAU * j as f32 / 48.0;
            pts.push(
                c + r * Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                ),
            );
        }
    }
    pts
}

#[test]
fn no_camera_anywhere_frames_the_bounding_sphere() {
    // The quad [−1, 1]² × {0} moved by (3, −2, 1): bounding sphere centre (3, −2, 1), r = √2.
    let dir = temp_dir("auto");
    let json = embedded_gltf(
        &[
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ],
        &[0, 1, 2, 0, 2, 3],
        "",
        r#", "translation": [3, -2, 1]"#,
    );
    std::fs::write(dir.join("s.gltf"), json).unwrap();
    let s = load_gltf(&dir.join("s.gltf"), &Default::default()).unwrap();
    assert!(s.cameras.is_empty());
    let (centre, r) = (Vec3::new(3.0, -2.0, 1.0), 2f32.sqrt());
    for (w, h, extra) in [
        (512, 512, ""),
        (400, 100, ""),
        (100, 300, ""),
        (300, 200, "[camera]\nfov_y = 70.0\n"),
        (400, 100, "[camera]\nprojection = \"orthographic\"\n"),
        (100, 300, "[camera]\nprojection = \"orthographic\"\n"),
    ] {
        let toml = format!("[render]\nwidth = {w}\nheight = {h}\n{extra}");
        let c = camera(&dir, &s, &toml).unwrap();
        let what = format!("{w}x{h} {extra:?}");
        // From the front (+Z), right (+X) and above (+Y), looking at the centre.
        let off = c.position - centre;
        assert!(off.x > 0.0 && off.y > 0.0 && off.z > 0.0, "{what}: {off}");
        assert!((off.normalize() + c.forward).length() < 1e-5, "{what}");
        assert!((c.up.dot(Vec3::Y)) > 0.9, "{what}");
        // The sphere is inside the frustum: every point of a slightly smaller sphere projects
        // onto the film (in front of the camera)…
        for p in sphere_points(centre, 0.995 * r) {
            assert!(c.project(p).is_some(), "{what}: {p} is not in view");
        }
        // …and the framing is tight: a slightly larger sphere leaves the film somewhere.
        assert!(
            sphere_points(centre, 1.03 * r)
                .iter()
                .any(|p| c.project(*p).is_none()),
            "{what}: the sphere is framed loosely"
        );
        // Independently of `project`: the pinhole distance is r / sin θ, θ the smaller half
        // angle of the view.
        if c.kind() == Projection::Perspective {
            let ty = c.tan_half_fov_y;
            let theta = ty.atan().min((ty * w as f32 / h as f32).atan());
            assert!((off.length() - r / theta.sin()).abs() < 1e-4, "{what}");
        } else {
            assert!(off.length() > r, "{what}: the film plane cuts the sphere");
        }
    }
}

#[test]
fn a_camera_node_with_zero_scale_is_skipped_not_fatal() {
    let (dir, s) = scene_with(
        "zeroscale",
        &[
            r#"{"camera": 0, "scale": [0, 0, 0]}"#,
            r#"{"camera": 0, "translation": [0, 0, 7]}"#,
        ],
        r#"{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}"#,
    );
    let got: Vec<usize> = s.cameras.iter().map(|c| c.node).collect();
    assert_eq!(got, [2]);
    let c = camera(&dir, &s, "").unwrap();
    assert!((c.position - Vec3::new(0.0, 0.0, 7.0)).length() < 1e-6);
}

#[test]
fn d16_a_forward_of_any_finite_length_is_a_direction() {
    // Its squared length overflowed (1e60) or underflowed (1e-60) f32, and the error blamed
    // `camera.look_at`, which the config does not have.
    let (dir, s) = scene_with("d16-forward", &[], "");
    for f in ["-1e30", "-1e-30"] {
        let c = camera(
            &dir,
            &s,
            &format!("[camera]\nposition = [0, 0, 5]\nforward = [0, 0, {f}]\n"),
        )
        .unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(
            (c.forward - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6,
            "{f}"
        );
    }
}
