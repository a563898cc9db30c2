//! The one glTF writer of the tests and of the benchmark scenes: small glTF 2.0 documents with an
//! embedded (base64 data URI) buffer.
//!
//! * [`Document`] is the low level: it packs byte views and accessors into one buffer
//!   (each view 4-byte aligned, as glTF requires for float data) and collects meshes,
//!   nodes, materials, images, textures, samplers, cameras and extensions as JSON.
//! * [`quads_gltf`] is one mesh made of quads with one material (the integration tests'
//!   scenes, e.g. [`emitting_square`]).
//! * [`Quad`] is the unit quad with chosen vertex attributes, images and material (the
//!   loader's texture and attribute tests).
//! * [`SceneBuilder`] is the benchmark scenes' builder: named materials, quads turned to
//!   face a direction, boxes, icospheres with smooth normals, triangle lists, a look-at
//!   camera; the `make-scenes` binary of this crate writes the benchmark scenes
//!   (`scenes.rs`) and the research scenes (`research.rs`) with it.

use serde_json::{json, Map, Value};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Standard base64 with padding.
pub fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
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

/// A fresh empty temporary directory for one test, removed when dropped.
pub fn temp_dir(tag: &str) -> TempDir {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    TempDir::new(&format!(
        "flowlight-testkit-{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}

/// A test's scratch directory under the system's temporary directory: made fresh (emptied if
/// a crashed run left it), used as a [`Path`], and removed with its contents when dropped,
/// unless the test is failing (a panic unwinding through it), so that a failure's files stay
/// to be looked at. Without the removal every run of the test suite left its scenes, images
/// and copied plugins behind (hundreds of megabytes per run).
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl TempDir {
    /// `std::env::temp_dir()/name`, fresh and empty.
    pub fn new(name: &str) -> TempDir {
        let d = std::env::temp_dir().join(name);
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("creating a temporary directory");
        TempDir(d)
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

/// A value that names something inside a [`TempDir`] (a file's path, say), kept together
/// with the directory so that the directory lasts as long as the value is used: it derefs
/// to what the value derefs to (`InTempDir<PathBuf>` to a [`Path`], `InTempDir<String>` to a
/// `str`).
#[derive(Debug)]
pub struct InTempDir<T> {
    pub dir: TempDir,
    pub value: T,
}

impl<T: std::ops::Deref> std::ops::Deref for InTempDir<T> {
    type Target = T::Target;
    fn deref(&self) -> &T::Target {
        &self.value
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Little-endian bytes of f32 values.
pub fn f32_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// glTF accessor component types.
pub const FLOAT: u32 = 5126;
pub const UNSIGNED_INT: u32 = 5125;
pub const UNSIGNED_SHORT: u32 = 5123;
/// bufferView targets.
pub const ARRAY_BUFFER: u32 = 34962;
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// A glTF document under construction (module docs). Every list is JSON in glTF order.
#[derive(Default)]
pub struct Document {
    pub generator: Option<String>,
    pub buffer: Vec<u8>,
    pub buffer_views: Vec<Value>,
    pub accessors: Vec<Value>,
    pub meshes: Vec<Value>,
    pub nodes: Vec<Value>,
    pub materials: Vec<Value>,
    pub cameras: Vec<Value>,
    pub images: Vec<Value>,
    pub textures: Vec<Value>,
    pub samplers: Vec<Value>,
    pub extensions_used: BTreeSet<String>,
    /// Top-level `extensions` (e.g. `KHR_lights_punctual`'s light list).
    pub extensions: Map<String, Value>,
}

impl Document {
    /// Appends `data` to the buffer as a new view (4-byte aligned); its index.
    pub fn view(&mut self, data: &[u8], target: Option<u32>) -> usize {
        while !self.buffer.len().is_multiple_of(4) {
            self.buffer.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.buffer.len(), "byteLength": data.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.buffer.extend_from_slice(data);
        self.buffer_views.push(v);
        self.buffer_views.len() - 1
    }

    /// A view of `data` and an accessor over it; the accessor's index.
    pub fn accessor(
        &mut self,
        data: &[u8],
        target: Option<u32>,
        component_type: u32,
        count: usize,
        ty: &str,
    ) -> usize {
        let view = self.view(data, target);
        let a = json!({"bufferView": view, "componentType": component_type, "count": count, "type": ty});
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// Sets accessor `i`'s `min` and `max` (glTF requires them on POSITION).
    pub fn bounds(&mut self, i: usize, min: Vec<f64>, max: Vec<f64>) {
        self.accessors[i]["min"] = json!(min);
        self.accessors[i]["max"] = json!(max);
    }

    /// A VEC3 float accessor of `points` (with min/max when `bounds`).
    pub fn vec3(&mut self, points: &[[f32; 3]], bounds: bool) -> usize {
        let min_max = bounds.then(|| {
            let f = |i: usize, pick: fn(f32, f32) -> f32| {
                points.iter().map(|p| p[i]).fold(points[0][i], pick) as f64
            };
            (
                (0..3).map(|i| f(i, f32::min)).collect(),
                (0..3).map(|i| f(i, f32::max)).collect(),
            )
        });
        let data = f32_bytes(points.iter().flatten().copied());
        let i = self.accessor(&data, Some(ARRAY_BUFFER), FLOAT, points.len(), "VEC3");
        if let Some((lo, hi)) = min_max {
            self.bounds(i, lo, hi);
        }
        i
    }

    /// A u32 SCALAR index accessor.
    pub fn indices_u32(&mut self, indices: &[u32]) -> usize {
        let data: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let target = Some(ELEMENT_ARRAY_BUFFER);
        self.accessor(&data, target, UNSIGNED_INT, indices.len(), "SCALAR")
    }

    /// The document as JSON text (compact); the buffer is embedded as a data URI.
    pub fn json(&self) -> String {
        let mut asset = json!({"version": "2.0"});
        if let Some(g) = &self.generator {
            asset["generator"] = json!(g);
        }
        let mut doc = Map::new();
        doc.insert("asset".into(), asset);
        doc.insert("scene".into(), json!(0));
        let roots: Vec<usize> = (0..self.nodes.len()).collect();
        doc.insert("scenes".into(), json!([{"nodes": roots}]));
        let lists = [
            ("nodes", &self.nodes),
            ("cameras", &self.cameras),
            ("meshes", &self.meshes),
            ("materials", &self.materials),
            ("accessors", &self.accessors),
            ("bufferViews", &self.buffer_views),
            ("images", &self.images),
            ("textures", &self.textures),
            ("samplers", &self.samplers),
        ];
        for (key, list) in lists {
            if !list.is_empty() {
                doc.insert(key.into(), Value::Array(list.clone()));
            }
        }
        doc.insert(
            "buffers".into(),
            json!([{
                "byteLength": self.buffer.len(),
                "uri": format!("data:application/octet-stream;base64,{}", base64(&self.buffer)),
            }]),
        );
        if !self.extensions_used.is_empty() {
            doc.insert("extensionsUsed".into(), json!(self.extensions_used));
        }
        if !self.extensions.is_empty() {
            doc.insert("extensions".into(), Value::Object(self.extensions.clone()));
        }
        Value::Object(doc).to_string()
    }
}

/// Parses a JSON object given as text (test inputs); panics with the text when invalid.
fn object(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("invalid JSON {text:?}: {e}"))
}

/// A glTF document with one mesh made of `quads` (each four corners, counter-clockwise seen
/// from its front), material `material` (JSON of `materials[0]`), and `extra_nodes` (JSON
/// objects, e.g. `KHR_lights_punctual` light nodes) after the mesh node. `lights` is the JSON
/// array of `KHR_lights_punctual` lights (empty: the extension is not used).
pub fn quads_gltf(
    quads: &[[[f32; 3]; 4]],
    material: &str,
    extra_nodes: &[String],
    lights: &str,
) -> String {
    let mut d = Document::default();
    let points: Vec<[f32; 3]> = quads.iter().flatten().copied().collect();
    let position = d.vec3(&points, true);
    let indices: Vec<u32> = (0..quads.len() as u32)
        .flat_map(|k| [4 * k, 4 * k + 1, 4 * k + 2, 4 * k, 4 * k + 2, 4 * k + 3])
        .collect();
    let index = d.indices_u32(&indices);
    d.meshes.push(json!({"primitives": [{"attributes": {"POSITION": position}, "indices": index, "material": 0}]}));
    d.materials.push(object(material));
    d.nodes.push(json!({"mesh": 0}));
    d.nodes.extend(extra_nodes.iter().map(|n| object(n)));
    if !lights.is_empty() {
        d.extensions_used.insert("KHR_lights_punctual".into());
        d.extensions.insert(
            "KHR_lights_punctual".into(),
            json!({"lights": object(lights)}),
        );
    }
    d.json()
}

/// Writes `q.gltf` into `dir`: an emitting square [−1, 1]² in z = 0 facing +Z (radiance 1),
/// with no camera and no other light.
pub fn emitting_square(dir: &Path) -> PathBuf {
    let gltf = quads_gltf(
        &[[
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ]],
        r#"{"emissiveFactor": [1, 1, 1]}"#,
        &[],
        "",
    );
    let path = dir.join("q.gltf");
    std::fs::write(&path, gltf).unwrap();
    path
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
            component_type: FLOAT,
            normalized: false,
            bytes: f32_bytes(values.iter().flatten().copied()),
        }
    }
}

/// The unit quad (0,0,0)–(1,1,0) facing +z, two triangles (0,1,2), (0,2,3), with NORMAL +z
/// and TEXCOORD_0 = (x, 1 − y) (the image's top row at the quad's top edge), plus `extra`
/// attributes, `images` (PNG bytes, embedded as data URIs), `textures` and `samplers` JSON
/// arrays (without brackets), one `material` (JSON object), and `extensions_used` (quoted
/// names, comma separated).
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

/// `[a, b]` JSON array text without brackets, parsed (empty text: no entries).
fn list(text: &str) -> Vec<Value> {
    if text.trim().is_empty() {
        return Vec::new();
    }
    match object(&format!("[{text}]")) {
        Value::Array(v) => v,
        _ => unreachable!(),
    }
}

impl Quad {
    pub fn json(&self) -> String {
        let mut d = Document::default();
        let index = d.indices_u32(&[0, 1, 2, 0, 2, 3]);
        let mut attrs = Map::new();
        attrs.insert("POSITION".into(), json!(d.vec3(&QUAD_POSITIONS, true)));
        let mut standard = Vec::new();
        if !self.no_normals {
            standard.push(Attribute::floats("NORMAL", [[0.0, 0.0, 1.0]; 4]));
        }
        standard.push(Attribute::floats(
            "TEXCOORD_0",
            QUAD_POSITIONS.map(|p| [p[0], 1.0 - p[1]]),
        ));
        for a in standard.iter().chain(&self.extra) {
            let i = d.accessor(&a.bytes, None, a.component_type, 4, a.ty);
            if a.normalized {
                d.accessors[i]["normalized"] = json!(true);
            }
            attrs.insert(a.semantic.clone(), json!(i));
        }
        d.meshes
            .push(json!({"primitives": [{"attributes": attrs, "indices": index, "material": 0}]}));
        d.materials.push(object(&self.material));
        d.nodes.push(json!({"mesh": 0}));
        if let Some([x, y, z]) = self.second_node {
            d.nodes.push(json!({"mesh": 0, "translation": [x, y, z]}));
        }
        d.images = self
            .images
            .iter()
            .map(|png| json!({"uri": format!("data:image/png;base64,{}", base64(png))}))
            .collect();
        d.textures = list(&self.textures);
        d.samplers = list(&self.samplers);
        for name in list(&self.extensions_used) {
            d.extensions_used
                .insert(name.as_str().expect("extension names are strings").into());
        }
        d.json()
    }

    /// Writes the file `name` into `dir` and returns its path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, self.json()).expect("writing the test glTF");
        p
    }
}

/// Options of a [`SceneBuilder::material`] beyond its base colour.
#[derive(Clone, Copy, Debug, Default)]
pub struct MaterialOptions {
    pub metallic: f64,
    /// `None`: 1 (fully rough).
    pub roughness: Option<f64>,
    /// Emitted colour and `KHR_materials_emissive_strength`.
    pub emission: Option<([f64; 3], f64)>,
    pub transmission: Option<f64>,
    pub ior: Option<f64>,
    /// `KHR_materials_volume` thickness: a closed volume that refracts.
    pub thickness: Option<f64>,
}

/// One mesh of a [`SceneBuilder`]: material name, positions, normals (smooth meshes only)
/// and indices (written as u16).
type SceneMesh = (String, Vec<[f64; 3]>, Option<Vec<[f64; 3]>>, Vec<u32>);

/// Builder of the benchmark scenes (module docs): one mesh per material, in the order the
/// materials are first used; quads and boxes flat-shaded, spheres smooth.
pub struct SceneBuilder {
    generator: String,
    materials: Vec<(String, Value)>,
    extensions: BTreeSet<String>,
    meshes: Vec<SceneMesh>,
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn norm(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

impl SceneBuilder {
    pub fn new(generator: &str) -> SceneBuilder {
        SceneBuilder {
            generator: generator.into(),
            materials: Vec::new(),
            extensions: BTreeSet::new(),
            meshes: Vec::new(),
        }
    }

    /// A double-sided glTF material named `name`.
    pub fn material(&mut self, name: &str, base: [f64; 3], o: MaterialOptions) {
        let mut m = json!({
            "name": name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [base[0], base[1], base[2], 1.0],
                "metallicFactor": o.metallic,
                "roughnessFactor": o.roughness.unwrap_or(1.0),
            },
            "doubleSided": true,
        });
        let mut ext = Map::new();
        if let Some((rgb, strength)) = o.emission {
            m["emissiveFactor"] = json!(rgb);
            ext.insert(
                "KHR_materials_emissive_strength".into(),
                json!({"emissiveStrength": strength}),
            );
        }
        if let Some(t) = o.transmission {
            ext.insert(
                "KHR_materials_transmission".into(),
                json!({"transmissionFactor": t}),
            );
        }
        if let Some(ior) = o.ior {
            ext.insert("KHR_materials_ior".into(), json!({"ior": ior}));
        }
        if let Some(t) = o.thickness {
            ext.insert("KHR_materials_volume".into(), json!({"thicknessFactor": t}));
        }
        if !ext.is_empty() {
            self.extensions.extend(ext.keys().cloned());
            m["extensions"] = Value::Object(ext);
        }
        self.materials.push((name.into(), m));
    }

    fn mesh(&mut self, material: &str, smooth: bool) -> usize {
        if let Some(i) = self.meshes.iter().position(|m| m.0 == material) {
            return i;
        }
        assert!(
            self.materials.iter().any(|m| m.0 == material),
            "material {material:?} used before it is declared"
        );
        let normals = smooth.then(Vec::new);
        self.meshes
            .push((material.into(), Vec::new(), normals, Vec::new()));
        self.meshes.len() - 1
    }

    /// A planar quad p0 p1 p2 p3 (in order around it). `facing`: the direction its front
    /// (counter-clockwise) face must point to; the winding is flipped to match.
    pub fn quad(&mut self, material: &str, p: [[f64; 3]; 4], facing: Option<[f64; 3]>) {
        let i = self.mesh(material, false);
        let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let pts = match facing {
            Some(f) if dot(n, f) < 0.0 => [p[0], p[3], p[2], p[1]],
            _ => p,
        };
        let mesh = &mut self.meshes[i];
        let base = mesh.1.len() as u32;
        mesh.1.extend(pts);
        mesh.3
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    /// Triangles `indices` (three per triangle, counter-clockwise seen from the front) over
    /// `positions`, with one vertex normal per position for a smooth mesh or none for a flat
    /// one: the research scenes' height fields, cones and boxes built from numbers. A material
    /// is either smooth or flat in every call.
    pub fn triangles(
        &mut self,
        material: &str,
        positions: &[[f64; 3]],
        normals: Option<&[[f64; 3]]>,
        indices: &[u32],
    ) {
        let i = self.mesh(material, normals.is_some());
        let mesh = &mut self.meshes[i];
        assert_eq!(
            mesh.2.is_some(),
            normals.is_some(),
            "{material}: mixes smooth and flat parts"
        );
        let base = mesh.1.len() as u32;
        mesh.1.extend_from_slice(positions);
        if let (Some(all), Some(n)) = (mesh.2.as_mut(), normals) {
            assert_eq!(
                n.len(),
                positions.len(),
                "{material}: one normal per position"
            );
            all.extend_from_slice(n);
        }
        mesh.3.extend(indices.iter().map(|k| base + k));
    }

    /// An axis-aligned closed box, faces pointing outwards.
    pub fn cuboid(&mut self, material: &str, lo: [f64; 3], hi: [f64; 3]) {
        let [x0, y0, z0] = lo;
        let [x1, y1, z1] = hi;
        let c = [0, 1, 2].map(|i| (lo[i] + hi[i]) / 2.0);
        let faces = [
            [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],
            [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
            [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
            [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
            [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
            [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
        ];
        for f in faces {
            let fc = [0, 1, 2].map(|i| f.iter().map(|p| p[i]).sum::<f64>() / 4.0);
            self.quad(material, f, Some(sub(fc, c)));
        }
    }

    /// An icosphere with smooth vertex normals, `subdivisions` times subdivided.
    pub fn sphere(&mut self, material: &str, centre: [f64; 3], radius: f64, subdivisions: u32) {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut verts: Vec<[f64; 3]> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .map(norm)
        .to_vec();
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut cache = std::collections::HashMap::new();
            let mut mid = |a: u32, b: u32, verts: &mut Vec<[f64; 3]>| -> u32 {
                *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (va, vb) = (verts[a as usize], verts[b as usize]);
                    verts.push(norm([0, 1, 2].map(|i| (va[i] + vb[i]) / 2.0)));
                    verts.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(faces.len() * 4);
            for [a, b, c] in faces {
                let ab = mid(a, b, &mut verts);
                let bc = mid(b, c, &mut verts);
                let ca = mid(c, a, &mut verts);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            faces = next;
        }
        let i = self.mesh(material, true);
        let mesh = &mut self.meshes[i];
        let base = mesh.1.len() as u32;
        for v in &verts {
            mesh.1.push([0, 1, 2].map(|k| centre[k] + radius * v[k]));
            mesh.2.as_mut().expect("a smooth mesh").push(*v);
        }
        mesh.3.extend(faces.iter().flatten().map(|k| base + k));
    }

    /// An open cylinder (a tube without caps, zero wall thickness) standing on the plane
    /// y = `base[1]`: axis +Y through `base`, `radius`, `height`, `segments` quads around,
    /// smooth vertex normals pointing out (a double-sided material shades the inside too).
    pub fn tube(
        &mut self,
        material: &str,
        base: [f64; 3],
        radius: f64,
        height: f64,
        segments: u32,
    ) {
        let i = self.mesh(material, true);
        let mesh = &mut self.meshes[i];
        let first = mesh.1.len() as u32;
        for k in 0..segments {
            let a = std::f64::consts::TAU * k as f64 / segments as f64;
            let (s, c) = a.sin_cos();
            for y in [0.0, height] {
                mesh.1
                    .push([base[0] + radius * c, base[1] + y, base[2] + radius * s]);
                mesh.2.as_mut().expect("a smooth mesh").push([c, 0.0, s]);
            }
        }
        for k in 0..segments {
            let (lo, hi) = (first + 2 * k, first + 2 * k + 1);
            let (lo2, hi2) = (
                first + 2 * ((k + 1) % segments),
                first + 2 * ((k + 1) % segments) + 1,
            );
            // Counter-clockwise seen from outside.
            mesh.3.extend([lo, hi, lo2, lo2, hi, hi2]);
        }
    }

    /// The document with a perspective camera at `position` looking at `look_at` (up +Y),
    /// vertical field of view `yfov_degrees`; and its triangle count.
    pub fn gltf(
        &self,
        position: [f64; 3],
        look_at: [f64; 3],
        yfov_degrees: f64,
        aspect: f64,
    ) -> (String, usize) {
        let mut d = Document {
            generator: Some(self.generator.clone()),
            extensions_used: self.extensions.clone(),
            ..Document::default()
        };
        let mut triangles = 0;
        for (name, positions, normals, indices) in &self.meshes {
            let f32s = |v: &[[f64; 3]]| f32_bytes(v.iter().flatten().map(|&c| c as f32));
            let lo = (0..3)
                .map(|i| positions.iter().map(|p| p[i]).fold(f64::INFINITY, f64::min))
                .collect();
            let hi = (0..3)
                .map(|i| {
                    positions
                        .iter()
                        .map(|p| p[i])
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            let target = Some(ARRAY_BUFFER);
            let count = positions.len();
            let pa = d.accessor(&f32s(positions), target, FLOAT, count, "VEC3");
            d.bounds(pa, lo, hi);
            let mut attrs = json!({"POSITION": pa});
            if let Some(n) = normals {
                attrs["NORMAL"] = json!(d.accessor(&f32s(n), target, FLOAT, n.len(), "VEC3"));
            }
            assert!(
                positions.len() < 65536,
                "{name}: too many vertices for u16 indices"
            );
            let ib: Vec<u8> = indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            let ia = d.accessor(
                &ib,
                Some(ELEMENT_ARRAY_BUFFER),
                UNSIGNED_SHORT,
                indices.len(),
                "SCALAR",
            );
            let material = self
                .materials
                .iter()
                .position(|m| &m.0 == name)
                .expect("declared material");
            d.meshes.push(json!({"name": name, "primitives": [{"attributes": attrs, "indices": ia, "material": material}]}));
            d.nodes
                .push(json!({"name": name, "mesh": d.meshes.len() - 1}));
            triangles += indices.len() / 3;
        }
        // The camera looks along its local −Z with +Y up.
        let f = norm(sub(look_at, position));
        let r = norm(cross(f, [0.0, 1.0, 0.0]));
        let u = cross(r, f);
        let m = [
            r[0],
            r[1],
            r[2],
            0.0,
            u[0],
            u[1],
            u[2],
            0.0,
            -f[0],
            -f[1],
            -f[2],
            0.0,
            position[0],
            position[1],
            position[2],
            1.0,
        ];
        let rounded: Vec<f64> = m.iter().map(|x| (x * 1e7).round() / 1e7).collect();
        d.nodes
            .push(json!({"name": "camera", "camera": 0, "matrix": rounded}));
        d.cameras
            .push(json!({"type": "perspective", "perspective": {
            "yfov": yfov_degrees.to_radians(), "znear": 0.01, "aspectRatio": aspect}}));
        d.materials = self.materials.iter().map(|m| m.1.clone()).collect();
        (d.json(), triangles)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_standard_alphabet_and_padding() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(&[0xfb, 0xff]), "+/8=");
    }

    #[test]
    fn views_are_aligned_and_accessors_point_at_them() {
        let mut d = Document::default();
        let a = d.accessor(&[1, 2, 3], None, 5121, 3, "SCALAR");
        let b = d.vec3(&[[1.0, -2.0, 3.0], [0.5, 4.0, -1.0]], true);
        assert_eq!((a, b), (0, 1));
        assert_eq!(
            d.buffer_views[1]["byteOffset"],
            json!(4),
            "padded to 4 bytes"
        );
        assert_eq!(d.accessors[1]["min"], json!([0.5, -2.0, -1.0]));
        assert_eq!(d.accessors[1]["max"], json!([1.0, 4.0, 3.0]));
        assert_eq!(d.buffer.len(), 4 + 24);
        let doc: Value = serde_json::from_str(&d.json()).unwrap();
        assert_eq!(doc["buffers"][0]["byteLength"], json!(28));
    }

    #[test]
    fn quads_face_where_they_are_told() {
        let mut b = SceneBuilder::new("test");
        b.material("m", [0.5; 3], MaterialOptions::default());
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        b.quad("m", p, Some([0.0, 0.0, -1.0]));
        let mesh = &b.meshes[0];
        let v = &mesh.1;
        let n = cross(sub(v[1], v[0]), sub(v[2], v[0]));
        assert!(n[2] < 0.0, "winding flipped to face -z: {v:?}");
        b.cuboid("m", [0.0; 3], [1.0; 3]);
        assert_eq!(b.meshes[0].3.len(), 6 + 36);
        b.material("s", [0.5; 3], MaterialOptions::default());
        b.sphere("s", [0.0; 3], 1.0, 1);
        assert_eq!(b.meshes.len(), 2, "one mesh per material");
        // 12 vertices, 30 edges: one subdivision adds a vertex per edge, 80 faces.
        assert_eq!((b.meshes[1].1.len(), b.meshes[1].3.len()), (42, 240));
        assert!(b.meshes[1]
            .1
            .iter()
            .all(|p| (dot(*p, *p) - 1.0).abs() < 1e-12));
    }
}
