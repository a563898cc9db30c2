//! Triangles stored and resident memory of a 27-instance scene, instanced vs flattened.
//!
//! `cargo run --release -p flowlight-host --example instancing_memory -- shared|flat`
//! writes a glTF with 27 placements of one 32,768-triangle sphere (`shared`: one node with
//! `EXT_mesh_gpu_instancing`; `flat`: 27 nodes with a mesh entry each, which the loader
//! stores as 27 copies, as every placement was before instancing), loads it, builds the BVH
//! and the Embree scene, and prints the triangles stored and the growth of the resident set
//! (`/proc/self/statm`) after each step. Run each mode in its own process.

use flowlight_host::intersector::{BvhIntersector, EmbreeIntersector};
use flowlight_testkit::gltf::base64;
use std::collections::BTreeMap;

fn rss() -> u64 {
    let s = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = s
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    pages * 4096
}

/// An octahedron subdivided `levels` times onto the unit sphere: 8 · 4^levels triangles.
fn sphere(levels: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut tris: Vec<[glam::Vec3; 3]> = {
        let (x, y, z) = (glam::Vec3::X, glam::Vec3::Y, glam::Vec3::Z);
        let mut t = Vec::new();
        for sx in [1.0f32, -1.0] {
            for sy in [1.0f32, -1.0] {
                for sz in [1.0f32, -1.0] {
                    let (a, b, c) = (x * sx, y * sy, z * sz);
                    // Counter-clockwise from outside.
                    if sx * sy * sz > 0.0 {
                        t.push([a, b, c]);
                    } else {
                        t.push([a, c, b]);
                    }
                }
            }
        }
        t
    };
    for _ in 0..levels {
        tris = tris
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (
                    (a + b).normalize(),
                    (b + c).normalize(),
                    (c + a).normalize(),
                );
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    let pos = tris.iter().flatten().map(|p| p.to_array()).collect();
    let idx = (0..tris.len() as u32 * 3).collect();
    (pos, idx)
}

fn main() {
    let mode = std::env::args().nth(1).unwrap_or_else(|| "shared".into());
    let (pos, idx) = sphere(6);
    let n = 27usize;
    let mut bin: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
    let p_off = bin.len();
    bin.extend(pos.iter().flatten().flat_map(|v| v.to_le_bytes()));
    let t_off = bin.len();
    let t: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            [
                3.0 * (i % 3) as f32,
                3.0 * (i / 3 % 3) as f32,
                3.0 * (i / 9) as f32,
            ]
        })
        .collect();
    bin.extend(t.iter().flatten().flat_map(|v| v.to_le_bytes()));
    let mesh = r#"{"primitives": [{"attributes": {"POSITION": 1, "NORMAL": 1}, "indices": 0}]}"#;
    let (nodes, meshes, roots) = if mode == "flat" {
        let nodes: Vec<String> = t
            .iter()
            .enumerate()
            .map(|(i, t)| {
                format!(
                    r#"{{"mesh": {i}, "translation": [{}, {}, {}]}}"#,
                    t[0], t[1], t[2]
                )
            })
            .collect();
        let roots: Vec<String> = (0..n).map(|i| i.to_string()).collect();
        (nodes.join(", "), vec![mesh; n].join(", "), roots.join(", "))
    } else {
        (
            r#"{"mesh": 0, "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 2}}}}"#.to_string(),
            mesh.to_string(),
            "0".to_string(),
        )
    };
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [{roots}]}}],
  "extensionsUsed": ["EXT_mesh_gpu_instancing"],
  "nodes": [{nodes}], "meshes": [{meshes}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5125, "count": {ni}, "type": "SCALAR"}},
    {{"bufferView": 1, "componentType": 5126, "count": {np}, "type": "VEC3", "min": [-1, -1, -1], "max": [1, 1, 1]}},
    {{"bufferView": 2, "componentType": 5126, "count": {n}, "type": "VEC3"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {p_off}}},
    {{"buffer": 0, "byteOffset": {p_off}, "byteLength": {pl}}},
    {{"buffer": 0, "byteOffset": {t_off}, "byteLength": {tl}}}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {len}}}]}}"#,
        ni = idx.len(),
        np = pos.len(),
        pl = t_off - p_off,
        tl = bin.len() - t_off,
        b64 = base64(&bin),
        len = bin.len(),
    );
    let dir = std::env::temp_dir().join(format!(
        "flowlight-instancing-memory-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join(format!("{mode}.gltf"));
    std::fs::write(&file, json).unwrap();
    drop(bin);
    let r0 = rss();
    let scene = flowlight_scene::load_gltf(&file, &BTreeMap::new()).unwrap();
    let r1 = rss();
    let (bvh, _) = BvhIntersector::build(&scene);
    let r2 = rss();
    let embree = EmbreeIntersector::build_with(&scene, flowlight_embree::SceneOptions::default());
    let r3 = rss();
    println!(
        "{mode}: {} instances, {} triangles shown, scene stores {} triangles / {} vertices (+{} MiB resident), BVH stores {} (+{} MiB), Embree stores {} (+{} MiB)",
        scene.instances.len(),
        scene.virtual_triangle_count(),
        scene.triangles.len(),
        scene.positions.len(),
        (r1 - r0) >> 20,
        bvh.stored_triangle_count(),
        (r2 - r1) >> 20,
        embree.as_ref().map_or(0, |(e, _)| e.stored_triangle_count()),
        (r3 - r2) >> 20,
    );
    let _ = std::fs::remove_dir_all(&dir);
}
