//! Loading the project's scenes, and hit reconstruction on known triangles.

use crate::common;

use common::*;
use flowlight_core::geometry::Ray;
use flowlight_core::Rgb;
use flowlight_scene::{load_config, load_gltf, CameraProjection, Scene};
use glam::{Vec2, Vec3};
use std::collections::BTreeMap;
use std::path::Path;

fn load(p: &Path) -> Scene {
    load_gltf(p, &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn every_scene_in_the_scenes_folder_loads() {
    let mut loaded = 0;
    for dir in std::fs::read_dir(scenes_dir()).unwrap() {
        let dir = dir.unwrap().path();
        // `experiments/` holds benchmark suites (`flowlight bench`), not render configs.
        if !dir.is_dir() || dir.file_name().is_some_and(|n| n == "experiments") {
            continue;
        }
        for f in std::fs::read_dir(&dir).unwrap() {
            let f = f.unwrap().path();
            match f.extension().and_then(|e| e.to_str()) {
                Some("gltf" | "glb") => {
                    let s = load(&f);
                    assert!(!s.triangles.is_empty(), "{}", f.display());
                    assert_eq!(s.triangles.len(), s.triangle_material.len());
                    assert_eq!(s.triangles.len(), s.triangle_emitter.len());
                    // Surface data reads a triangle's emitter rank only where its material
                    // is emissive (`MeshView`'s docs): no emitter may hide elsewhere.
                    for (t, &r) in s.triangle_emitter.iter().enumerate() {
                        let m = &s.materials[s.triangle_material[t] as usize];
                        assert!(r < 0 || m.is_emissive(), "{}: {t}", f.display());
                    }
                    // Normals and TEXCOORD_0: one per vertex, or none in the scene.
                    for len in [s.normals.len(), s.uvs.len()] {
                        assert!(len == 0 || len == s.positions.len(), "{}", f.display());
                    }
                    loaded += 1;
                }
                Some("toml") => {
                    let c = load_config(&f).unwrap_or_else(|e| panic!("{e}"));
                    assert!(
                        c.scene.exists(),
                        "{}: scene {} missing",
                        f.display(),
                        c.scene.display()
                    );
                    let s = load_gltf(&c.scene, &c.material_overrides)
                        .unwrap_or_else(|e| panic!("{e}"));
                    c.camera(&s).unwrap_or_else(|e| panic!("{e}"));
                    loaded += 1;
                }
                _ => {}
            }
        }
    }
    assert!(loaded >= 3, "only {loaded} scene files found");
}

#[test]
fn cornell_box_gltf_and_glb_agree_and_match_the_source_note() {
    let dir = scenes_dir().join("cornell-box");
    let a = load(&dir.join("cornell-box.gltf"));
    let b = load(&dir.join("cornell-box.glb"));
    // light 2 + floor 2 + ceiling 4 + back 2 + 2 side walls × 2 + two boxes × 12.
    assert_eq!(a.triangles.len(), 38);
    assert_eq!(b.triangles.len(), 38);
    assert_eq!(a.triangle_vertices(), b.triangle_vertices());
    assert_eq!(a.stats.degenerate_dropped, 0);

    for s in [&a, &b] {
        assert_eq!(s.emitters.len(), 2);
        for e in &s.emitters {
            let want = Rgb::new(18.387, 10.9873, 2.75357);
            assert!(
                (e.radiance.r - want.r).abs() < 1e-3
                    && (e.radiance.g - want.g).abs() < 1e-3
                    && (e.radiance.b - want.b).abs() < 1e-3,
                "{:?}",
                e.radiance
            );
            assert!((e.p0.y - 0.5483).abs() < 1e-6);
            assert_eq!(
                s.triangle_emitter[e.prim as usize],
                s.emitters.iter().position(|x| x == e).unwrap() as i32
            );
        }
        let total_area: f32 = s.emitters.iter().map(|e| e.area).sum();
        assert!((total_area - 0.13 * 0.105).abs() < 1e-5, "{total_area}");
        assert_eq!(s.emitter_power_cdf.len(), 2);
        assert_eq!(*s.emitter_power_cdf.last().unwrap(), 1.0);

        assert_eq!(s.cameras.len(), 1);
        let cam = &s.cameras[0];
        assert!((cam.position - Vec3::new(0.278, 0.273, -0.8)).length() < 1e-6);
        assert!((cam.forward - Vec3::Z).length() < 1e-6, "{}", cam.forward);
        assert!((cam.up - Vec3::Y).length() < 1e-6);
        let CameraProjection::Perspective { fov_y_degrees } = cam.projection else {
            panic!("{:?}", cam.projection)
        };
        assert!((fov_y_degrees - 39.3077).abs() < 1e-3);

        let (lo, hi) = s.bounds().unwrap();
        assert!(lo.abs().max_element() < 1e-6);
        assert!(
            (hi - Vec3::new(0.556, 0.5488, 0.5592)).length() < 1e-5,
            "{hi}"
        );
        let white = s.material_names.iter().position(|n| n == "white").unwrap();
        assert_eq!(s.materials[white].base_color.r, 0.885809);
        assert!(!s.materials[white].is_emissive());
    }
}

#[test]
fn surface_hit_on_a_known_triangle() {
    let dir = temp_dir("hit");
    let positions = [
        [0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.0, 2.0, 0.0],
        [5.0, 5.0, 5.0],
        [6.0, 5.0, 5.0],
        [5.0, 6.0, 5.0],
    ];
    let uv: [[f32; 2]; 6] = [
        [0.0, 0.0],
        [1.0, 0.0],
        [0.0, 1.0],
        [0.0; 2],
        [0.0; 2],
        [0.0; 2],
    ];
    let mut bytes = mesh_bytes(&positions, &[0, 1, 2, 3, 4, 5]);
    let uv_off = bytes.len();
    for t in uv {
        for c in t {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0, "translation": [0, 0, 1]}}],
  "meshes": [{{"primitives": [
    {{"attributes": {{"POSITION": 0, "TEXCOORD_0": 2}}, "indices": 1, "material": 0}}]}}],
  "materials": [{{"name": "lamp", "emissiveFactor": [1, 1, 1], "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": 4}}}}}}],
  "extensionsUsed": ["KHR_materials_emissive_strength"],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 6, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}},
    {{"bufferView": 2, "componentType": 5126, "count": 6, "type": "VEC2"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 72}},
    {{"buffer": 0, "byteOffset": 72, "byteLength": 24}},
    {{"buffer": 0, "byteOffset": {uv_off}, "byteLength": 48}}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {len}}}]}}"#,
        b64 = base64(&bytes),
        len = bytes.len()
    );
    let path = dir.join("hit.gltf");
    std::fs::write(&path, json).unwrap();
    let s = load(&path);
    assert_eq!(s.triangles.len(), 2);
    assert_eq!(s.emitters.len(), 2);
    assert_eq!(s.emitters[0].radiance, Rgb::splat(4.0));
    assert!((s.emitters[0].area - 2.0).abs() < 1e-6);
    let ray = Ray::new(Vec3::new(0.5, 0.5, 5.0), -Vec3::Z, f32::INFINITY);
    // b1 = 0.25 (vertex 1), b2 = 0.5 (vertex 2): p = (0.5, 1.0, 1.0) after the translation.
    let h = s.surface_hit(&ray, 4.0, 0, 0.25, 0.5);
    assert!((h.p - Vec3::new(0.5, 1.0, 1.0)).length() < 1e-6, "{}", h.p);
    assert!(h.p_error.max_element() > 0.0 && h.p_error.max_element() < 1e-5);
    assert_eq!(h.ng, Vec3::Z);
    assert_eq!(h.ns, Vec3::Z);
    assert!((h.uv - Vec2::new(0.25, 0.5)).length() < 1e-6, "{}", h.uv);
    assert_eq!((h.prim, h.material, h.emitter, h.t), (0, 0, 0, 4.0));
    let h2 = s.surface_hit(&ray, 1.0, 1, 0.0, 0.0);
    assert_eq!(h2.emitter, 1);
    assert!((h2.p - Vec3::new(5.0, 5.0, 6.0)).length() < 1e-6);
}

#[test]
fn mirrored_nodes_keep_the_front_face_and_normals_follow_the_inverse_transpose() {
    let dir = temp_dir("mirror");
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let path = dir.join("m.gltf");
    std::fs::write(
        &path,
        embedded_gltf(&pos, &[0, 1, 2], "", r#", "scale": [-1, 2, 1]"#),
    )
    .unwrap();
    let s = load(&path);
    let [p0, p1, p2] = s.triangle_vertices()[0];
    // Mirrored in x: the face still points to +z, so the winding was flipped.
    let n = (p1 - p0).cross(p2 - p0).normalize();
    assert!((n - Vec3::Z).length() < 1e-6, "{n}");
    let h = s.surface_hit(&Ray::new(Vec3::ZERO, Vec3::Z, 1.0), 1.0, 0, 0.3, 0.3);
    assert!((h.ng - Vec3::Z).length() < 1e-6 && (h.ns - Vec3::Z).length() < 1e-6);
    assert_eq!(s.material_names, ["default"]);
    assert_eq!(
        s.materials[0],
        flowlight_core::material::Material::default()
    );
    assert!(s.emitters.is_empty() && s.emitter_power_cdf.is_empty());
}

#[test]
fn oren_nayar_from_extras_and_config_overrides() {
    use flowlight_core::material::DiffuseModel;
    use flowlight_scene::{DiffuseChoice, MaterialOverride};
    let dir = temp_dir("on");
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mat = r#"{"name": "rough", "extras": {"flowlight": {"diffuse": "oren-nayar", "sigma_degrees": 20}}}"#;
    let path = dir.join("on.gltf");
    std::fs::write(&path, embedded_gltf(&pos, &[0, 1, 2], mat, "")).unwrap();
    let s = load(&path);
    assert_eq!(s.materials[0].diffuse_model, DiffuseModel::OrenNayar);
    assert!((s.materials[0].oren_nayar_sigma - 20f32.to_radians()).abs() < 1e-6);
    let mut o = BTreeMap::new();
    o.insert(
        "rough".to_string(),
        MaterialOverride {
            diffuse: Some(DiffuseChoice::Lambert),
            two_sided_emission: None,
            base_color: None,
            sigma_degrees: None,
        },
    );
    let s = load_gltf(&path, &o).unwrap();
    assert_eq!(s.materials[0].diffuse_model, DiffuseModel::Lambert);
}

#[test]
fn triangle_strips_are_converted_with_consistent_winding() {
    let dir = temp_dir("strip");
    let pos = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let path = dir.join("strip.gltf");
    let json = embedded_gltf(&pos, &[0, 1, 2, 3], "", "")
        .replace(r#""indices": 1"#, r#""indices": 1, "mode": 5"#);
    std::fs::write(&path, json).unwrap();
    let s = load(&path);
    assert_eq!(s.triangles.len(), 2);
    assert_eq!(s.stats.converted_strips_fans, 1);
    for [p0, p1, p2] in s.triangle_vertices() {
        assert!((p1 - p0).cross(p2 - p0).z > 0.0, "strip triangle flipped");
    }
    let json = embedded_gltf(&pos, &[0, 1, 2, 3], "", "")
        .replace(r#""indices": 1"#, r#""indices": 1, "mode": 0"#);
    std::fs::write(&path, json).unwrap();
    let e = load_gltf(&path, &BTreeMap::new()).unwrap_err();
    assert!(
        matches!(e, flowlight_scene::SceneError::NoTriangles { .. }),
        "{e}"
    );
}
