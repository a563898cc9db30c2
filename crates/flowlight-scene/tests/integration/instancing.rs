//! Instancing: a mesh placed by several nodes (or by EXT_mesh_gpu_instancing) is stored once
//! and shows, triangle by triangle, what the flattened scene shows.

use flowlight_core::geometry::Ray;
use flowlight_scene::{load_gltf, Scene};
use flowlight_testkit::gltf::{octahedra_ext_gltf, octahedra_gltf, octahedra_placements, temp_dir};
use glam::{Mat4, Vec3};
use std::collections::BTreeMap;

fn load_json(tag: &str, json: &str) -> Scene {
    let dir = temp_dir(tag);
    let p = dir.join(format!("{tag}.gltf"));
    std::fs::write(&p, json).unwrap();
    load_gltf(&p, &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"))
}

fn pair(n: usize, material: &str) -> (Scene, Scene) {
    let placements = octahedra_placements(n);
    (
        load_json("shared", &octahedra_gltf(&placements, false, material)),
        load_json("flat", &octahedra_gltf(&placements, true, material)),
    )
}

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).abs().max_element() <= tol * (1.0 + a.abs().max_element())
}

#[test]
fn nodes_sharing_a_mesh_store_one_copy_and_show_the_flattened_triangles() {
    let n = 7;
    let (shared, flat) = pair(n, "{}");
    // One copy of the octahedron's 8 triangles and 6 vertices.
    assert_eq!(shared.triangles.len(), 8);
    assert_eq!(shared.positions.len(), 6);
    assert_eq!(shared.instances.len(), n);
    assert!(shared.is_instanced());
    assert_eq!(shared.virtual_triangle_count(), 8 * n);
    assert_eq!(shared.stats.instanced_placements, n);
    // The flattened file: a copy per node, one identity instance.
    assert_eq!(flat.triangles.len(), 8 * n);
    assert!(!flat.is_instanced());
    assert_eq!(flat.virtual_triangle_count(), 8 * n);
    // Same world-space vertices in the same order (mirrored instances' winding swapped like
    // the flattening loader's), bit for bit: both transform by the same matrix.
    for v in 0..(8 * n) as u32 {
        assert_eq!(
            shared.world_triangle(v),
            flat.world_triangle(v),
            "triangle {v}"
        );
    }
    // Instances are bounded by their mesh box's transformed corners: a box around the
    // flat one, no more than the octahedron's box transformed (√3 larger at most here).
    let (a, b) = (shared.bounds().unwrap(), flat.bounds().unwrap());
    assert!(
        a.0.cmple(b.0).all() && a.1.cmpge(b.1).all(),
        "{a:?} vs {b:?}"
    );
    assert!(
        (a.1 - a.0).length() < 1.2 * (b.1 - b.0).length(),
        "{a:?} vs {b:?}"
    );
}

#[test]
fn surface_hits_of_instances_match_the_flattened_scene() {
    let n = 6;
    let (shared, flat) = pair(n, "{}");
    let placements = octahedra_placements(n);
    for v in 0..(8 * n) as u32 {
        let inst = v as usize / 8;
        let mirrored = Mat4::from_cols_array(&placements[inst]).determinant() < 0.0;
        for &(b1, b2) in &[(0.2f32, 0.3f32), (0.6, 0.1), (0.05, 0.9)] {
            let [q0, q1, q2] = shared.world_triangle(v);
            let target = q0 * (1.0 - b1 - b2) + q1 * b1 + q2 * b2;
            let ray = Ray::new(
                target + Vec3::new(0.3, 5.0, 0.7),
                -Vec3::new(0.3, 5.0, 0.7).normalize(),
                f32::INFINITY,
            );
            // Intersectors report barycentrics of the stored vertices: a mirrored
            // instance's stored order has vertices 1 and 2 swapped against the flat copy.
            let (s1, s2) = if mirrored { (b2, b1) } else { (b1, b2) };
            let a = shared.surface_hit(&ray, 1.0, v, s1, s2);
            let b = flat.surface_hit(&ray, 1.0, v, b1, b2);
            assert!(close(a.p, b.p, 1e-6), "{v}: p {} vs {}", a.p, b.p);
            assert!(close(a.p, target, 1e-6), "{v}: p {} vs {target}", a.p);
            assert!(close(a.ng, b.ng, 1e-6), "{v}: ng {} vs {}", a.ng, b.ng);
            assert!(close(a.ns, b.ns, 1e-5), "{v}: ns {} vs {}", a.ns, b.ns);
            assert!((a.uv - b.uv).abs().max_element() < 1e-6, "{v}: uv");
            assert_eq!(
                (a.prim, a.material, a.emitter),
                (b.prim, b.material, b.emitter)
            );
            // The instance's bound adds the transforms' rounding to the flat one.
            assert!(
                a.p_error.cmpge(b.p_error).all(),
                "{v}: {} vs {}",
                a.p_error,
                b.p_error
            );
            assert!(a.p_error.max_element() < 1e-4 * (1.0 + a.p.abs().max_element()));
        }
    }
}

#[test]
fn mirrored_instances_keep_their_normals_pointing_out() {
    let n = 9;
    let (shared, _) = pair(n, "{}");
    let placements = octahedra_placements(n);
    let mut mirrored = 0;
    for (i, m) in placements.iter().enumerate() {
        let m = Mat4::from_cols_array(m);
        mirrored += (m.determinant() < 0.0) as usize;
        let centre = m.transform_point3(Vec3::ZERO);
        for k in 0..8u32 {
            let v = (8 * i) as u32 + k;
            let [p0, p1, p2] = shared.world_triangle(v);
            let c = (p0 + p1 + p2) / 3.0;
            let ray = Ray::new(
                c + (c - centre) * 4.0,
                (centre - c).normalize(),
                f32::INFINITY,
            );
            let h = shared.surface_hit(&ray, 1.0, v, 1.0 / 3.0, 1.0 / 3.0);
            // The octahedron is convex around its centre: the front face looks outwards.
            assert!(
                h.ng.dot(c - centre) > 0.0,
                "instance {i} tri {k}: ng {}",
                h.ng
            );
            // The interpolated normal at the centroid: the mean of the three vertex normals
            // (the local corners' directions) each taken by the inverse transpose and
            // normalised.
            let nm = glam::Mat3::from_mat4(m).inverse().transpose();
            let want = [p0, p1, p2]
                .map(|p| (nm * m.inverse().transform_point3(p).round()).normalize())
                .iter()
                .sum::<Vec3>()
                .normalize();
            assert!(
                close(h.ns, want, 1e-5),
                "instance {i} tri {k}: ns {} vs {want}",
                h.ns
            );
            assert!(h.ns.dot(h.ng) > 0.0);
        }
    }
    assert_eq!(mirrored, 3);
}

#[test]
fn each_instance_of_an_emissive_mesh_is_its_own_light() {
    let n = 5;
    let emissive = r#"{"emissiveFactor": [1.0, 0.5, 0.25]}"#;
    let (shared, flat) = pair(n, emissive);
    assert_eq!(shared.triangles.len(), 8);
    assert_eq!(shared.emitters.len(), 8 * n);
    assert_eq!(flat.emitters.len(), 8 * n);
    for (k, (a, b)) in shared.emitters.iter().zip(&flat.emitters).enumerate() {
        assert_eq!(a.prim, b.prim, "emitter {k}");
        assert_eq!([a.p0, a.p1, a.p2], [b.p0, b.p1, b.p2], "emitter {k}");
        assert!(close(a.n, b.n, 1e-6), "emitter {k}");
        assert!((a.area - b.area).abs() <= 1e-6 * b.area, "emitter {k}");
        assert!((a.radiance.g - 0.5).abs() < 1e-6);
        // A hit on the emitter's virtual triangle names it.
        let c = (a.p0 + a.p1 + a.p2) / 3.0;
        let ray = Ray::new(c + a.n, -a.n, f32::INFINITY);
        let h = shared.surface_hit(&ray, 1.0, a.prim, 1.0 / 3.0, 1.0 / 3.0);
        assert_eq!(h.emitter, k as i32, "emitter {k}");
    }
    // Instances differ in size, so their lights' powers do: the CDF is the flat one.
    assert_eq!(shared.emitter_power_cdf.len(), flat.emitter_power_cdf.len());
    for (a, b) in shared.emitter_power_cdf.iter().zip(&flat.emitter_power_cdf) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    let first = shared.emitters[0].area;
    assert!(shared
        .emitters
        .iter()
        .any(|e| (e.area - first).abs() > 0.1 * first));
}

#[test]
fn gpu_instancing_stores_one_copy_for_27_instances() {
    let t: Vec<[f32; 3]> = (0..27)
        .map(|i| {
            [
                3.0 * (i % 3) as f32,
                3.0 * (i / 3 % 3) as f32,
                3.0 * (i / 9) as f32,
            ]
        })
        .collect();
    let s: Vec<[f32; 3]> = (0..27).map(|i| [1.0, 1.0 + 0.01 * i as f32, 1.0]).collect();
    let scene = load_json("ext27", &octahedra_ext_gltf(&t, &s, "{}"));
    assert_eq!(scene.triangles.len(), 8);
    assert_eq!(scene.instances.len(), 27);
    assert_eq!(scene.virtual_triangle_count(), 27 * 8);
    for (i, ti) in t.iter().enumerate() {
        let [p0, ..] = scene.world_triangle(8 * i as u32);
        // Triangle 0's vertex 0 is the local (1, 0, 0).
        assert!(
            close(p0, Vec3::from_array(*ti) + Vec3::X, 1e-6),
            "{i}: {p0}"
        );
    }
}

#[test]
fn instanced_triangles_beyond_32_bit_ids_are_refused_naming_the_file_and_counts() {
    // 2^16 placements of a mesh of 2^16 + 1 triangles: 2^32 + 2^16 virtual triangles.
    // Only the accessors' counts are read before the refusal.
    let placements = 1usize << 16;
    let tris = (1usize << 16) + 1;
    let dir = temp_dir("limit");
    let mut bin: Vec<u8> = Vec::new();
    for i in 0..placements {
        for v in [i as f32 * 2.0, 0.0, 0.0] {
            bin.extend(v.to_le_bytes());
        }
    }
    let pos_off = bin.len();
    bin.resize(pos_off + tris * 3 * 12, 0);
    std::fs::write(dir.join("big.bin"), &bin).unwrap();
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
  "extensionsUsed": ["EXT_mesh_gpu_instancing"],
  "nodes": [{{"mesh": 0, "extensions": {{"EXT_mesh_gpu_instancing": {{"attributes": {{"TRANSLATION": 0}}}}}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 1}}}}]}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {placements}, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5126, "count": {}, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0]}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pos_off}}},
    {{"buffer": 0, "byteOffset": {pos_off}, "byteLength": {}}}],
  "buffers": [{{"uri": "big.bin", "byteLength": {}}}]}}"#,
        tris * 3,
        tris * 36,
        bin.len()
    );
    let p = dir.join("big.gltf");
    std::fs::write(&p, json).unwrap();
    let e = load_gltf(&p, &BTreeMap::new()).unwrap_err().to_string();
    assert!(e.contains("big.gltf"), "{e}");
    assert!(e.contains("65536 mesh instances"), "{e}");
    assert!(e.contains(&((placements * tris) as u64).to_string()), "{e}");
    assert!(e.contains(&(u32::MAX as u64 - 1).to_string()), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
}

/// Every mesh placement is one object (the AOVs' `object_id`), whether the mesh is stored
/// once per node (flattened) or once for all of them (instanced): triangle v of n octahedra
/// of 8 triangles is on object v / 8 in both.
#[test]
fn each_placement_is_one_object_flattened_or_instanced() {
    let n = 5;
    let (shared, flat) = pair(n, "{}");
    for scene in [&shared, &flat] {
        assert_eq!(scene.object_first_virtual.len(), n);
        for v in 0..(8 * n) as u32 {
            assert_eq!(scene.object_of(v), v / 8, "triangle {v}");
        }
    }
    assert_eq!(
        Scene::default().object_of(3),
        0,
        "a scene built by hand is one object"
    );
}
