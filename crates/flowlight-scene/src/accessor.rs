//! Validated reading of glTF accessors: every offset, stride and count is checked against the
//! buffer view and buffer before a byte is read, so malformed files give errors, not panics.
//!
//! Component types (glTF 2.0 §3.6.2, and `KHR_mesh_quantization`, which allows byte and short
//! POSITION, NORMAL, TANGENT and TEXCOORD): float as it is; a `normalized` integer c with b
//! bits maps to c / (2^b − 1) when unsigned and max(c / (2^(b−1) − 1), −1) when signed, so
//! −128 and −127 both give −1; a non-normalized integer is its plain value (a quantized
//! position is dequantized by its node's transform). An accessor without a buffer view is
//! zeros, unless a `KHR_draco_mesh_compression` stream fills it ([`GltfSource::draco_bytes`]);
//! a view compressed with `EXT_meshopt_compression` is decoded by [`GltfSource::view_bytes`].

use crate::error::SceneError;
use crate::source::GltfSource;
use gltf::accessor::{DataType, Dimensions};

/// Components per element.
pub fn dims_count(d: Dimensions) -> usize {
    match d {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        Dimensions::Mat2 => 4,
        Dimensions::Mat3 => 9,
        Dimensions::Mat4 => 16,
    }
}

fn accessor_error(
    src: &GltfSource,
    accessor: &gltf::Accessor,
    reason: impl Into<String>,
) -> SceneError {
    SceneError::Accessor {
        file: src.file.clone(),
        accessor: accessor.index(),
        reason: reason.into(),
    }
}

/// Reads one component at `bytes[0..size]` as f32, applying normalisation when asked.
fn component(bytes: &[u8], ty: DataType, normalized: bool) -> f32 {
    match ty {
        DataType::F32 => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
        DataType::U8 => {
            let v = bytes[0] as f32;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::I8 => {
            let v = bytes[0] as i8 as f32;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([bytes[0], bytes[1]]) as f32;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([bytes[0], bytes[1]]) as f32;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U32 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f32,
    }
}

fn component_u32(bytes: &[u8], ty: DataType) -> u32 {
    match ty {
        DataType::U8 => bytes[0] as u32,
        DataType::U16 => u16::from_le_bytes([bytes[0], bytes[1]]) as u32,
        DataType::U32 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
        _ => 0,
    }
}

/// Reads the raw elements of `accessor` (dense part and sparse substitution) through `f`,
/// which receives each element's component bytes.
fn read_elements<T: Clone>(
    src: &mut GltfSource,
    accessor: &gltf::Accessor,
    zero: T,
    mut f: impl FnMut(&[u8]) -> T,
) -> Result<Vec<T>, SceneError> {
    let count = accessor.count();
    let comp = accessor.data_type().size();
    let elem = comp * dims_count(accessor.dimensions());
    let mut out = match accessor.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(accessor_error(
                    src,
                    accessor,
                    format!("byteStride {stride} is smaller than the element size {elem}"),
                ));
            }
            let offset = accessor.offset();
            if count > 0 {
                let needed = (count - 1)
                    .checked_mul(stride)
                    .and_then(|n| n.checked_add(offset))
                    .and_then(|n| n.checked_add(elem));
                if needed.is_none_or(|n| n > view.length()) {
                    return Err(accessor_error(
                        src,
                        accessor,
                        format!(
                            "{count} elements of {elem} bytes (stride {stride}) at offset {offset} run past buffer view {} ({} bytes)",
                            view.index(),
                            view.length()
                        ),
                    ));
                }
            }
            let bytes = src.view_bytes(&view)?;
            (0..count)
                .map(|i| f(&bytes[offset + i * stride..offset + i * stride + elem]))
                .collect()
        }
        None => match src.draco_bytes(accessor)? {
            // Filled by a KHR_draco_mesh_compression stream, tightly packed.
            Some(bytes) => bytes.chunks_exact(elem).map(&mut f).collect(),
            None => vec![zero; count],
        },
    };
    if let Some(sparse) = accessor.sparse() {
        let n = sparse.count();
        let idx = sparse.indices();
        let ity = match idx.index_type() {
            gltf::accessor::sparse::IndexType::U8 => DataType::U8,
            gltf::accessor::sparse::IndexType::U16 => DataType::U16,
            gltf::accessor::sparse::IndexType::U32 => DataType::U32,
        };
        let ibytes = src.view_bytes(&idx.view())?.to_vec();
        let ioff = idx.offset();
        let vals = sparse.values();
        let vbytes = src.view_bytes(&vals.view())?.to_vec();
        let voff = vals.offset();
        let isz = ity.size();
        if n.checked_mul(isz)
            .and_then(|x| x.checked_add(ioff))
            .is_none_or(|x| x > ibytes.len())
            || n.checked_mul(elem)
                .and_then(|x| x.checked_add(voff))
                .is_none_or(|x| x > vbytes.len())
        {
            return Err(accessor_error(
                src,
                accessor,
                "sparse indices or values run past their buffer views",
            ));
        }
        for k in 0..n {
            let i = component_u32(&ibytes[ioff + k * isz..], ity) as usize;
            if i >= count {
                return Err(accessor_error(
                    src,
                    accessor,
                    format!("sparse index {i} out of range (count {count})"),
                ));
            }
            out[i] = f(&vbytes[voff + k * elem..voff + (k + 1) * elem]);
        }
    }
    Ok(out)
}

/// Reads a float attribute with `N` components (VEC2 or VEC3), accepting f32 and normalised
/// integer component types.
pub fn read_floats<const N: usize>(
    src: &mut GltfSource,
    accessor: &gltf::Accessor,
) -> Result<Vec<[f32; N]>, SceneError> {
    if dims_count(accessor.dimensions()) != N || matches!(accessor.dimensions(), Dimensions::Mat2) {
        return Err(accessor_error(
            src,
            accessor,
            format!("expected {N} components, found {:?}", accessor.dimensions()),
        ));
    }
    let ty = accessor.data_type();
    let normalized = accessor.normalized();
    if ty == DataType::U32 {
        return Err(accessor_error(
            src,
            accessor,
            "unsigned int components are not allowed for vertex attributes",
        ));
    }
    let size = ty.size();
    read_elements(src, accessor, [0.0; N], |b| {
        std::array::from_fn(|c| component(&b[c * size..], ty, normalized))
    })
}

/// Reads an index accessor (SCALAR of unsigned byte, short or int).
pub fn read_indices(
    src: &mut GltfSource,
    accessor: &gltf::Accessor,
) -> Result<Vec<u32>, SceneError> {
    let ty = accessor.data_type();
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(accessor_error(
            src,
            accessor,
            format!("indices must be SCALAR, found {:?}", accessor.dimensions()),
        ));
    }
    if !matches!(ty, DataType::U8 | DataType::U16 | DataType::U32) {
        return Err(accessor_error(
            src,
            accessor,
            format!("indices must be unsigned integers, found component type {ty:?}"),
        ));
    }
    read_elements(src, accessor, 0u32, |b| component_u32(b, ty))
}
