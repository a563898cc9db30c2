//! Decoding of compressed geometry: `EXT_meshopt_compression` buffer views and
//! `KHR_draco_mesh_compression` primitives.
//!
//! ## EXT_meshopt_compression
//!
//! A compressed view carries `extensions.EXT_meshopt_compression = { buffer, byteOffset,
//! byteLength, byteStride, count, mode, filter }`: `byteLength` bytes at `byteOffset` of
//! `buffer` decode to `count × byteStride` bytes, which are what the view's accessors read. The
//! view's own `buffer` is a fallback (often with no data at all: `fallback: true`) and is never
//! read. Modes and filters (extension spec, "Modes" and "Filters"):
//!
//! * `ATTRIBUTES`: meshoptimizer's vertex codec; `byteStride` a multiple of 4, at most 256;
//! * `TRIANGLES`: the index codec for triangle lists; `byteStride` 2 or 4, `count` % 3 = 0;
//! * `INDICES`: the index-sequence codec; `byteStride` 2 or 4;
//! * filters, for `ATTRIBUTES` only, applied after decoding:
//!   - `OCTAHEDRAL` (stride 4 or 8): unit vectors from signed octahedral X/Y,
//!   - `QUATERNION` (stride 8): unit quaternions with the largest component dropped,
//!   - `EXPONENTIAL` (stride % 4 = 0): each 32-bit word is `2^e · m` with an 8-bit signed
//!     exponent `e` (top byte) and a 24-bit signed mantissa `m`.
//!
//! The codecs are meshoptimizer's own (the `meshopt` crate), which are safe on untrusted input
//! (they may decode garbage, never read out of bounds); the lengths are checked here first.
//!
//! ## KHR_draco_mesh_compression
//!
//! A compressed primitive carries `extensions.KHR_draco_mesh_compression = { bufferView,
//! attributes: { SEMANTIC: uniqueId } }`: the buffer view holds one Draco mesh bitstream; each
//! listed attribute's accessor (which has no `bufferView`) takes the values of the Draco
//! attribute with that unique id, one per Draco point, and the indices accessor takes the
//! faces' point indices. The accessors' `count`, `type` and `componentType` describe the
//! decoded data (extension spec, "Conformance"). Decoded with `draco-core`, a pure-Rust port
//! of Google's decoder. Only float attributes are taken from the stream (what Blender,
//! gltf-transform and gltfpack write for Draco); an integer attribute is an error naming it.

use gltf::json::Value;

/// `mode` of a compressed view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Attributes,
    Triangles,
    Indices,
}

/// `filter` of a compressed view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    None,
    Octahedral,
    Quaternion,
    Exponential,
}

/// The parsed `EXT_meshopt_compression` object of one buffer view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshoptView {
    pub buffer: usize,
    pub byte_offset: usize,
    pub byte_length: usize,
    pub byte_stride: usize,
    pub count: usize,
    pub mode: Mode,
    pub filter: Filter,
}

fn uint(obj: &Value, key: &str, default: Option<usize>) -> Result<usize, String> {
    match obj.get(key) {
        None => default.ok_or_else(|| format!("missing `{key}`")),
        Some(v) => v
            .as_u64()
            .and_then(|x| usize::try_from(x).ok())
            .ok_or_else(|| format!("`{key}` must be a non-negative integer, found {v}")),
    }
}

impl MeshoptView {
    /// Parses and checks the extension object (the reason names the offending member).
    pub fn parse(obj: &Value) -> Result<MeshoptView, String> {
        if !obj.is_object() {
            return Err("extension value is not an object".into());
        }
        let mode = match obj.get("mode").and_then(Value::as_str) {
            Some("ATTRIBUTES") => Mode::Attributes,
            Some("TRIANGLES") => Mode::Triangles,
            Some("INDICES") => Mode::Indices,
            other => {
                return Err(format!(
                    "`mode` must be ATTRIBUTES, TRIANGLES or INDICES, found {other:?}"
                ))
            }
        };
        let filter = match obj.get("filter").map(|v| v.as_str()) {
            None | Some(Some("NONE")) => Filter::None,
            Some(Some("OCTAHEDRAL")) => Filter::Octahedral,
            Some(Some("QUATERNION")) => Filter::Quaternion,
            Some(Some("EXPONENTIAL")) => Filter::Exponential,
            Some(other) => {
                return Err(format!(
                    "`filter` must be NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL, found {other:?}"
                ))
            }
        };
        let m = MeshoptView {
            buffer: uint(obj, "buffer", None)?,
            byte_offset: uint(obj, "byteOffset", Some(0))?,
            byte_length: uint(obj, "byteLength", None)?,
            byte_stride: uint(obj, "byteStride", None)?,
            count: uint(obj, "count", None)?,
            mode,
            filter,
        };
        let s = m.byte_stride;
        match m.mode {
            Mode::Attributes if s == 0 || !s.is_multiple_of(4) || s > 256 => {
                return Err(format!(
                    "ATTRIBUTES needs a byteStride that is a multiple of 4 up to 256, found {s}"
                ))
            }
            Mode::Triangles | Mode::Indices if s != 2 && s != 4 => {
                return Err(format!("{:?} needs byteStride 2 or 4, found {s}", m.mode))
            }
            Mode::Triangles if !m.count.is_multiple_of(3) => {
                return Err(format!(
                    "TRIANGLES needs a count divisible by 3, found {}",
                    m.count
                ))
            }
            _ => {}
        }
        match (m.filter, m.mode) {
            (Filter::None, _) => {}
            (_, Mode::Triangles | Mode::Indices) => {
                return Err(format!(
                    "filter {:?} is only allowed with ATTRIBUTES",
                    m.filter
                ))
            }
            (Filter::Octahedral, _) if s != 4 && s != 8 => {
                return Err(format!("OCTAHEDRAL needs byteStride 4 or 8, found {s}"))
            }
            (Filter::Quaternion, _) if s != 8 => {
                return Err(format!("QUATERNION needs byteStride 8, found {s}"))
            }
            _ => {}
        }
        if m.count.checked_mul(s).is_none() {
            return Err("count × byteStride overflows".into());
        }
        // The decoders allocate `count × byteStride` bytes before reading the stream, so a
        // count the stream cannot hold is refused here rather than allocated.
        let most = m.most_decoded_bytes();
        if m.decoded_len() > most {
            return Err(format!(
                "count {} × byteStride {s} = {} bytes cannot come from byteLength {} ({:?} decodes at most {most} bytes from it)",
                m.count,
                m.decoded_len(),
                m.byte_length,
                m.mode
            ));
        }
        Ok(m)
    }

    /// The most bytes `byteLength` compressed bytes can decode to (meshoptimizer's codecs,
    /// `vertexcodec.cpp` and `indexcodec.cpp`): the vertex codec reads at least `byteStride/4`
    /// control bytes (version 1; version 0 at least as many group headers) per block of at
    /// most 256 vertices, so `count × byteStride ≤ 1024 × byteLength`; the triangle codec
    /// reads at least one code byte per triangle; the sequence codec at least one byte per
    /// index.
    pub fn most_decoded_bytes(&self) -> usize {
        let n = self.byte_length;
        match self.mode {
            Mode::Attributes => n.saturating_mul(1024),
            Mode::Triangles => n.saturating_mul(3 * self.byte_stride),
            Mode::Indices => n.saturating_mul(self.byte_stride),
        }
    }

    /// Size of the decoded data in bytes.
    pub fn decoded_len(&self) -> usize {
        self.count * self.byte_stride
    }

    /// Decodes `data` (the `byteLength` compressed bytes) to `count × byteStride` bytes.
    pub fn decode(&self, data: &[u8]) -> Result<Vec<u8>, String> {
        let err = |e: meshopt::Error| format!("{:?} stream does not decode: {e}", self.mode);
        let mut out = match (self.mode, self.byte_stride) {
            (Mode::Attributes, s) => decode_vertices(data, self.count, s).map_err(err)?,
            (Mode::Triangles, 2) => {
                flatten_u16(&meshopt::decode_index_buffer::<u16>(data, self.count).map_err(err)?)
            }
            (Mode::Triangles, _) => {
                flatten_u32(&meshopt::decode_index_buffer::<u32>(data, self.count).map_err(err)?)
            }
            (Mode::Indices, 2) => {
                flatten_u16(&meshopt::decode_index_sequence::<u16>(data, self.count).map_err(err)?)
            }
            (Mode::Indices, _) => {
                flatten_u32(&meshopt::decode_index_sequence::<u32>(data, self.count).map_err(err)?)
            }
        };
        match (self.filter, self.byte_stride) {
            (Filter::None, _) => {}
            (Filter::Octahedral, 4) => {
                let mut v: Vec<[i8; 4]> = out
                    .chunks_exact(4)
                    .map(|c| [c[0] as i8, c[1] as i8, c[2] as i8, c[3] as i8])
                    .collect();
                meshopt::decode_filter_oct(&mut v);
                out = v.iter().flat_map(|c| c.map(|x| x as u8)).collect();
            }
            (Filter::Octahedral | Filter::Quaternion, _) => {
                let mut v: Vec<[i16; 4]> = out
                    .chunks_exact(8)
                    .map(|c| std::array::from_fn(|k| i16::from_le_bytes([c[2 * k], c[2 * k + 1]])))
                    .collect();
                if self.filter == Filter::Octahedral {
                    meshopt::decode_filter_oct(&mut v);
                } else {
                    meshopt::decode_filter_quat(&mut v);
                }
                out = v
                    .iter()
                    .flat_map(|c| c.iter().flat_map(|x| x.to_le_bytes()))
                    .collect();
            }
            (Filter::Exponential, _) => {
                // The exponential filter decodes every 32-bit word on its own, so the stream
                // can be filtered as single-word elements whatever its stride.
                let mut v: Vec<[u32; 1]> = out
                    .chunks_exact(4)
                    .map(|c| [u32::from_le_bytes([c[0], c[1], c[2], c[3]])])
                    .collect();
                meshopt::decode_filter_exp(&mut v);
                out = v.iter().flat_map(|c| c[0].to_le_bytes()).collect();
            }
        }
        debug_assert_eq!(out.len(), self.decoded_len());
        Ok(out)
    }
}

fn flatten_u16(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn flatten_u32(v: &[u32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// One vertex of `S` bytes (arrays implement `Default` only up to 32 elements).
#[derive(Clone, Copy)]
#[repr(transparent)]
struct Vertex<const S: usize>([u8; S]);

impl<const S: usize> Default for Vertex<S> {
    fn default() -> Self {
        Vertex([0; S])
    }
}

fn decode_fixed<const S: usize>(data: &[u8], count: usize) -> meshopt::Result<Vec<u8>> {
    let v = meshopt::decode_vertex_buffer::<Vertex<S>>(data, count)?;
    Ok(v.iter().flat_map(|x| x.0).collect())
}

/// The vertex codec for a stride known only at run time (it interleaves bytes per vertex, so
/// the element size must be the stride): one instantiation per allowed stride.
fn decode_vertices(data: &[u8], count: usize, stride: usize) -> meshopt::Result<Vec<u8>> {
    macro_rules! strides {
        ($($s:literal)*) => {
            match stride {
                $($s => decode_fixed::<$s>(data, count),)*
                _ => unreachable!("stride {stride} was checked to be a multiple of 4 up to 256"),
            }
        };
    }
    strides!(4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64 68 72 76 80 84 88 92 96 100 104 108
        112 116 120 124 128 132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192 196
        200 204 208 212 216 220 224 228 232 236 240 244 248 252 256)
}

/// The parsed `KHR_draco_mesh_compression` object of one primitive.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DracoPrimitive {
    pub buffer_view: usize,
    /// (glTF semantic, Draco unique attribute id).
    pub attributes: Vec<(String, u32)>,
}

impl DracoPrimitive {
    pub fn parse(obj: &Value) -> Result<DracoPrimitive, String> {
        let buffer_view = uint(obj, "bufferView", None)?;
        let attrs = obj
            .get("attributes")
            .and_then(Value::as_object)
            .ok_or("missing `attributes` object")?;
        let mut attributes = Vec::new();
        for (k, v) in attrs {
            let id = v
                .as_u64()
                .and_then(|x| u32::try_from(x).ok())
                .ok_or_else(|| format!("attributes.{k} must be a non-negative integer id"))?;
            attributes.push((k.clone(), id));
        }
        Ok(DracoPrimitive {
            buffer_view,
            attributes,
        })
    }
}

/// What one accessor of a Draco primitive takes from the decoded mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DracoPart {
    /// The attribute with this unique id.
    Attribute(u32),
    /// The faces' point indices.
    Indices,
}

/// A decoded Draco mesh.
pub struct DracoMesh(draco_core::Mesh);

impl DracoMesh {
    pub fn decode(data: &[u8]) -> Result<DracoMesh, String> {
        let mut buffer = draco_core::DecoderBuffer::new(data);
        let mut mesh = draco_core::Mesh::new();
        draco_core::MeshDecoder::new()
            .decode(&mut buffer, &mut mesh)
            .map_err(|e| {
                format!(
                    "the Draco bitstream does not decode ({e}); re-export without Draco, e.g. `gltf-transform copy in.glb out.glb` or `gltfpack -i in.glb -o out.glb` (without -cc)"
                )
            })?;
        Ok(DracoMesh(mesh))
    }

    /// `count` elements of `components` little-endian f32 values (for attributes) or u32
    /// indices written as `index_size`-byte integers (for indices), tightly packed.
    pub fn bytes(
        &self,
        part: DracoPart,
        count: usize,
        components: usize,
        index_size: usize,
    ) -> Result<Vec<u8>, String> {
        let mesh = &self.0;
        match part {
            DracoPart::Attribute(id) => {
                let attr = mesh
                    .attribute_by_unique_id(id)
                    .ok_or_else(|| format!("the Draco stream has no attribute with id {id}"))?;
                let n = mesh.num_points();
                if n != count {
                    return Err(format!(
                        "the Draco stream has {n} points but the accessor's count is {count}"
                    ));
                }
                let values = attr.read_f32s(n, components);
                Ok(values.iter().flat_map(|v| v.to_le_bytes()).collect())
            }
            DracoPart::Indices => {
                let n = mesh.num_faces() * 3;
                if n != count {
                    return Err(format!(
                        "the Draco stream has {} faces ({n} indices) but the accessor's count is {count}",
                        mesh.num_faces()
                    ));
                }
                let mut out = Vec::with_capacity(n * index_size);
                for face in mesh.faces() {
                    for p in face {
                        let i = p.0;
                        match index_size {
                            1 => out.push(u8::try_from(i).map_err(|_| {
                                format!("index {i} does not fit the accessor's unsigned byte")
                            })?),
                            2 => out.extend_from_slice(
                                &u16::try_from(i)
                                    .map_err(|_| {
                                        format!(
                                            "index {i} does not fit the accessor's unsigned short"
                                        )
                                    })?
                                    .to_le_bytes(),
                            ),
                            _ => out.extend_from_slice(&i.to_le_bytes()),
                        }
                    }
                }
                Ok(out)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(json: &str) -> Result<MeshoptView, String> {
        MeshoptView::parse(&gltf::json::deserialize::from_str(json).unwrap())
    }

    #[test]
    fn parse_checks_mode_stride_and_filter() {
        let ok =
            view(r#"{"buffer":1,"byteLength":10,"byteStride":12,"count":3,"mode":"ATTRIBUTES"}"#)
                .unwrap();
        assert_eq!((ok.byte_offset, ok.filter), (0, Filter::None));
        for bad in [
            r#"{"buffer":1,"byteLength":10,"byteStride":6,"count":3,"mode":"ATTRIBUTES"}"#,
            r#"{"buffer":1,"byteLength":10,"byteStride":4,"count":4,"mode":"TRIANGLES"}"#,
            r#"{"buffer":1,"byteLength":10,"byteStride":4,"count":3,"mode":"TRIANGLES","filter":"OCTAHEDRAL"}"#,
            r#"{"buffer":1,"byteLength":10,"byteStride":12,"count":3,"mode":"ATTRIBUTES","filter":"QUATERNION"}"#,
            r#"{"buffer":1,"byteLength":10,"byteStride":12,"count":3,"mode":"FOO"}"#,
            r#"{"byteLength":10,"byteStride":12,"count":3,"mode":"ATTRIBUTES"}"#,
        ] {
            assert!(view(bad).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn d3_count_beyond_what_the_stream_can_hold_is_refused_before_allocating() {
        // 2³¹ vertices of 12 bytes (25.7 GB) from 2 KB of stream: refused by the parse.
        for (bad, names) in [
            (
                r#"{"buffer":1,"byteLength":2048,"byteStride":12,"count":2147483648,"mode":"ATTRIBUTES"}"#,
                "count 2147483648",
            ),
            (
                r#"{"buffer":1,"byteLength":100,"byteStride":4,"count":3000,"mode":"TRIANGLES"}"#,
                "byteLength 100",
            ),
            (
                r#"{"buffer":1,"byteLength":100,"byteStride":2,"count":101,"mode":"INDICES"}"#,
                "count 101",
            ),
        ] {
            let err = view(bad).unwrap_err();
            assert!(err.contains(names), "{bad}: {err}");
        }
        // At the codecs' best ratios, still accepted.
        for ok in [
            r#"{"buffer":1,"byteLength":3,"byteStride":4,"count":768,"mode":"ATTRIBUTES"}"#,
            r#"{"buffer":1,"byteLength":100,"byteStride":4,"count":300,"mode":"TRIANGLES"}"#,
            r#"{"buffer":1,"byteLength":100,"byteStride":2,"count":100,"mode":"INDICES"}"#,
        ] {
            assert!(view(ok).is_ok(), "{ok}");
        }
    }

    #[test]
    fn exponential_filter_decodes_words_as_two_to_the_e_times_m() {
        // e = -3 (0xFD), m = 12345: 12345 / 8. e = 2, m = -7: -28.
        let words = [
            (0xFDu32 << 24) | 12345,
            (2u32 << 24) | ((-7i32 as u32) & 0x00FF_FFFF),
        ];
        let raw: Vec<[u8; 8]> = vec![{
            let mut b = [0u8; 8];
            b[..4].copy_from_slice(&words[0].to_le_bytes());
            b[4..].copy_from_slice(&words[1].to_le_bytes());
            b
        }];
        let enc = meshopt::encode_vertex_buffer(&raw).unwrap();
        let m = MeshoptView {
            buffer: 0,
            byte_offset: 0,
            byte_length: enc.len(),
            byte_stride: 8,
            count: 1,
            mode: Mode::Attributes,
            filter: Filter::Exponential,
        };
        let out = m.decode(&enc).unwrap();
        let f = |k: usize| {
            f32::from_le_bytes([out[4 * k], out[4 * k + 1], out[4 * k + 2], out[4 * k + 3]])
        };
        assert_eq!(f(0), 12345.0 / 8.0);
        assert_eq!(f(1), -28.0);
    }

    #[test]
    fn quaternion_filter_round_trips_unit_quaternions() {
        let q: Vec<[f32; 4]> = [
            [0.1f32, -0.7, 0.3, 0.5],
            [0.0, 0.0, 0.0, 1.0],
            [-0.9, 0.1, 0.2, 0.3],
        ]
        .iter()
        .map(|v| {
            let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            v.map(|x| x / n)
        })
        .collect();
        let enc = meshopt::encode_vertex_buffer(&meshopt::encode_filter_quat(&q, 16)).unwrap();
        let m = MeshoptView {
            buffer: 0,
            byte_offset: 0,
            byte_length: enc.len(),
            byte_stride: 8,
            count: 3,
            mode: Mode::Attributes,
            filter: Filter::Quaternion,
        };
        let out = m.decode(&enc).unwrap();
        for (k, want) in q.iter().enumerate() {
            let got: Vec<f32> = (0..4)
                .map(|c| {
                    let i = 8 * k + 2 * c;
                    (i16::from_le_bytes([out[i], out[i + 1]]) as f32 / 32767.0).max(-1.0)
                })
                .collect();
            // q and -q are the same rotation.
            let dot: f32 = got.iter().zip(want).map(|(a, b)| a * b).sum();
            assert!(dot.abs() > 0.9999, "quaternion {k}: {got:?} vs {want:?}");
        }
    }
}
