//! Builders of small glTF files for tests (this crate's and the host's): a unit quad with
//! chosen vertex attributes, images and material.
#![doc(hidden)]

use std::path::{Path, PathBuf};

/// Standard base64 with padding.
pub fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= c.len() {
                out.push(T[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// PNG bytes of an 8-bit image with `channels` (1–4) channels.
pub fn png8(width: u32, height: u32, channels: u32, texels: &[u8]) -> Vec<u8> {
    let ct = match channels {
        1 => image::ExtendedColorType::L8,
        2 => image::ExtendedColorType::La8,
        3 => image::ExtendedColorType::Rgb8,
        _ => image::ExtendedColorType::Rgba8,
    };
    let mut out = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut out),
        texels,
        width,
        height,
        ct,
    )
    .expect("PNG encoding");
    out
}

/// A vertex attribute of the quad: glTF semantic, accessor type, component type, normalized,
/// and the raw little-endian bytes for the 4 vertices.
pub struct Attribute {
    pub semantic: String,
    pub ty: &'static str,
    pub component_type: u32,
    pub normalized: bool,
    pub bytes: Vec<u8>,
}

impl Attribute {
    /// An f32 attribute with `N` components per vertex.
    pub fn floats<const N: usize>(semantic: &str, values: [[f32; N]; 4]) -> Attribute {
        let ty = match N {
            2 => "VEC2",
            3 => "VEC3",
            4 => "VEC4",
            _ => "SCALAR",
        };
        Attribute {
            semantic: semantic.into(),
            ty,
            component_type: 5126,
            normalized: false,
            bytes: values
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
        }
    }
}

/// The unit quad (0,0,0)–(1,1,0) facing +z, two triangles (0,1,2), (0,2,3), with NORMAL +z
/// and TEXCOORD_0 = (x, 1 − y) (the image's top row at the quad's top edge), plus `extra`
/// attributes, `images` (PNG bytes, embedded as data URIs), `textures` and `samplers` JSON
/// arrays (without brackets), one `material` (JSON object), and `extensions_used`.
pub struct Quad {
    pub extra: Vec<Attribute>,
    pub images: Vec<Vec<u8>>,
    pub textures: String,
    pub samplers: String,
    pub material: String,
    pub extensions_used: String,
    pub no_normals: bool,
    /// A second node instancing the quad at this translation.
    pub second_node: Option<[f32; 3]>,
}

impl Default for Quad {
    fn default() -> Self {
        Quad {
            extra: Vec::new(),
            images: Vec::new(),
            textures: String::new(),
            samplers: String::new(),
            material: "{}".into(),
            extensions_used: String::new(),
            no_normals: false,
            second_node: None,
        }
    }
}

pub const QUAD_POSITIONS: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];

impl Quad {
    pub fn json(&self) -> String {
        let mut attrs = vec![Attribute::floats("POSITION", QUAD_POSITIONS)];
        if !self.no_normals {
            attrs.push(Attribute::floats("NORMAL", [[0.0, 0.0, 1.0]; 4]));
        }
        attrs.push(Attribute::floats(
            "TEXCOORD_0",
            QUAD_POSITIONS.map(|p| [p[0], 1.0 - p[1]]),
        ));
        let mut bytes: Vec<u8> = [0u32, 1, 2, 0, 2, 3]
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let mut views = vec![r#"{"buffer": 0, "byteOffset": 0, "byteLength": 24}"#.to_string()];
        let mut accessors = vec![
            r#"{"bufferView": 0, "componentType": 5125, "count": 6, "type": "SCALAR"}"#.to_string(),
        ];
        let mut attr_json = Vec::new();
        for a in attrs.iter().chain(&self.extra) {
            while !bytes.len().is_multiple_of(4) {
                bytes.push(0);
            }
            let off = bytes.len();
            bytes.extend_from_slice(&a.bytes);
            views.push(format!(
                r#"{{"buffer": 0, "byteOffset": {off}, "byteLength": {}}}"#,
                a.bytes.len()
            ));
            let i = accessors.len();
            let mut acc = format!(
                r#"{{"bufferView": {i}, "componentType": {}, "count": 4, "type": "{}", "normalized": {}"#,
                a.component_type, a.ty, a.normalized
            );
            if a.semantic == "POSITION" {
                acc.push_str(r#", "min": [0, 0, 0], "max": [1, 1, 0]"#);
            }
            acc.push('}');
            accessors.push(acc);
            attr_json.push(format!(r#""{}": {i}"#, a.semantic));
        }
        let images: Vec<String> = self
            .images
            .iter()
            .map(|png| format!(r#"{{"uri": "data:image/png;base64,{}"}}"#, base64(png)))
            .collect();
        let opt = |key: &str, body: &str| {
            if body.is_empty() {
                String::new()
            } else {
                format!(r#", "{key}": [{body}]"#)
            }
        };
        let (scene_nodes, nodes) = match self.second_node {
            None => ("0".to_string(), r#"{"mesh": 0}"#.to_string()),
            Some([x, y, z]) => (
                "0, 1".to_string(),
                format!(r#"{{"mesh": 0}}, {{"mesh": 0, "translation": [{x}, {y}, {z}]}}"#),
            ),
        };
        format!(
            r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [{scene_nodes}]}}],
  "nodes": [{nodes}],
  "meshes": [{{"primitives": [{{"attributes": {{{attrs}}}, "indices": 0, "material": 0}}]}}],
  "materials": [{material}],
  "accessors": [{accessors}],
  "bufferViews": [{views}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {len}}}]{images}{textures}{samplers}{ext}}}"#,
            attrs = attr_json.join(", "),
            material = self.material,
            accessors = accessors.join(", "),
            views = views.join(", "),
            b64 = base64(&bytes),
            len = bytes.len(),
            images = opt("images", &images.join(", ")),
            textures = opt("textures", &self.textures),
            samplers = opt("samplers", &self.samplers),
            ext = opt("extensionsUsed", &self.extensions_used),
        )
    }

    /// Writes the file `name` into `dir` and returns its path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, self.json()).expect("writing the test glTF");
        p
    }
}

/// A fresh temporary directory for one test.
pub fn temp_dir(tag: &str) -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "flowlight-testutil-{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("creating a temporary directory");
    d
}

/// A glTF with one mesh — an octahedron of radius 1 around the origin (8 triangles, smooth
/// NORMALs pointing out, TEXCOORD_0 from the position) with material `material` — placed
/// by one node per matrix of `placements` (column-major, as glTF's `matrix`). With
/// `flatten`, every node gets its own `meshes` entry (over the same accessors), so the
/// loader stores a copy per node: the same scene without instancing, triangle for triangle
/// in the same order.
pub fn octahedra_gltf(placements: &[[f32; 16]], flatten: bool, material: &str) -> String {
    let nodes: Vec<String> = placements
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let m: Vec<String> = m.iter().map(|v| format!("{v:?}")).collect();
            format!(
                r#"{{"mesh": {}, "matrix": [{}]}}"#,
                if flatten { i } else { 0 },
                m.join(", ")
            )
        })
        .collect();
    octahedra_doc(
        &nodes,
        if flatten { placements.len() } else { 1 },
        material,
        &[],
        "",
    )
}

/// [`octahedra_gltf`]'s octahedron placed by one node with `EXT_mesh_gpu_instancing`:
/// instance i at `translations[i]`, scaled by `scales[i]`.
pub fn octahedra_ext_gltf(
    translations: &[[f32; 3]],
    scales: &[[f32; 3]],
    material: &str,
) -> String {
    assert_eq!(translations.len(), scales.len());
    let node = r#"{"mesh": 0, "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 4, "SCALE": 5}}}}"#;
    octahedra_doc(
        &[node.to_string()],
        1,
        material,
        &[translations, scales],
        r#", "extensionsUsed": ["EXT_mesh_gpu_instancing"], "extensionsRequired": ["EXT_mesh_gpu_instancing"]"#,
    )
}

fn octahedra_doc(
    nodes: &[String],
    meshes: usize,
    material: &str,
    vec3_accessors: &[&[[f32; 3]]],
    top: &str,
) -> String {
    let pos: [[f32; 3]; 6] = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    // Counter-clockwise seen from outside.
    let idx: [u32; 24] = [
        0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5,
    ];
    let mut bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
    let mut views = vec![format!(
        r#"{{"buffer": 0, "byteOffset": 0, "byteLength": {}}}"#,
        bytes.len()
    )];
    let mut push = |data: Vec<f32>, bytes: &mut Vec<u8>| {
        let off = bytes.len();
        bytes.extend(data.iter().flat_map(|v| v.to_le_bytes()));
        views.push(format!(
            r#"{{"buffer": 0, "byteOffset": {off}, "byteLength": {}}}"#,
            data.len() * 4
        ));
    };
    push(pos.iter().flatten().copied().collect(), &mut bytes);
    push(pos.iter().flatten().copied().collect(), &mut bytes);
    push(
        pos.iter()
            .flat_map(|p| [0.5 + 0.5 * p[0], 0.5 - 0.5 * p[1]])
            .collect(),
        &mut bytes,
    );
    let mut accessors = vec![
        r#"{"bufferView": 0, "componentType": 5125, "count": 24, "type": "SCALAR"}"#.to_string(),
        r#"{"bufferView": 1, "componentType": 5126, "count": 6, "type": "VEC3", "min": [-1, -1, -1], "max": [1, 1, 1]}"#.to_string(),
        r#"{"bufferView": 2, "componentType": 5126, "count": 6, "type": "VEC3"}"#.to_string(),
        r#"{"bufferView": 3, "componentType": 5126, "count": 6, "type": "VEC2"}"#.to_string(),
    ];
    for a in vec3_accessors {
        push(a.iter().flatten().copied().collect(), &mut bytes);
        accessors.push(format!(
            r#"{{"bufferView": {}, "componentType": 5126, "count": {}, "type": "VEC3"}}"#,
            accessors.len(),
            a.len()
        ));
    }
    let mesh = r#"{"primitives": [{"attributes": {"POSITION": 1, "NORMAL": 2, "TEXCOORD_0": 3}, "indices": 0, "material": 0}]}"#;
    let roots: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [{roots}]}}],
  "nodes": [{nodes}],
  "meshes": [{meshes}],
  "materials": [{material}],
  "accessors": [{accessors}],
  "bufferViews": [{views}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {len}}}]{top}}}"#,
        roots = roots.join(", "),
        nodes = nodes.join(", "),
        meshes = vec![mesh; meshes].join(", "),
        accessors = accessors.join(", "),
        views = views.join(", "),
        b64 = base64(&bytes),
        len = bytes.len(),
    )
}

/// Placements for [`octahedra_gltf`]: a row of octahedra along x, rotated, scaled
/// non-uniformly, and every third one mirrored (negative x scale).
pub fn octahedra_placements(n: usize) -> Vec<[f32; 16]> {
    (0..n)
        .map(|i| {
            let f = i as f32;
            let mirror = if i % 3 == 2 { -1.0 } else { 1.0 };
            let m = glam::Mat4::from_scale_rotation_translation(
                glam::Vec3::new(mirror * (0.6 + 0.1 * f), 0.5 + 0.05 * f, 0.8),
                glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3 * f, 0.7 + 0.2 * f, -0.4 * f),
                glam::Vec3::new(3.0 * f, 0.25 * f, -0.5 * f),
            );
            m.to_cols_array()
        })
        .collect()
}
