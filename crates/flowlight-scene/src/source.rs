//! Reading a glTF asset from disk: `.gltf` JSON or `.glb` container, validation, and the
//! buffers it references (the GLB binary chunk, external files, base64 data URIs).

use crate::compression::{DracoMesh, DracoPart, DracoPrimitive, MeshoptView};
use crate::error::SceneError;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A parsed and validated glTF document with the means to fetch its buffers on demand.
pub struct GltfSource {
    pub file: PathBuf,
    pub base_dir: PathBuf,
    pub document: gltf::Document,
    /// Warning lines about the file's extensions (ignored or unknown optional ones), already
    /// logged by [`GltfSource::open`]; kept for callers and tests.
    pub warnings: Vec<String>,
    blob: Option<Vec<u8>>,
    buffers: Vec<Option<Vec<u8>>>,
    /// Decoded `EXT_meshopt_compression` buffer views, by view index.
    decoded: HashMap<usize, Vec<u8>>,
    /// Accessors without a buffer view that a `KHR_draco_mesh_compression` primitive fills:
    /// accessor index to (compressed buffer view, part).
    draco_accessors: HashMap<usize, (usize, DracoPart)>,
    /// Decoded Draco meshes, by buffer view index.
    draco_meshes: HashMap<usize, DracoMesh>,
}

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

fn read_u32(data: &[u8], at: usize) -> Option<u32> {
    let b = data.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// A GLB chunk: type, payload, offset of the next chunk.
type Chunk<'a> = (u32, &'a [u8], usize);

/// Splits a GLB container into its JSON chunk and optional BIN chunk, checking every length.
pub fn split_glb(data: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    if data.len() < 12 {
        return Err(format!(
            "file is {} bytes, shorter than the 12-byte header",
            data.len()
        ));
    }
    if &data[0..4] != GLB_MAGIC {
        return Err("missing 'glTF' magic".into());
    }
    let version = read_u32(data, 4).unwrap_or(0);
    if version != 2 {
        return Err(format!(
            "unsupported container version {version} (expected 2)"
        ));
    }
    let total = read_u32(data, 8).unwrap_or(0) as usize;
    if total > data.len() {
        return Err(format!(
            "header says {total} bytes but the file has only {} (truncated)",
            data.len()
        ));
    }
    if total < 20 {
        return Err(format!(
            "header length {total} leaves no room for a JSON chunk"
        ));
    }
    let data = &data[..total];
    let chunk = |at: usize| -> Result<Option<Chunk>, String> {
        if at == data.len() {
            return Ok(None);
        }
        let (Some(len), Some(ty)) = (read_u32(data, at), read_u32(data, at + 4)) else {
            return Err(format!("chunk header at byte {at} is truncated"));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                format!(
                    "chunk at byte {at} claims {len} bytes but only {} remain (truncated)",
                    data.len() - start
                )
            })?;
        Ok(Some((ty, &data[start..end], end)))
    };
    let Some((ty, json, next)) = chunk(12)? else {
        return Err("no JSON chunk".into());
    };
    if ty != CHUNK_JSON {
        return Err(format!("first chunk has type {ty:#x}, expected JSON"));
    }
    let mut bin = None;
    let mut at = next;
    // Later chunks: the first BIN chunk is the binary buffer; unknown chunk types are skipped.
    while let Some((ty, bytes, next)) = chunk(at)? {
        if ty == CHUNK_BIN && bin.is_none() {
            bin = Some(bytes);
        }
        at = next;
    }
    Ok((json, bin))
}

impl GltfSource {
    /// Reads and validates `file`.
    pub fn open(file: &Path) -> Result<GltfSource, SceneError> {
        let path = file.to_path_buf();
        let data = crate::files::read_regular_file(file, crate::files::MAX_INPUT_FILE_BYTES)
            .map_err(|source| SceneError::Io {
                file: path.clone(),
                source,
            })?;
        let (json, blob) = if data.starts_with(GLB_MAGIC) {
            let (json, bin) = split_glb(&data).map_err(|reason| SceneError::Glb {
                file: path.clone(),
                reason,
            })?;
            (json, bin.map(<[u8]>::to_vec))
        } else {
            (&data[..], None)
        };
        let root: gltf::json::Root =
            gltf::json::deserialize::from_slice(json).map_err(|e| SceneError::Json {
                file: path.clone(),
                reason: e.to_string(),
            })?;
        // Extensions: our own table decides (gltf-json refuses every required extension that
        // is not one of its enabled features, naming none of the ones it does not know).
        let warnings = crate::extensions::check(&root.extensions_used, &root.extensions_required)
            .map_err(|reason| SceneError::Validation {
            file: path.clone(),
            reason,
        })?;
        for w in &warnings {
            tracing::warn!(file = %path.display(), "{w}");
        }
        // gltf-json's own validation indexes a primitive's accessors without checking them
        // (a file without an `accessors` array panics there): check those indices first.
        let accessor_count = root.accessors.len();
        for (m, mesh) in root.meshes.iter().enumerate() {
            for (p, prim) in mesh.primitives.iter().enumerate() {
                let used = prim
                    .attributes
                    .iter()
                    .map(|(semantic, index)| (format!("attributes.{semantic:?}"), index.value()))
                    .chain(
                        prim.indices
                            .iter()
                            .map(|index| ("indices".to_string(), index.value())),
                    );
                for (what, index) in used {
                    if index >= accessor_count {
                        return Err(SceneError::Validation {
                            file: path,
                            reason: format!(
                                "meshes[{m}].primitives[{p}].{what}: accessor {index} is out of bounds (the file has {accessor_count} accessors)"
                            ),
                        });
                    }
                }
            }
        }
        // Draco primitives: which accessors their streams fill (those have no bufferView).
        let mut draco_accessors = HashMap::new();
        for (m, mesh) in root.meshes.iter().enumerate() {
            for (p, prim) in mesh.primitives.iter().enumerate() {
                let Some(ext) = prim
                    .extensions
                    .as_ref()
                    .and_then(|e| e.others.get("KHR_draco_mesh_compression"))
                else {
                    continue;
                };
                let at =
                    format!("meshes[{m}].primitives[{p}].extensions.KHR_draco_mesh_compression");
                let verr = |reason: String| SceneError::Validation {
                    file: path.clone(),
                    reason: format!("{at}: {reason}"),
                };
                let d = DracoPrimitive::parse(ext).map_err(verr)?;
                if d.buffer_view >= root.buffer_views.len() {
                    return Err(verr(format!("bufferView {} does not exist", d.buffer_view)));
                }
                let mut parts: Vec<(usize, DracoPart)> = Vec::new();
                for (semantic, id) in &d.attributes {
                    if let Some((_, acc)) = prim
                        .attributes
                        .iter()
                        .find(|(k, _)| k.to_string() == *semantic)
                    {
                        parts.push((acc.value(), DracoPart::Attribute(*id)));
                    }
                }
                if let Some(acc) = &prim.indices {
                    parts.push((acc.value(), DracoPart::Indices));
                }
                for (acc, part) in parts {
                    let has_view = root
                        .accessors
                        .get(acc)
                        .is_some_and(|a| a.buffer_view.is_some());
                    if has_view {
                        continue; // uncompressed fallback data: read as it is
                    }
                    if let Some(&old) = draco_accessors.get(&acc) {
                        if old != (d.buffer_view, part) {
                            return Err(verr(format!(
                                "accessor {acc} is filled by two different Draco streams or attributes"
                            )));
                        }
                    }
                    draco_accessors.insert(acc, (d.buffer_view, part));
                }
            }
        }
        // The crate's validation, less the POSITION min/max requirement, which many exporters
        // ignore and this loader does not need, and less its check of `extensionsRequired`
        // (done above).
        let mut errors = Vec::new();
        {
            use gltf::json::validation::{Error as VError, Validate};
            root.validate(&root, gltf::json::Path::new, &mut |path, error| {
                let p = path();
                let minmax = p.as_str().ends_with(".min") || p.as_str().ends_with(".max");
                let required = p.as_str().starts_with("extensionsRequired");
                let draco = draco_accessors
                    .keys()
                    .any(|a| p.as_str() == format!("accessors[{a}].bufferView"));
                let skipped = match error {
                    VError::Missing => minmax || draco,
                    VError::Unsupported => required,
                    _ => false,
                };
                if !skipped {
                    errors.push(format!("{p}: {error}"));
                }
            });
        }
        if !errors.is_empty() {
            return Err(SceneError::Validation {
                file: path,
                reason: errors.join("; "),
            });
        }
        let document = gltf::Document::from_json_without_validation(root);
        let base_dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
        let buffers = vec![None; document.buffers().len()];
        Ok(GltfSource {
            file: path,
            base_dir,
            document,
            warnings,
            blob,
            buffers,
            decoded: HashMap::new(),
            draco_accessors,
            draco_meshes: HashMap::new(),
        })
    }

    fn buffer_error(&self, buffer: usize, reason: impl Into<String>) -> SceneError {
        SceneError::Buffer {
            file: self.file.clone(),
            buffer,
            reason: reason.into(),
        }
    }

    /// The bytes of buffer `index`, loaded on first use and checked against `byteLength`.
    pub fn buffer(&mut self, index: usize) -> Result<&[u8], SceneError> {
        if index >= self.buffers.len() {
            return Err(self.buffer_error(index, "no such buffer"));
        }
        if self.buffers[index].is_none() {
            let buffer = self.document.buffers().nth(index).expect("index checked");
            let bytes = match buffer.source() {
                gltf::buffer::Source::Bin => match &self.blob {
                    Some(b) => b.clone(),
                    None => {
                        return Err(self.buffer_error(
                            index,
                            "refers to the GLB binary chunk, which is absent",
                        ))
                    }
                },
                gltf::buffer::Source::Uri(uri) => self.read_uri(uri).map_err(|e| match e {
                    UriError::Io(missing, source) => SceneError::MissingBuffer {
                        file: self.file.clone(),
                        buffer: index,
                        missing,
                        source,
                    },
                    UriError::Other(reason) => self.buffer_error(index, reason),
                })?,
            };
            if bytes.len() < buffer.length() {
                return Err(self.buffer_error(
                    index,
                    format!(
                        "byteLength is {} but only {} bytes are present",
                        buffer.length(),
                        bytes.len()
                    ),
                ));
            }
            self.buffers[index] = Some(bytes);
        }
        Ok(self.buffers[index].as_deref().expect("just loaded"))
    }

    /// Bytes of buffer view `view`, bounds-checked; decoded first when the view is compressed
    /// with `EXT_meshopt_compression`.
    pub fn view_bytes(&mut self, view: &gltf::buffer::View) -> Result<&[u8], SceneError> {
        if let Some(ext) = view.extension_value("EXT_meshopt_compression") {
            let ext = ext.clone();
            return self.meshopt_view(view, &ext);
        }
        let (buffer, offset, length) = (view.buffer().index(), view.offset(), view.length());
        let declared = view.buffer().length();
        let available = self.buffer(buffer)?.len();
        let end = offset
            .checked_add(length)
            .filter(|&e| e <= available && e <= declared);
        match end {
            Some(end) => Ok(&self.buffer(buffer)?[offset..end]),
            None => Err(SceneError::Buffer {
                file: self.file.clone(),
                buffer,
                reason: format!(
                    "buffer view {} (offset {offset}, length {length}) runs past the buffer's {declared} bytes",
                    view.index()
                ),
            }),
        }
    }

    /// The decoded bytes of a view compressed with `EXT_meshopt_compression`, decoded once.
    fn meshopt_view(
        &mut self,
        view: &gltf::buffer::View,
        ext: &gltf::json::Value,
    ) -> Result<&[u8], SceneError> {
        let index = view.index();
        if !self.decoded.contains_key(&index) {
            let err = |file: &Path, reason: String| SceneError::Validation {
                file: file.to_path_buf(),
                reason: format!(
                    "bufferViews[{index}].extensions.EXT_meshopt_compression: {reason}"
                ),
            };
            let m = MeshoptView::parse(ext).map_err(|r| err(&self.file, r))?;
            if m.decoded_len() < view.length() {
                return Err(err(
                    &self.file,
                    format!(
                        "count {} × byteStride {} = {} bytes is less than the view's byteLength {}",
                        m.count,
                        m.byte_stride,
                        m.decoded_len(),
                        view.length()
                    ),
                ));
            }
            if m.buffer >= self.buffers.len() {
                return Err(err(
                    &self.file,
                    format!("buffer {} does not exist", m.buffer),
                ));
            }
            let data = self.buffer(m.buffer)?;
            let Some(compressed) = m
                .byte_offset
                .checked_add(m.byte_length)
                .and_then(|end| data.get(m.byte_offset..end))
            else {
                let n = data.len();
                return Err(err(
                    &self.file,
                    format!(
                        "byteOffset {} + byteLength {} runs past buffer {} ({n} bytes)",
                        m.byte_offset, m.byte_length, m.buffer
                    ),
                ));
            };
            let bytes = m.decode(compressed).map_err(|r| err(&self.file, r))?;
            self.decoded.insert(index, bytes);
        }
        Ok(&self.decoded[&index][..view.length()])
    }

    /// For an accessor that a `KHR_draco_mesh_compression` stream fills: its elements, tightly
    /// packed in the accessor's layout (f32 components for attributes). `None` for any other
    /// accessor.
    pub fn draco_bytes(
        &mut self,
        accessor: &gltf::Accessor,
    ) -> Result<Option<Vec<u8>>, SceneError> {
        let Some(&(view_index, part)) = self.draco_accessors.get(&accessor.index()) else {
            return Ok(None);
        };
        let err = |file: &Path, reason: String| SceneError::Accessor {
            file: file.to_path_buf(),
            accessor: accessor.index(),
            reason: format!("KHR_draco_mesh_compression: {reason}"),
        };
        let ty = accessor.data_type();
        let index_size = match part {
            DracoPart::Attribute(_) if ty != gltf::accessor::DataType::F32 => {
                return Err(err(
                    &self.file,
                    format!(
                    "component type {ty:?}: only float attributes are decoded from Draco streams"
                ),
                ))
            }
            DracoPart::Attribute(_) => 4,
            DracoPart::Indices => ty.size(),
        };
        if !self.draco_meshes.contains_key(&view_index) {
            let document = self.document.clone();
            let view = document.views().nth(view_index).expect("checked in open");
            let mesh = DracoMesh::decode(self.view_bytes(&view)?)
                .map_err(|r| err(&self.file, format!("bufferView {view_index}: {r}")))?;
            self.draco_meshes.insert(view_index, mesh);
        }
        let components = crate::accessor::dims_count(accessor.dimensions());
        self.draco_meshes[&view_index]
            .bytes(part, accessor.count(), components, index_size)
            .map(Some)
            .map_err(|r| err(&self.file, r))
    }

    /// The files the document's buffers and images name by URI (not `data:` URIs), as
    /// [`GltfSource::read_uri`] resolves them.
    pub fn referenced_files(&self) -> Vec<PathBuf> {
        let buffers = self.document.buffers().filter_map(|b| match b.source() {
            gltf::buffer::Source::Uri(uri) => Some(uri),
            gltf::buffer::Source::Bin => None,
        });
        let images = self
            .document
            .as_json()
            .images
            .iter()
            .filter_map(|i| i.uri.as_deref());
        buffers
            .chain(images)
            .filter(|uri| !uri.starts_with("data:") && !uri.contains("://"))
            .map(|uri| self.base_dir.join(percent_decode(uri)))
            .collect()
    }

    /// Reads a URI relative to the asset: a `data:` URI or a (percent-encoded) relative path.
    pub fn read_uri(&self, uri: &str) -> Result<Vec<u8>, UriError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (meta, payload) = rest
                .split_once(',')
                .ok_or_else(|| UriError::Other("data URI without ','".into()))?;
            if meta.ends_with(";base64") {
                decode_base64(payload).map_err(UriError::Other)
            } else {
                Ok(percent_decode(payload).into_bytes())
            }
        } else if uri.contains("://") {
            Err(UriError::Other(format!(
                "unsupported URI scheme in '{uri}' (only relative paths and data URIs)"
            )))
        } else {
            let path = self.base_dir.join(percent_decode(uri));
            crate::files::read_regular_file(&path, crate::files::MAX_INPUT_FILE_BYTES)
                .map_err(|e| UriError::Io(path, e))
        }
    }
}

/// Failure to read a URI: a missing or unreadable file, or a malformed URI.
#[derive(Debug)]
pub enum UriError {
    Io(PathBuf, std::io::Error),
    Other(String),
}

impl std::fmt::Display for UriError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            UriError::Io(p, e) => write!(f, "cannot read {}: {e}", p.display()),
            UriError::Other(s) => f.write_str(s),
        }
    }
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok());
            if let Some(v) = hex {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard (RFC 4648) base64 with optional padding; whitespace is ignored.
pub fn decode_base64(s: &str) -> Result<Vec<u8>, String> {
    fn val(c: u8) -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        } as u32)
    }
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    let mut padding = false;
    for (i, &c) in s.as_bytes().iter().enumerate() {
        if c.is_ascii_whitespace() {
            continue;
        }
        if c == b'=' {
            padding = true;
            continue;
        }
        if padding {
            return Err(format!(
                "invalid base64: data after padding at character {i}"
            ));
        }
        let v = val(c).ok_or_else(|| format!("invalid base64 character {:?} at {i}", c as char))?;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    if bits >= 6 {
        return Err("invalid base64: truncated final group".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_vectors() {
        assert_eq!(decode_base64("").unwrap(), b"");
        assert_eq!(decode_base64("Zg==").unwrap(), b"f");
        assert_eq!(decode_base64("Zm8=").unwrap(), b"fo");
        assert_eq!(decode_base64("Zm9v").unwrap(), b"foo");
        assert_eq!(decode_base64("Zm9vYmFy").unwrap(), b"foobar");
        assert!(decode_base64("Zm9v!").is_err());
        assert!(decode_base64("Z").is_err());
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("100%"), "100%");
    }

    #[test]
    fn glb_split_rejects_truncation() {
        let json = br#"{"asset":{"version":"2.0"}}  "#; // 28 bytes, 4-aligned
        let mut glb = Vec::new();
        glb.extend_from_slice(b"glTF");
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&((12 + 8 + json.len()) as u32).to_le_bytes());
        glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
        glb.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        glb.extend_from_slice(json);
        let (j, b) = split_glb(&glb).unwrap();
        assert_eq!(j, json);
        assert!(b.is_none());
        for n in 0..glb.len() {
            assert!(
                split_glb(&glb[..n]).is_err(),
                "prefix of {n} bytes accepted"
            );
        }
    }
}
