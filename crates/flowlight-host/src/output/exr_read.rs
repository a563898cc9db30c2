//! Reading EXR files back: the RGB layers, the integer channels and the string attributes
//! of what [`super::exr`] writes (and of any scan-line OpenEXR file with `R,G,B` channels):
//! `flowlight compare`, the merge of distributed parts and the tests read images this way.

use std::collections::BTreeMap;
use std::path::Path;

use exr::prelude::{AttributeValue, FlatSamples, Vec2};
use flowlight_core::spectrum::Rgb;

use super::exr::text_to_string;
use super::{ExrMetadata, OutputError};

/// Integer channels by name, as [`read_exr_u32`] returns them.
pub type U32Channels = BTreeMap<String, Vec<u32>>;

/// Refuses an EXR whose headers claim more pixels than the file or this process's memory
/// can hold, before the decoder allocates them: a 1 KB file whose header claims
/// 100000×100000 made the decoder abort on a 160 GB allocation. The file must hold at least
/// its offset tables (8 bytes a chunk), and the samples decoded (with the copies the
/// readers make) must fit in the memory available.
pub fn check_exr_size(path: &Path) -> Result<(), OutputError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|source| {
        OutputError::ExrDecode {
            path: path.to_owned(),
            source,
        }
    })?;
    let file_len = std::fs::metadata(path)
        .map_err(|source| OutputError::Io {
            path: path.to_owned(),
            source,
        })?
        .len();
    let (mut chunks, mut bytes) = (0u64, 0u64);
    for h in &meta.headers {
        let pixels = h.layer_size.0 as u64 * h.layer_size.1 as u64;
        chunks = chunks.saturating_add(h.chunk_count as u64);
        bytes = bytes.saturating_add(pixels.saturating_mul(h.channels.bytes_per_pixel as u64));
    }
    let size = meta
        .headers
        .first()
        .map_or((0, 0), |h| (h.layer_size.0, h.layer_size.1));
    let unsupported = |reason: String| OutputError::Unsupported {
        path: path.to_owned(),
        reason,
    };
    if chunks.saturating_mul(8) > file_len {
        return Err(unsupported(format!(
            "its header claims {}x{} pixels in {chunks} chunks, but the file's {file_len} bytes cannot even hold their offset table: it is truncated or corrupt",
            size.0, size.1
        )));
    }
    // The decoded samples, their f32 copies and the RGB pixels: about three times the data.
    let need = bytes.saturating_mul(3);
    if let Some(avail) = flowlight_scene::memory::available_memory() {
        if need > avail {
            return Err(unsupported(format!(
                "its header claims {}x{} pixels, about {} MiB to decode, but {} MiB is available",
                size.0,
                size.1,
                need >> 20,
                avail >> 20
            )));
        }
    }
    Ok(())
}

/// The 32-bit unsigned integer channels of an EXR file ([`RawChannel`](super::RawChannel)) as
/// `(width, height, name → samples)`; float channels are skipped.
pub fn read_exr_u32(path: &Path) -> Result<(usize, usize, U32Channels), OutputError> {
    use exr::prelude::traits::*;
    check_exr_size(path)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|source| OutputError::ExrDecode {
            path: path.to_owned(),
            source,
        })?;
    let layer = &image.layer_data;
    let mut out = BTreeMap::new();
    for channel in &layer.channel_data.list {
        if let FlatSamples::U32(v) = &channel.sample_data {
            out.insert(text_to_string(&channel.name), v.clone());
        }
    }
    Ok((layer.size.0, layer.size.1, out))
}

/// Layers as read back: `(layer name, width * height pixels)`, main layer (`""`) first.
pub type NamedLayers = Vec<(String, Vec<Rgb>)>;

/// Reads every RGB layer of an EXR file as `(width, height, [(layer name, pixels)])`.
///
/// Channels are grouped by the text before their last `.` (`R,G,B` → layer `""`,
/// `layer1.R,...` → `"layer1"`); in multi-part files the part name is prepended
/// (`part.layer`). Channels other than `R`, `G`, `B` (alpha, depth, ...) are ignored. The
/// main layer `""` comes first, the others follow sorted by name. Half and uint samples are
/// converted to `f32`.
pub fn read_exr_rgb(path: &Path) -> Result<(usize, usize, NamedLayers), OutputError> {
    use exr::prelude::traits::*;
    check_exr_size(path)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|source| OutputError::ExrDecode {
            path: path.to_owned(),
            source,
        })?;

    let unsupported = |reason: String| OutputError::Unsupported {
        path: path.to_owned(),
        reason,
    };
    let first = image
        .layer_data
        .first()
        .ok_or_else(|| unsupported("file has no parts".to_owned()))?;
    let size = first.size;
    let (width, height) = (size.0, size.1);
    let count = width * height;

    // layer name -> [R, G, B] samples
    let mut groups: BTreeMap<String, [Option<Vec<f32>>; 3]> = BTreeMap::new();
    for part in &image.layer_data {
        if part.size != size {
            return Err(unsupported(format!(
                "parts differ in size ({}x{} vs {}x{})",
                part.size.0, part.size.1, width, height
            )));
        }
        let part_name = part.attributes.layer_name.as_ref().map(text_to_string);
        for channel in &part.channel_data.list {
            let full = text_to_string(&channel.name);
            let (prefix, suffix) = match full.rfind('.') {
                Some(i) => (&full[..i], &full[i + 1..]),
                None => ("", full.as_str()),
            };
            let index = match suffix {
                "R" => 0,
                "G" => 1,
                "B" => 2,
                _ => continue,
            };
            if channel.sampling != Vec2(1, 1) {
                return Err(unsupported(format!("channel {full:?} is subsampled")));
            }
            let layer = match (&part_name, prefix) {
                (Some(p), "") if !p.is_empty() => p.clone(),
                (Some(p), q) if !p.is_empty() => format!("{p}.{q}"),
                _ => prefix.to_owned(),
            };
            let samples: Vec<f32> = channel.sample_data.values_as_f32().collect();
            if samples.len() != count {
                return Err(unsupported(format!(
                    "channel {full:?} has {} samples",
                    samples.len()
                )));
            }
            let slot = &mut groups.entry(layer.clone()).or_default()[index];
            if slot.is_some() {
                return Err(unsupported(format!(
                    "layer {layer:?} has channel {suffix} twice"
                )));
            }
            *slot = Some(samples);
        }
    }

    let mut layers = Vec::with_capacity(groups.len());
    for (name, [r, g, b]) in groups {
        let (Some(r), Some(g), Some(b)) = (r, g, b) else {
            return Err(unsupported(format!("layer {name:?} lacks one of R, G, B")));
        };
        let pixels = (0..count).map(|i| Rgb::new(r[i], g[i], b[i])).collect();
        layers.push((name, pixels));
    }
    // BTreeMap order puts "" first already; the rest are sorted by name.
    Ok((width, height, layers))
}

/// Reads the string attributes of an EXR file (everything [`write_exr`](super::write_exr) writes from
/// [`ExrMetadata`], plus `software`, `comments`, `owner`, `capDate` when present), sorted by
/// key. In multi-part files the first part's attributes are returned.
pub fn read_exr_metadata(path: &Path) -> Result<ExrMetadata, OutputError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|source| {
        OutputError::ExrDecode {
            path: path.to_owned(),
            source,
        }
    })?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| OutputError::Unsupported {
            path: path.to_owned(),
            reason: "file has no parts".to_owned(),
        })?;
    let mut entries = BTreeMap::new();
    let own = &header.own_attributes;
    for (key, value) in [
        ("software", &own.software_name),
        ("comments", &own.comments),
        ("owner", &own.owner),
        ("capDate", &own.capture_date),
    ] {
        if let Some(value) = value {
            entries.insert(key.to_owned(), text_to_string(value));
        }
    }
    for (key, value) in own
        .other
        .iter()
        .chain(header.shared_attributes.other.iter())
    {
        if let AttributeValue::Text(value) = value {
            entries.insert(text_to_string(key), text_to_string(value));
        }
    }
    Ok(ExrMetadata {
        entries: entries.into_iter().collect(),
    })
}
