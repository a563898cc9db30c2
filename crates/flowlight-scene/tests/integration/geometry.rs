//! Geometry, compression and instancing: KHR_mesh_quantization, EXT_meshopt_compression,
//! KHR_draco_mesh_compression, the extension table, EXT_mesh_gpu_instancing.

use crate::common;

use common::*;
use flowlight_core::geometry::Ray;
use flowlight_scene::source::GltfSource;
use flowlight_scene::{load_gltf, Scene, SceneError};
use flowlight_testkit::gltf::InTempDir;
use glam::{Vec2, Vec3};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Builds a one-buffer glTF whose binary data is a base64 data URI.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
    /// Extra top-level JSON members, e.g. `"extensionsUsed": [...]`.
    top: Vec<String>,
    /// Extra buffers after buffer 0 (JSON objects).
    buffers: Vec<String>,
}

impl Builder {
    /// Appends `bytes` (4-aligned) as a buffer view; `extra` is spliced into the view object.
    fn view(&mut self, bytes: &[u8], extra: &str) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let off = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(format!(
            r#"{{"buffer": 0, "byteOffset": {off}, "byteLength": {}{extra}}}"#,
            bytes.len()
        ));
        self.views.len() - 1
    }

    /// Appends raw bytes to buffer 0 (4-aligned) without a view; returns the offset.
    fn raw(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let off = self.bin.len();
        self.bin.extend_from_slice(bytes);
        off
    }

    /// A view object given verbatim.
    fn view_json(&mut self, json: String) -> usize {
        self.views.push(json);
        self.views.len() - 1
    }

    fn accessor(&mut self, json: String) -> usize {
        self.accessors.push(json);
        self.accessors.len() - 1
    }

    /// The document with `nodes`, `meshes` (JSON array bodies) and scene 0 listing `roots`.
    fn json(&self, nodes: &str, meshes: &str, roots: &str) -> String {
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut buffers = vec![format!(
            r#"{{"uri": "data:application/octet-stream;base64,{}", "byteLength": {}}}"#,
            base64(&bin),
            bin.len()
        )];
        buffers.extend(self.buffers.iter().cloned());
        let mut top = String::new();
        for t in &self.top {
            top.push_str(t);
            top.push_str(",\n");
        }
        format!(
            r#"{{
  {top}"asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [{roots}]}}],
  "nodes": [{nodes}],
  "meshes": [{meshes}],
  "accessors": [{}],
  "bufferViews": [{}],
  "buffers": [{}]
}}"#,
            self.accessors.join(",\n"),
            self.views.join(",\n"),
            buffers.join(",\n")
        )
    }
}

/// The glTF `json` written into a test's temporary directory, which goes with the result.
fn write(tag: &str, json: &str) -> InTempDir<PathBuf> {
    let dir = temp_dir(tag);
    let value = dir.join("scene.gltf");
    std::fs::write(&value, json).unwrap();
    InTempDir { dir, value }
}

fn load(p: &Path) -> Result<Scene, SceneError> {
    load_gltf(p, &BTreeMap::new())
}

fn le<T: Copy, const N: usize>(v: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    v.iter().flat_map(|&x| f(x)).collect()
}

const QUANT: &str = r#""extensionsUsed": ["KHR_mesh_quantization"], "extensionsRequired": ["KHR_mesh_quantization"]"#;

// ---------------------------------------------------------------------------------------------
// KHR_mesh_quantization

/// The spec's normalisation (glTF 2.0 §3.11, "Animations" table, also used by accessors):
/// signed: max(c / (2^(b-1) - 1), -1); unsigned: c / (2^b - 1).
fn snorm16(c: i16) -> f32 {
    (c as f32 / 32767.0).max(-1.0)
}
fn snorm8(c: i8) -> f32 {
    (c as f32 / 127.0).max(-1.0)
}
fn unorm16(c: u16) -> f32 {
    c as f32 / 65535.0
}

#[test]
fn quantized_normalized_short_positions_byte_normals_ushort_uvs() {
    // Four vertices of a quad, i16 normalized positions (padded to 8 bytes per vertex as
    // the spec requires 4-byte alignment of each element), i8 normalized normals (padded to
    // 4), u16 normalized texcoords.
    let pos: [[i16; 3]; 4] = [
        [-32768, -32767, 0],
        [32767, -32767, 0],
        [32767, 16384, 100],
        [-16384, 16384, 100],
    ];
    let nrm: [[i8; 3]; 4] = [[0, 0, 127], [0, -127, 127], [-128, 0, 127], [0, 0, 127]];
    let uv: [[u16; 2]; 4] = [[0, 0], [65535, 0], [65535, 32768], [1, 65535]];
    let mut b = Builder::default();
    let mut pb = Vec::new();
    for p in pos {
        for c in p {
            pb.extend_from_slice(&c.to_le_bytes());
        }
        pb.extend_from_slice(&[0, 0]);
    }
    let mut nb = Vec::new();
    for n in nrm {
        nb.extend(n.map(|c| c as u8));
        nb.push(0);
    }
    let ub = le(&uv.concat(), u16::to_le_bytes);
    let ib = le(&[0u32, 1, 2, 0, 2, 3], u32::to_le_bytes);
    let pv = b.view(&pb, r#", "byteStride": 8"#);
    let nv = b.view(&nb, r#", "byteStride": 4"#);
    let uvv = b.view(&ub, "");
    let iv = b.view(&ib, "");
    b.accessor(format!(
        r#"{{"bufferView": {pv}, "componentType": 5122, "normalized": true, "count": 4, "type": "VEC3", "min": [-32768, -32767, 0], "max": [32767, 16384, 100]}}"#
    ));
    b.accessor(format!(
        r#"{{"bufferView": {nv}, "componentType": 5120, "normalized": true, "count": 4, "type": "VEC3"}}"#
    ));
    b.accessor(format!(
        r#"{{"bufferView": {uvv}, "componentType": 5123, "normalized": true, "count": 4, "type": "VEC2"}}"#
    ));
    b.accessor(format!(
        r#"{{"bufferView": {iv}, "componentType": 5125, "count": 6, "type": "SCALAR"}}"#
    ));
    b.top.push(QUANT.into());
    // The dequantisation transform gltfpack writes: a node scale and translation.
    let json = b.json(
        r#"{"mesh": 0, "scale": [2, 2, 2], "translation": [1, 0, 0]}"#,
        r#"{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3}]}"#,
        "0",
    );
    let s = load(&write("quant", &json)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.positions.len(), 4);
    for (i, p) in pos.iter().enumerate() {
        let want = Vec3::new(snorm16(p[0]), snorm16(p[1]), snorm16(p[2])) * 2.0 + Vec3::X;
        assert!(
            (s.positions[i] - want).abs().max_element() < 1e-6,
            "vertex {i}: {} vs {want}",
            s.positions[i]
        );
    }
    // -32768 clamps to exactly -1, not -1.00003.
    assert_eq!(s.positions[0].x, -2.0 + 1.0);
    for (i, n) in nrm.iter().enumerate() {
        let want = Vec3::new(snorm8(n[0]), snorm8(n[1]), snorm8(n[2])).normalize();
        assert!(
            (s.normals[i] - want).abs().max_element() < 1e-6,
            "normal {i}: {} vs {want}",
            s.normals[i]
        );
    }
    for (i, t) in uv.iter().enumerate() {
        let want = Vec2::new(unorm16(t[0]), unorm16(t[1]));
        assert!((s.uvs[i] - want).abs().max_element() < 1e-7, "uv {i}");
    }
    assert_eq!(s.triangles.len(), 2);
}

#[test]
fn quantized_unnormalized_byte_positions_are_plain_integers() {
    let pos: [[u8; 3]; 3] = [[0, 0, 7], [200, 0, 7], [0, 255, 7]];
    let mut b = Builder::default();
    let mut pb = Vec::new();
    for p in pos {
        pb.extend_from_slice(&p);
        pb.push(0);
    }
    let pv = b.view(&pb, r#", "byteStride": 4"#);
    b.accessor(format!(
        r#"{{"bufferView": {pv}, "componentType": 5121, "count": 3, "type": "VEC3", "min": [0, 0, 7], "max": [200, 255, 7]}}"#
    ));
    b.top.push(QUANT.into());
    let json = b.json(
        r#"{"mesh": 0}"#,
        r#"{"primitives": [{"attributes": {"POSITION": 0}}]}"#,
        "0",
    );
    let s = load(&write("quant-u8", &json)).unwrap_or_else(|e| panic!("{e}"));
    let got: Vec<Vec3> = s.triangles[0]
        .iter()
        .map(|&i| s.positions[i as usize])
        .collect();
    assert_eq!(
        got,
        vec![
            Vec3::new(0.0, 0.0, 7.0),
            Vec3::new(200.0, 0.0, 7.0),
            Vec3::new(0.0, 255.0, 7.0)
        ]
    );
}

// ---------------------------------------------------------------------------------------------
// Extension table

fn triangle_builder() -> Builder {
    let mut b = Builder::default();
    let pv = b.view(
        &mesh_bytes(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[]),
        "",
    );
    b.accessor(format!(
        r#"{{"bufferView": {pv}, "componentType": 5126, "count": 3, "type": "VEC3"}}"#
    ));
    b
}

fn one_mesh(b: &Builder) -> String {
    b.json(
        r#"{"mesh": 0}"#,
        r#"{"primitives": [{"attributes": {"POSITION": 0}}]}"#,
        "0",
    )
}

#[test]
fn unknown_optional_extensions_warn_once_each_required_ones_fail_naming_them() {
    let mut b = triangle_builder();
    b.top.push(
        r#""extensionsUsed": ["EXT_made_up_a", "KHR_mesh_quantization", "EXT_made_up_b"]"#.into(),
    );
    let p = write("ext-used", &one_mesh(&b));
    let src = GltfSource::open(&p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(src.warnings.len(), 2, "{:?}", src.warnings);
    assert!(src.warnings[0].contains("EXT_made_up_a"));
    assert!(src.warnings[1].contains("EXT_made_up_b"));
    load(&p).unwrap_or_else(|e| panic!("{e}"));

    let mut b = triangle_builder();
    b.top.push(
        r#""extensionsUsed": ["EXT_made_up_a"], "extensionsRequired": ["EXT_made_up_a"]"#.into(),
    );
    let e = load(&write("ext-req", &one_mesh(&b)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("EXT_made_up_a") && e.contains("extensionsRequired") && e.contains("scene.gltf"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
}

// ---------------------------------------------------------------------------------------------
// EXT_meshopt_compression

/// A 5 × 5 grid on a bumpy surface with analytic normals; indices of its 32 triangles.
fn grid() -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<u32>) {
    let (mut p, mut n, mut idx) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..5 {
        for i in 0..5 {
            let (x, y) = (i as f32 * 0.25 - 0.5, j as f32 * 0.25 - 0.5);
            let z = 0.3 * (3.0 * x).sin() * (2.0 * y).cos();
            p.push([x, y, z]);
            let g = Vec3::new(
                -0.9 * (3.0 * x).cos() * (2.0 * y).cos(),
                0.6 * (3.0 * x).sin() * (2.0 * y).sin(),
                1.0,
            )
            .normalize();
            n.push(g.to_array());
        }
    }
    for j in 0..4u32 {
        for i in 0..4u32 {
            let a = j * 5 + i;
            idx.extend_from_slice(&[a, a + 1, a + 6, a, a + 6, a + 5]);
        }
    }
    (p, n, idx)
}

#[test]
fn meshopt_attributes_triangles_indices_and_filters_decode_to_the_source_mesh() {
    let (pos, nrm, idx) = grid();
    let mut b = Builder::default();
    // Buffer 1 is the fallback: no data at all; every view's `buffer` names it.
    let mut fallback_len = 0usize;
    let mut compressed_view = |b: &mut Builder,
                               enc: &[u8],
                               stride: usize,
                               count: usize,
                               mode: &str,
                               filter: &str,
                               target: bool| {
        let off = b.raw(enc);
        let len = stride * count;
        let v = b.view_json(format!(
            r#"{{"buffer": 1, "byteOffset": {fallback_len}, "byteLength": {len}{}{}, "extensions": {{"EXT_meshopt_compression": {{"buffer": 0, "byteOffset": {off}, "byteLength": {}, "byteStride": {stride}, "count": {count}, "mode": "{mode}"{filter}}}}}}}"#,
            if mode == "ATTRIBUTES" { format!(r#", "byteStride": {stride}"#) } else { String::new() },
            if target { r#", "target": 34962"# } else { "" },
            enc.len()
        ));
        fallback_len += len.next_multiple_of(4);
        v
    };
    // Primitive 0: plain f32 positions, octahedral 16-bit normals, TRIANGLES u32 indices.
    let p0 = compressed_view(
        &mut b,
        &meshopt::encode_vertex_buffer(&pos).unwrap(),
        12,
        25,
        "ATTRIBUTES",
        "",
        true,
    );
    let oct: Vec<[f32; 4]> = nrm.iter().map(|n| [n[0], n[1], n[2], 0.0]).collect();
    let oct = meshopt::encode_filter_oct::<i16>(&oct, 16);
    let n0 = compressed_view(
        &mut b,
        &meshopt::encode_vertex_buffer(&oct).unwrap(),
        8,
        25,
        "ATTRIBUTES",
        r#", "filter": "OCTAHEDRAL""#,
        true,
    );
    let i0 = compressed_view(
        &mut b,
        &meshopt::encode_index_buffer(&idx, 25).unwrap(),
        4,
        idx.len(),
        "TRIANGLES",
        "",
        false,
    );
    // Primitive 1: exponential-filtered positions, INDICES u16 indices.
    let exp = meshopt::encode_filter_exp(&pos, 20, meshopt::EncodeExpMode::SharedVector);
    let p1 = compressed_view(
        &mut b,
        &meshopt::encode_vertex_buffer(&exp).unwrap(),
        12,
        25,
        "ATTRIBUTES",
        r#", "filter": "EXPONENTIAL""#,
        true,
    );
    let i1 = compressed_view(
        &mut b,
        &meshopt::encode_index_sequence(&idx, 25).unwrap(),
        2,
        idx.len(),
        "INDICES",
        "",
        false,
    );
    b.buffers.push(format!(
        r#"{{"byteLength": {fallback_len}, "extensions": {{"EXT_meshopt_compression": {{"fallback": true}}}}}}"#
    ));
    let vec3 = |v: usize, ty: u32, norm: bool| {
        format!(
            r#"{{"bufferView": {v}, "componentType": {ty}, "normalized": {norm}, "count": 25, "type": "VEC3"}}"#
        )
    };
    let ap0 = b.accessor(vec3(p0, 5126, false));
    let an0 = b.accessor(vec3(n0, 5122, true));
    let ai0 = b.accessor(format!(
        r#"{{"bufferView": {i0}, "componentType": 5125, "count": {}, "type": "SCALAR"}}"#,
        idx.len()
    ));
    let ap1 = b.accessor(vec3(p1, 5126, false));
    let ai1 = b.accessor(format!(
        r#"{{"bufferView": {i1}, "componentType": 5123, "count": {}, "type": "SCALAR"}}"#,
        idx.len()
    ));
    b.top.push(
        r#""extensionsUsed": ["EXT_meshopt_compression", "KHR_mesh_quantization"], "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"]"#
            .into(),
    );
    let json = b.json(
        r#"{"mesh": 0}"#,
        &format!(
            r#"{{"primitives": [
                {{"attributes": {{"POSITION": {ap0}, "NORMAL": {an0}}}, "indices": {ai0}}},
                {{"attributes": {{"POSITION": {ap1}, "NORMAL": {an0}}}, "indices": {ai1}}}]}}"#
        ),
        "0",
    );
    let s = load(&write("meshopt", &json)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.positions.len(), 50);
    assert_eq!(s.triangles.len(), 64);
    for k in 0..25 {
        assert_eq!(s.positions[k], Vec3::from_array(pos[k]), "plain vertex {k}");
        // 20-bit mantissas with a shared exponent: relative error below 2^-19 of the largest
        // component.
        let d = (s.positions[25 + k] - Vec3::from_array(pos[k]))
            .abs()
            .max_element();
        assert!(d < 2e-6, "exponential vertex {k}: off by {d}");
        // 16-bit octahedral normals: within 1e-4 rad.
        let want = Vec3::from_array(nrm[k]);
        for base in [0, 25] {
            let got = s.normals[base + k];
            assert!(
                got.angle_between(want) < 1e-3,
                "normal {k}: {got} vs {want}"
            );
        }
    }
    // Triangle connectivity: the index codec may rotate a triangle's corners (it keeps the
    // winding), so compare each triangle as a rotation of the source one.
    for prim in 0..2 {
        for (t, want) in idx.chunks_exact(3).enumerate() {
            let got = s.triangles[prim * 32 + t].map(|i| i - 25 * prim as u32);
            let rotations = [
                [want[0], want[1], want[2]],
                [want[1], want[2], want[0]],
                [want[2], want[0], want[1]],
            ];
            assert!(
                rotations.contains(&got),
                "primitive {prim} triangle {t}: {got:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn meshopt_bad_stream_is_an_error_naming_the_view() {
    let (pos, _, _) = grid();
    let mut b = Builder::default();
    let mut enc = meshopt::encode_vertex_buffer(&pos).unwrap();
    enc.truncate(enc.len() / 2);
    let off = b.raw(&enc);
    let v = b.view_json(format!(
        r#"{{"buffer": 1, "byteLength": 300, "byteStride": 12, "extensions": {{"EXT_meshopt_compression": {{"buffer": 0, "byteOffset": {off}, "byteLength": {}, "byteStride": 12, "count": 25, "mode": "ATTRIBUTES"}}}}}}"#,
        enc.len()
    ));
    b.buffers.push(r#"{"byteLength": 300}"#.into());
    b.accessor(format!(
        r#"{{"bufferView": {v}, "componentType": 5126, "count": 25, "type": "VEC3"}}"#
    ));
    b.top.push(r#""extensionsUsed": ["EXT_meshopt_compression"], "extensionsRequired": ["EXT_meshopt_compression"]"#.into());
    let e = load(&write("meshopt-bad", &one_mesh(&b)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bufferViews[0].extensions.EXT_meshopt_compression") && e.contains("decode"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// KHR_draco_mesh_compression

fn draco_grid() -> (Vec<u8>, Vec<[f32; 3]>, Vec<u32>, u32, u32) {
    use draco_core::{
        DataType, EncoderBuffer, EncoderOptions, FaceIndex, GeometryAttributeType, Mesh,
        MeshEncoder, PointAttribute,
    };
    let (pos, nrm, idx) = grid();
    let mut mesh = Mesh::new();
    let attr = |ty, data: &[[f32; 3]]| {
        let mut a = PointAttribute::new();
        a.init(ty, 3, DataType::Float32, false, data.len());
        for (i, v) in data.iter().enumerate() {
            for (c, x) in v.iter().enumerate() {
                a.buffer_mut().write((i * 3 + c) * 4, &x.to_le_bytes());
            }
        }
        a
    };
    let pa = attr(GeometryAttributeType::Position, &pos);
    let na = attr(GeometryAttributeType::Normal, &nrm);
    let pid = mesh.add_attribute(pa) as u32;
    let nid = mesh.add_attribute(na) as u32;
    mesh.set_num_faces(idx.len() / 3);
    for (f, t) in idx.chunks_exact(3).enumerate() {
        mesh.set_face(FaceIndex(f as u32), [t[0].into(), t[1].into(), t[2].into()]);
    }
    let mut options = EncoderOptions::new();
    options.set_attribute_int(0, "quantization_bits", 16);
    options.set_attribute_int(1, "quantization_bits", 12);
    let mut encoder = MeshEncoder::new();
    encoder.set_mesh(mesh);
    let mut buffer = EncoderBuffer::new();
    encoder.encode(&options, &mut buffer).unwrap();
    (buffer.data().to_vec(), pos, idx, pid, nid)
}

fn draco_gltf(stream: &[u8], points: usize, indices: usize, pid: u32, nid: u32) -> String {
    let mut b = Builder::default();
    let v = b.view(stream, "");
    b.accessor(format!(
        r#"{{"componentType": 5126, "count": {points}, "type": "VEC3", "min": [-0.5, -0.5, -0.3], "max": [0.5, 0.5, 0.3]}}"#
    ));
    b.accessor(format!(
        r#"{{"componentType": 5126, "count": {points}, "type": "VEC3"}}"#
    ));
    b.accessor(format!(
        r#"{{"componentType": 5125, "count": {indices}, "type": "SCALAR"}}"#
    ));
    b.top.push(r#""extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"]"#.into());
    b.json(
        r#"{"mesh": 0}"#,
        &format!(
            r#"{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2,
                "extensions": {{"KHR_draco_mesh_compression": {{"bufferView": {v}, "attributes": {{"POSITION": {pid}, "NORMAL": {nid}}}}}}}}}]}}"#
        ),
        "0",
    )
}

#[test]
fn draco_primitive_decodes_to_the_source_triangles() {
    let (stream, pos, idx, pid, nid) = draco_grid();
    // Draco renumbers points (EdgeBreaker order): find the decoded point count from the source
    // mesh, which has no duplicated points.
    let json = draco_gltf(&stream, pos.len(), idx.len(), pid, nid);
    let s = load(&write("draco", &json)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.triangles.len(), idx.len() / 3);
    // Every decoded triangle is a source triangle (same corners within the 16-bit
    // quantisation step of a 1-unit box, same winding up to rotation), and all are found.
    let tol = 2.0 / 65535.0;
    let mut found = vec![false; idx.len() / 3];
    for t in &s.triangles {
        let got = t.map(|i| s.positions[i as usize]);
        let hit = idx.chunks_exact(3).position(|w| {
            let want = [0, 1, 2].map(|k| Vec3::from_array(pos[w[k] as usize]));
            (0..3).any(|r| (0..3).all(|k| (got[k] - want[(k + r) % 3]).abs().max_element() < tol))
        });
        let h = hit.unwrap_or_else(|| panic!("decoded triangle {got:?} is not a source triangle"));
        found[h] = true;
    }
    assert!(found.iter().all(|&f| f));
    // Normals come from the stream too (12-bit octahedral): each vertex's normal is the
    // source normal of the source vertex at that position.
    let (_, nrm, _) = grid();
    for (v, p) in s.positions.iter().enumerate() {
        let k = pos
            .iter()
            .position(|q| (Vec3::from_array(*q) - *p).abs().max_element() < tol)
            .unwrap();
        assert!(
            s.normals[v].angle_between(Vec3::from_array(nrm[k])) < 0.01,
            "vertex {v}"
        );
    }
}

#[test]
fn draco_bad_stream_is_an_error_naming_draco_and_the_way_out() {
    let (mut stream, pos, idx, pid, nid) = draco_grid();
    stream.truncate(20);
    let json = draco_gltf(&stream, pos.len(), idx.len(), pid, nid);
    let e = load(&write("draco-bad", &json)).unwrap_err().to_string();
    assert!(
        e.contains("KHR_draco_mesh_compression")
            && e.contains("gltf-transform")
            && e.contains("gltfpack"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1);
}

// ---------------------------------------------------------------------------------------------
// EXT_mesh_gpu_instancing

/// 27 instances of one triangle on a 3 × 3 × 3 lattice: translation 10·(i, j, k), a rotation
/// of (i + j + k) quarter turns about Z stored as normalized shorts, scale 1 + k.
fn instanced_json() -> (String, Vec<[Vec3; 3]>) {
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut b = Builder::default();
    let pv = b.view(&mesh_bytes(&tri, &[]), "");
    b.accessor(format!(
        r#"{{"bufferView": {pv}, "componentType": 5126, "count": 3, "type": "VEC3"}}"#
    ));
    let (mut t, mut r, mut s) = (Vec::new(), Vec::new(), Vec::new());
    let mut want = Vec::new();
    let node_t = Vec3::new(0.5, -2.0, 3.0);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    // Quarter turns about Z as (x, y, z, w): identity, 90°, 180°, 270°.
    let quats: [[f32; 4]; 4] = [
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, h, h],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, h, -h],
    ];
    for k in 0..3 {
        for j in 0..3 {
            for i in 0..3 {
                let tr = Vec3::new(i as f32, j as f32, k as f32) * 10.0;
                let turns = (i + j + k) % 4;
                let sc = 1.0 + k as f32;
                t.push(tr.to_array());
                r.push(quats[turns].map(|c| (c * 32767.0).round() as i16));
                s.push([sc; 3]);
                // By hand: scale, then turn (x, y) → (−y, x) `turns` times, then translate.
                want.push(tri.map(|p| {
                    let mut q = Vec3::from_array(p) * sc;
                    for _ in 0..turns {
                        q = Vec3::new(-q.y, q.x, q.z);
                    }
                    node_t + tr + q
                }));
            }
        }
    }
    let tv = b.view(&le(&t.concat(), f32::to_le_bytes), "");
    let rv = b.view(&le(&r.concat(), i16::to_le_bytes), "");
    let sv = b.view(&le(&s.concat(), f32::to_le_bytes), "");
    let at = b.accessor(format!(
        r#"{{"bufferView": {tv}, "componentType": 5126, "count": 27, "type": "VEC3"}}"#
    ));
    let ar = b.accessor(format!(r#"{{"bufferView": {rv}, "componentType": 5122, "normalized": true, "count": 27, "type": "VEC4"}}"#));
    let asc = b.accessor(format!(
        r#"{{"bufferView": {sv}, "componentType": 5126, "count": 27, "type": "VEC3"}}"#
    ));
    b.top.push(r#""extensionsUsed": ["EXT_mesh_gpu_instancing", "KHR_mesh_quantization"], "extensionsRequired": ["EXT_mesh_gpu_instancing"]"#.into());
    let json = b.json(
        &format!(
            r#"{{"mesh": 0, "translation": [0.5, -2.0, 3.0], "extensions": {{"EXT_mesh_gpu_instancing": {{"attributes": {{"TRANSLATION": {at}, "ROTATION": {ar}, "SCALE": {asc}}}}}}}}}"#
        ),
        r#"{"primitives": [{"attributes": {"POSITION": 0}}]}"#,
        "0",
    );
    (json, want)
}

#[test]
fn gpu_instancing_renders_every_instance_where_the_spec_puts_it() {
    let (json, want) = instanced_json();
    let s = load(&write("instancing", &json)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.stats.mesh_instances, 27);
    // One copy of the mesh's triangle, 27 placements of it.
    assert_eq!(s.triangles.len(), 1);
    assert_eq!(s.positions.len(), 3);
    assert_eq!(s.instances.len(), 27);
    assert_eq!(s.virtual_triangle_count(), 27);
    assert_eq!(s.stats.virtual_triangles, 27);
    for (i, w) in want.iter().enumerate() {
        let got = s.world_triangle(i as u32);
        for c in 0..3 {
            // Rotations are 16-bit normalized: error ≤ 1/32767 per component, times the
            // scaled vertex (≤ 3).
            assert!(
                (got[c] - w[c]).abs().max_element() < 3e-4,
                "instance {i} corner {c}: {} vs {}",
                got[c],
                w[c]
            );
        }
    }
}

#[test]
fn gpu_instancing_with_mismatched_counts_is_an_error_naming_the_node() {
    let (json, _) = instanced_json();
    // Make the SCALE accessor claim 26 instances.
    let json = json.replacen(
        r#""componentType": 5126, "count": 27, "type": "VEC3"}"#,
        r#""componentType": 5126, "count": 26, "type": "VEC3"}"#,
        2,
    );
    let e = load(&write("instancing-bad", &json))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("node 0") && e.contains("EXT_mesh_gpu_instancing") && e.contains("counts"),
        "{e}"
    );
}

// Primitives without NORMAL

/// A primitive without NORMAL is flat shaded with its vertices still shared: the loader
/// stores the grid's 25 vertices once (not 3 per triangle) with zero normals, and a hit's
/// shading normal is its triangle's geometric normal, the face normal the spec asks for.
/// Vertices that no kept triangle uses are not stored.
#[test]
fn flat_primitives_keep_shared_vertices_and_shade_with_the_face_normal() {
    let (mut pos, _, mut idx) = grid();
    // A NaN vertex that only a dropped triangle uses is not stored.
    pos.push([f32::NAN, 0.0, 0.0]);
    idx.extend_from_slice(&[0, 1, 25]);
    let json = embedded_gltf(&pos, &idx, "", "");
    let s = load(&write("flat-shared", &json)).unwrap();
    assert_eq!(s.stats.flat_shaded_primitives, 1);
    assert_eq!(s.stats.dropped_non_finite, 1);
    assert_eq!(s.triangles.len(), 32);
    assert_eq!(
        s.positions.len(),
        25,
        "vertices are not duplicated per triangle"
    );
    assert!(s.positions.iter().all(|p| p.is_finite()));
    // No primitive has NORMAL or TEXCOORD_0: neither is stored (a hit reads neither).
    assert!(s.normals.is_empty());
    assert!(s.uvs.is_empty());
    for prim in 0..32u32 {
        let [p0, p1, p2] = s.world_triangle(prim);
        let face = (p1 - p0).cross(p2 - p0).normalize();
        for &(b1, b2) in &[(0.2f32, 0.3f32), (0.6, 0.1), (0.05, 0.9)] {
            let target = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
            let ray = Ray::new(target + face, -face, f32::INFINITY);
            let h = s.surface_hit(&ray, 1.0, prim, b1, b2);
            assert_eq!(
                h.ns, h.ng,
                "{prim}: the shading normal is the geometric one"
            );
            assert!((h.ng - face).length() < 1e-6, "{prim}: {} vs {face}", h.ng);
            assert!((h.p - target).length() < 1e-6);
        }
    }
}

/// A scene with a flat and a smooth primitive keeps normals for every vertex: zero for the
/// flat one's (its hits take the face normal), the file's for the smooth one's. Without
/// TEXCOORD_0 anywhere, no texture coordinates are stored.
#[test]
fn a_flat_primitive_beside_a_smooth_one_keeps_zero_normals() {
    let (pos, nrm, idx) = grid();
    let mut bytes = mesh_bytes(&pos, &idx);
    let normals_at = bytes.len();
    for n in &nrm {
        for c in n {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    let (np, ni) = (pos.len(), idx.len());
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0}}],
  "meshes": [{{"primitives": [
    {{"attributes": {{"POSITION": 0}}, "indices": 1}},
    {{"attributes": {{"POSITION": 0, "NORMAL": 2}}, "indices": 1}}]}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {np}, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5125, "count": {ni}, "type": "SCALAR"}},
    {{"bufferView": 2, "componentType": 5126, "count": {np}, "type": "VEC3"}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pb}}},
    {{"buffer": 0, "byteOffset": {pb}, "byteLength": {ib}}},
    {{"buffer": 0, "byteOffset": {normals_at}, "byteLength": {pb}}}
  ],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{data}", "byteLength": {total}}}]
}}"#,
        pb = np * 12,
        ib = ni * 4,
        total = bytes.len(),
        data = base64(&bytes),
    );
    let s = load(&write("flat-beside-smooth", &json)).unwrap();
    assert_eq!(s.positions.len(), 2 * np);
    assert_eq!(s.normals.len(), 2 * np);
    assert!(s.normals[..np].iter().all(|&n| n == Vec3::ZERO));
    for (k, n) in nrm.iter().enumerate() {
        let want = Vec3::from_array(*n).normalize();
        assert!((s.normals[np + k] - want).length() < 1e-6, "{k}");
    }
    assert!(s.uvs.is_empty());
}
