//! Image output: multi-layer OpenEXR (the render result) and an 8-bit sRGB PNG preview.
//!
//! # EXR layout
//!
//! Every file is a **single-part, scan-line OpenEXR** with 32-bit float channels and lossless
//! ZIP compression (16 scan lines per block). Layers are expressed with the OpenEXR
//! channel-naming convention rather than as separate parts:
//!
//! * the main image (`ImageLayer { name: "" }`) is stored as channels `R`, `G`, `B`;
//! * every other layer `name` is stored as `name.R`, `name.G`, `name.B`.
//!
//! This is the layout Blender's multilayer EXR, Nuke, tev and OpenImageIO all group into
//! layers (OpenImageIO reports one subimage with channels `R,G,B,layer1.R,...`), and unlike
//! multi-part files it is read by every OpenEXR reader, including old ones. There is no
//! `chromaticities` attribute: per the OpenEXR specification that means Rec.709 primaries
//! with a D65 white point, which is what [`Rgb`] holds. Pixels are row-major, top row first
//! (pixel `(x, y)` is `pixels[y * width + x]`), written with increasing line order.
//!
//! Metadata entries ([`ExrMetadata`]) are written as header attributes of type `string`
//! (values as UTF-8 bytes). The standard text attributes `software`, `comments`, `owner` and
//! `capDate` may be set through it as well; any other standard OpenEXR attribute name is
//! rejected, since it would collide with (or be mis-typed as) a structural attribute.
//!
//! # Safety of existing files
//!
//! Both writers go through [`write_atomically`]: the data are written to a temporary file in
//! the destination directory, flushed to disk, then renamed over the destination. A failed
//! write therefore never leaves a truncated image behind nor damages an existing one. All
//! input is validated (sizes, finiteness, names) before anything touches the file system.

use std::collections::{BTreeMap, HashSet};
use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Blocks, Compression, Encoding, FlatSamples, Image,
    Layer, LayerAttributes, LineOrder, Text, Vec2, WritableImage,
};
use flowlight_core::spectrum::Rgb;

/// One RGB layer of an EXR file. `name == ""` is the main image (channels `R,G,B`); any
/// other name `n` is stored as channels `n.R`, `n.G`, `n.B`.
#[derive(Clone, Debug)]
pub struct ImageLayer<'a> {
    pub name: String,
    /// `width * height` pixels, row-major, top row first.
    pub pixels: &'a [Rgb],
}

/// One RGB layer of an EXR file as owned planar channels (`r`, `g`, `b`, each `width *
/// height` samples, row-major, top row first): handed to the encoder without a copy.
#[derive(Clone, Debug)]
pub struct PlanarLayer {
    pub name: String,
    pub channels: [Vec<f32>; 3],
}

/// The EXR layers of a frame: the main image (unnamed) then `layer0`, `layer1`, … over
/// `layers` (the frame's per-depth lighting layers, already resolved to pixels).
pub fn frame_layers<'a>(image: &'a [Rgb], layers: &'a [Vec<Rgb>]) -> Vec<ImageLayer<'a>> {
    let mut out = vec![ImageLayer {
        name: String::new(),
        pixels: image,
    }];
    out.extend(layers.iter().enumerate().map(|(k, l)| ImageLayer {
        name: format!("layer{k}"),
        pixels: l,
    }));
    out
}

/// String attributes written into the EXR header (e.g. `integrator`, `spp`, `seed`,
/// `biased`). Keys must be unique, non-empty, free of NUL bytes and not a structural OpenEXR
/// attribute name (see the module documentation).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExrMetadata {
    pub entries: Vec<(String, String)>,
}

impl ExrMetadata {
    /// The value of attribute `key`, if the header has it.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// Everything that can go wrong while writing or reading an image. Every variant names the
/// file it concerns.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("cannot create directory {dir} for {path}: {source}")]
    CreateDir {
        path: PathBuf,
        dir: PathBuf,
        source: io::Error,
    },

    #[error("cannot write {path}: {source}")]
    Io { path: PathBuf, source: io::Error },

    #[error("cannot encode EXR {path}: {source}")]
    ExrEncode {
        path: PathBuf,
        source: exr::error::Error,
    },

    #[error("cannot read EXR {path}: {source}")]
    ExrDecode {
        path: PathBuf,
        source: exr::error::Error,
    },

    #[error("cannot encode PNG {path}: {source}")]
    PngEncode {
        path: PathBuf,
        source: png::EncodingError,
    },

    #[error("invalid image size {width}x{height} for {path}")]
    InvalidSize {
        path: PathBuf,
        width: usize,
        height: usize,
    },

    #[error(
        "layer {layer:?} of {path} has {actual} pixels, expected {expected} ({width}x{height})"
    )]
    PixelCount {
        path: PathBuf,
        layer: String,
        width: usize,
        height: usize,
        expected: usize,
        actual: usize,
    },

    #[error("layer {layer:?} of {path} has a non-finite (NaN or infinite) pixel at ({x}, {y})")]
    NonFinite {
        path: PathBuf,
        layer: String,
        x: usize,
        y: usize,
    },

    #[error("invalid layer name {layer:?} for {path}: {reason}")]
    InvalidLayer {
        path: PathBuf,
        layer: String,
        reason: String,
    },

    #[error("invalid metadata key {key:?} for {path}: {reason}")]
    InvalidMetadata {
        path: PathBuf,
        key: String,
        reason: String,
    },

    #[error("unsupported EXR content in {path}: {reason}")]
    Unsupported { path: PathBuf, reason: String },
}

/// Standard OpenEXR attribute names that user metadata must not use.
const RESERVED_ATTRIBUTES: &[&str] = &[
    "tiles",
    "name",
    "type",
    "version",
    "chunkCount",
    "maxSamplesPerPixel",
    "channels",
    "compression",
    "dataWindow",
    "displayWindow",
    "lineOrder",
    "pixelAspectRatio",
    "screenWindowCenter",
    "screenWindowWidth",
    "whiteLuminance",
    "adoptedNeutral",
    "renderingTransform",
    "lookModTransform",
    "xDensity",
    "utcOffset",
    "longitude",
    "latitude",
    "altitude",
    "focus",
    "expTime",
    "aperture",
    "isoSpeed",
    "envmap",
    "keyCode",
    "timeCode",
    "wrapmodes",
    "framesPerSecond",
    "multiView",
    "worldToCamera",
    "worldToNDC",
    "deepImageState",
    "originalDataWindow",
    "dwaCompressionLevel",
    "preview",
    "view",
    "chromaticities",
    "near",
    "far",
    "fieldOfViewHorizontal",
    "fieldOfViewVertical",
];

fn text(s: &str) -> Text {
    // OpenEXR strings are byte strings; store UTF-8 (what OpenEXR and its tools assume).
    Text::from_slice_unchecked(s.as_bytes())
}

fn text_to_string(t: &Text) -> String {
    match std::str::from_utf8(t.as_slice()) {
        Ok(s) => s.to_owned(),
        // Not UTF-8: treat as Latin-1, which every byte maps to.
        Err(_) => t.as_slice().iter().map(|&b| b as char).collect(),
    }
}

fn pixel_count(path: &Path, width: usize, height: usize) -> Result<usize, OutputError> {
    let invalid = || OutputError::InvalidSize {
        path: path.to_owned(),
        width,
        height,
    };
    if width == 0 || height == 0 || width > i32::MAX as usize || height > i32::MAX as usize {
        return Err(invalid());
    }
    width.checked_mul(height).ok_or_else(invalid)
}

fn check_pixels(
    path: &Path,
    layer: &str,
    width: usize,
    height: usize,
    pixels: &[Rgb],
) -> Result<(), OutputError> {
    let expected = pixel_count(path, width, height)?;
    if pixels.len() != expected {
        return Err(OutputError::PixelCount {
            path: path.to_owned(),
            layer: layer.to_owned(),
            width,
            height,
            expected,
            actual: pixels.len(),
        });
    }
    if let Some(i) = pixels.iter().position(|p| !p.is_finite()) {
        return Err(OutputError::NonFinite {
            path: path.to_owned(),
            layer: layer.to_owned(),
            x: i % width,
            y: i / width,
        });
    }
    Ok(())
}

fn check_layer_name(path: &Path, name: &str) -> Result<(), OutputError> {
    let invalid = |reason: &str| OutputError::InvalidLayer {
        path: path.to_owned(),
        layer: name.to_owned(),
        reason: reason.to_owned(),
    };
    if name.is_empty() {
        return Ok(());
    }
    if name.contains('\0') {
        return Err(invalid("contains a NUL byte"));
    }
    if name.starts_with('.') || name.ends_with('.') || name.contains("..") {
        return Err(invalid("empty component between '.' separators"));
    }
    Ok(())
}

/// One 32-bit unsigned integer channel written beside the RGB layers (the exact sums and
/// sample counts of a distributed render's part: [`crate::parts`]). Readers of the RGB
/// layers ignore it: its name ends in neither `R`, `G` nor `B`.
#[derive(Clone, Debug)]
pub struct RawChannel {
    pub name: String,
    /// `width * height` samples, row-major, top row first.
    pub samples: Vec<u32>,
}

/// Writes `layers` (each `width * height` pixels) as one multi-layer EXR, atomically.
///
/// Fails without touching the file system when a layer has the wrong pixel count, a pixel
/// is NaN or infinite ([`OutputError::NonFinite`]), layer names are invalid or duplicated,
/// or a metadata key is invalid. Missing parent directories are created.
pub fn write_exr(
    path: &Path,
    width: usize,
    height: usize,
    layers: &[ImageLayer],
    meta: &ExrMetadata,
) -> Result<(), OutputError> {
    write_exr_with_raw(path, width, height, layers, &[], meta)
}

/// [`write_exr`] with extra `u32` channels ([`RawChannel`]), e.g. a part's exact sums.
pub fn write_exr_with_raw(
    path: &Path,
    width: usize,
    height: usize,
    layers: &[ImageLayer],
    raw: &[RawChannel],
    meta: &ExrMetadata,
) -> Result<(), OutputError> {
    // Checked here with the pixel's position, before the channels are split.
    for layer in layers {
        check_pixels(path, &layer.name, width, height, layer.pixels)?;
    }
    let planar = layers
        .iter()
        .map(|l| PlanarLayer {
            name: l.name.clone(),
            channels: std::array::from_fn(|c| l.pixels.iter().map(|p| p.to_array()[c]).collect()),
        })
        .collect();
    write_exr_planar(path, width, height, planar, raw, meta)
}

/// Writes `layers` (owned planar channels) and `raw` as one multi-layer EXR, atomically,
/// encoding straight into the temporary file: besides the channels themselves, writing
/// needs only the encoder's chunk buffers (a 1080p image with 8 layers would otherwise hold
/// a second copy of its 224 MB).
///
/// Fails without touching the file system like [`write_exr`].
pub fn write_exr_planar(
    path: &Path,
    width: usize,
    height: usize,
    layers: Vec<PlanarLayer>,
    raw: &[RawChannel],
    meta: &ExrMetadata,
) -> Result<(), OutputError> {
    let count = pixel_count(path, width, height)?;
    for r in raw {
        let suffix = r.name.rsplit('.').next().unwrap_or("");
        if r.name.is_empty() || r.name.contains('\0') || ["R", "G", "B"].contains(&suffix) {
            return Err(OutputError::InvalidLayer {
                path: path.to_owned(),
                layer: r.name.clone(),
                reason: "integer channel names must not end in R, G or B".to_owned(),
            });
        }
        if r.samples.len() != count {
            return Err(OutputError::PixelCount {
                path: path.to_owned(),
                layer: r.name.clone(),
                width,
                height,
                expected: count,
                actual: r.samples.len(),
            });
        }
    }
    if layers.is_empty() {
        return Err(OutputError::InvalidLayer {
            path: path.to_owned(),
            layer: String::new(),
            reason: "no layers to write".to_owned(),
        });
    }
    let mut names = HashSet::new();
    for layer in &layers {
        check_layer_name(path, &layer.name)?;
        if !names.insert(layer.name.as_str()) {
            return Err(OutputError::InvalidLayer {
                path: path.to_owned(),
                layer: layer.name.clone(),
                reason: "duplicate layer name".to_owned(),
            });
        }
        for ch in &layer.channels {
            if ch.len() != count {
                return Err(OutputError::PixelCount {
                    path: path.to_owned(),
                    layer: layer.name.clone(),
                    width,
                    height,
                    expected: count,
                    actual: ch.len(),
                });
            }
        }
        let bad = (0..count).find(|&i| !layer.channels.iter().all(|ch| ch[i].is_finite()));
        if let Some(i) = bad {
            return Err(OutputError::NonFinite {
                path: path.to_owned(),
                layer: layer.name.clone(),
                x: i % width,
                y: i / width,
            });
        }
    }

    let mut attributes = LayerAttributes::default();
    let mut keys = HashSet::new();
    for (key, value) in &meta.entries {
        let invalid = |reason: &str| OutputError::InvalidMetadata {
            path: path.to_owned(),
            key: key.clone(),
            reason: reason.to_owned(),
        };
        if key.is_empty() {
            return Err(invalid("empty key"));
        }
        if key.contains('\0') {
            return Err(invalid("key contains a NUL byte"));
        }
        if key.len() > 255 {
            return Err(invalid("key longer than 255 bytes"));
        }
        if !keys.insert(key.as_str()) {
            return Err(invalid("duplicate key"));
        }
        if RESERVED_ATTRIBUTES.contains(&key.as_str()) {
            return Err(invalid("reserved OpenEXR attribute name"));
        }
        let value = text(value);
        match key.as_str() {
            "software" => attributes.software_name = Some(value),
            "comments" => attributes.comments = Some(value),
            "owner" => attributes.owner = Some(value),
            "capDate" => attributes.capture_date = Some(value),
            _ => {
                attributes
                    .other
                    .insert(text(key), AttributeValue::Text(value));
            }
        }
    }

    let mut channels = smallvec_of_channels(layers.len() * 3);
    for layer in layers {
        for (samples, suffix) in layer.channels.into_iter().zip(["R", "G", "B"]) {
            let name = if layer.name.is_empty() {
                suffix.to_owned()
            } else {
                format!("{}.{suffix}", layer.name)
            };
            channels.push(AnyChannel::new(text(&name), FlatSamples::F32(samples)));
        }
    }
    for r in raw {
        channels.push(AnyChannel::new(
            text(&r.name),
            FlatSamples::U32(r.samples.clone()),
        ));
    }

    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        Vec2(width, height),
        attributes,
        encoding,
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);

    let io_err = |source| OutputError::Io {
        path: path.to_owned(),
        source,
    };
    write_atomically(path, |tmp| {
        let file = fs::File::create(tmp).map_err(io_err)?;
        let mut out = BufWriter::new(file);
        image
            .write()
            .to_buffered(&mut out)
            .map_err(|source| OutputError::ExrEncode {
                path: path.to_owned(),
                source,
            })?;
        out.flush().map_err(io_err)?;
        drop(out);
        // Put the header's attributes in name order (the exr crate keeps them in a HashMap,
        // whose order changes from run to run): in place, the header keeps its length.
        sort_header_in_file(tmp).map_err(|reason| match reason {
            Ok(source) => io_err(source),
            Err(reason) => OutputError::Unsupported {
                path: path.to_owned(),
                reason,
            },
        })
    })
}

/// [`sort_header_attributes`] on the header at the start of file `path`, rewritten in place.
/// `Err(Ok(_))` for an I/O error, `Err(Err(reason))` for a file it cannot parse.
fn sort_header_in_file(path: &Path) -> Result<(), Result<io::Error, String>> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(Ok)?;
    let len = f.metadata().map_err(Ok)?.len();
    // The header (magic, version, attributes) is small; the metadata strings are its bulk.
    let mut head = vec![0u8; len.min(16 << 20) as usize];
    f.read_exact(&mut head).map_err(Ok)?;
    sort_header_attributes(&mut head).map_err(Err)?;
    f.seek(SeekFrom::Start(0)).map_err(Ok)?;
    f.write_all(&head).map_err(Ok)?;
    Ok(())
}

/// Rewrites the header of a single-part EXR file so that its attributes follow in byte order
/// of their names. The header keeps its length, so the offset table after it stays valid;
/// identical images with identical metadata then give identical files.
///
/// Header layout (OpenEXR file layout, "Header"): magic (4 bytes), version (4), then
/// attributes `name\0 type\0 size:i32le value[size]`, ended by a single `\0`.
pub fn sort_header_attributes(file: &mut [u8]) -> Result<(), String> {
    const START: usize = 8;
    if file.len() < START || file[..4] != [0x76, 0x2f, 0x31, 0x01] {
        return Err("not an OpenEXR file".into());
    }
    if file[5] & 0x10 != 0 {
        return Err("multi-part header ordering is not supported".into());
    }
    let mut attrs: Vec<(Vec<u8>, std::ops::Range<usize>)> = Vec::new();
    let mut at = START;
    let cstr = |from: usize| -> Result<usize, String> {
        file.get(from..)
            .and_then(|r| r.iter().position(|&b| b == 0))
            .map(|n| from + n)
            .ok_or_else(|| "unterminated attribute name".to_string())
    };
    loop {
        match file.get(at) {
            None => return Err("header without end".into()),
            Some(0) => break,
            Some(_) => {}
        }
        let name_end = cstr(at)?;
        let type_end = cstr(name_end + 1)?;
        let size_at = type_end + 1;
        let size = file
            .get(size_at..size_at + 4)
            .map(|b| i32::from_le_bytes(b.try_into().unwrap()))
            .ok_or("attribute size past the end")?;
        let end = usize::try_from(size)
            .ok()
            .and_then(|n| (size_at + 4).checked_add(n))
            .filter(|&e| e <= file.len())
            .ok_or("attribute value past the end")?;
        attrs.push((file[at..name_end].to_vec(), at..end));
        at = end;
    }
    let mut sorted = attrs.clone();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    let mut header = Vec::with_capacity(at - START);
    for (_, r) in &sorted {
        header.extend_from_slice(&file[r.clone()]);
    }
    file[START..at].copy_from_slice(&header);
    Ok(())
}

fn smallvec_of_channels(capacity: usize) -> exr::prelude::SmallVec<[AnyChannel<FlatSamples>; 4]> {
    exr::prelude::SmallVec::with_capacity(capacity)
}

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
    let file_len = fs::metadata(path)
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

/// The 32-bit unsigned integer channels of an EXR file ([`RawChannel`]) as
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

/// Reads the string attributes of an EXR file (everything [`write_exr`] writes from
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

/// sRGB opto-electronic transfer function (IEC 61966-2-1), for `v` in `[0, 1]`.
fn srgb_oetf(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Maps a linear value to an 8-bit sRGB code: `× scale`, clamp to `[0, 1]`, OETF, round.
fn to_srgb8(v: f32, scale: f32) -> u8 {
    let v = (v * scale).clamp(0.0, 1.0);
    (srgb_oetf(v) * 255.0 + 0.5).floor() as u8
}

/// Writes an 8-bit sRGB PNG preview of linear `pixels`: each channel is multiplied by
/// `2^exposure`, clamped to `[0, 1]`, encoded with the sRGB OETF and rounded. The file is
/// tagged with an sRGB chunk and written atomically; parent directories are created.
/// Non-finite pixels (and a non-finite exposure) are rejected like in [`write_exr`]
/// (the layer is reported as `""`).
pub fn write_png_preview(
    path: &Path,
    width: usize,
    height: usize,
    pixels: &[Rgb],
    exposure: f32,
) -> Result<(), OutputError> {
    PngPreview::new(path, width, height, pixels, exposure)?.write(path)
}

/// An encoded-to-sRGB 8-bit preview held until it is written (3 bytes a pixel): the EXR
/// writer can then take the frame apart without a float copy of the image kept aside.
pub struct PngPreview {
    width: u32,
    height: u32,
    bytes: Vec<u8>,
}

impl PngPreview {
    /// The preview of `pixels` (checked as [`write_png_preview`] checks them; `path` only
    /// names the file in errors).
    pub fn new(
        path: &Path,
        width: usize,
        height: usize,
        pixels: &[Rgb],
        exposure: f32,
    ) -> Result<PngPreview, OutputError> {
        check_pixels(path, "", width, height, pixels)?;
        Self::from_fn(path, width, height, |i| pixels[i], exposure)
    }

    /// The preview of planar `channels` (R, G, B of `width * height` each), checked like
    /// [`PngPreview::new`].
    pub fn from_planar(
        path: &Path,
        width: usize,
        height: usize,
        channels: &[Vec<f32>; 3],
        exposure: f32,
    ) -> Result<PngPreview, OutputError> {
        let count = pixel_count(path, width, height)?;
        if let Some(ch) = channels.iter().find(|c| c.len() != count) {
            return Err(OutputError::PixelCount {
                path: path.to_owned(),
                layer: String::new(),
                width,
                height,
                expected: count,
                actual: ch.len(),
            });
        }
        let at = |i: usize| Rgb::new(channels[0][i], channels[1][i], channels[2][i]);
        if let Some(i) = (0..count).find(|&i| !at(i).is_finite()) {
            return Err(OutputError::NonFinite {
                path: path.to_owned(),
                layer: String::new(),
                x: i % width,
                y: i / width,
            });
        }
        Self::from_fn(path, width, height, at, exposure)
    }

    fn from_fn(
        path: &Path,
        width: usize,
        height: usize,
        pixel: impl Fn(usize) -> Rgb,
        exposure: f32,
    ) -> Result<PngPreview, OutputError> {
        let (w, h) = match (u32::try_from(width), u32::try_from(height)) {
            (Ok(w), Ok(h)) => (w, h),
            _ => {
                return Err(OutputError::InvalidSize {
                    path: path.to_owned(),
                    width,
                    height,
                })
            }
        };
        let scale = exposure.exp2();
        if !scale.is_finite() {
            return Err(OutputError::NonFinite {
                path: path.to_owned(),
                layer: format!("exposure {exposure}"),
                x: 0,
                y: 0,
            });
        }
        let n = width * height;
        let mut bytes = Vec::with_capacity(n * 3);
        for i in 0..n {
            let p = pixel(i);
            bytes.extend([
                to_srgb8(p.r, scale),
                to_srgb8(p.g, scale),
                to_srgb8(p.b, scale),
            ]);
        }
        Ok(PngPreview {
            width: w,
            height: h,
            bytes,
        })
    }

    /// Writes the preview to `path`, atomically.
    pub fn write(&self, path: &Path) -> Result<(), OutputError> {
        write_atomically(path, |tmp| {
            let io_err = |source| OutputError::Io {
                path: path.to_owned(),
                source,
            };
            let png_err = |source| OutputError::PngEncode {
                path: path.to_owned(),
                source,
            };
            let file = fs::File::create(tmp).map_err(io_err)?;
            let mut out = BufWriter::new(file);
            let mut encoder = png::Encoder::new(&mut out, self.width, self.height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
            let mut writer = encoder.write_header().map_err(png_err)?;
            writer.write_image_data(&self.bytes).map_err(png_err)?;
            writer.finish().map_err(png_err)?;
            out.flush().map_err(io_err)
        })
    }
}

/// The temporary-file prefix of `path`'s writes: `.{file name}.tmp-`.
fn temp_prefix(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    Some(format!(".{name}.tmp-"))
}

/// Whether process `pid` is alive in this PID namespace, where that can be told (Linux:
/// `/proc/PID`). A PID that is not alive here may still be a live writer elsewhere.
fn process_alive(pid: u32) -> Option<bool> {
    if !Path::new("/proc/self").exists() {
        return None;
    }
    Some(Path::new("/proc").join(pid.to_string()).exists())
}

/// Removes temporary files `.{file name}.tmp-{pid}-{n}` of this output left by writes that
/// never finished (a process killed during the write, a second Ctrl-C): those no live writer
/// holds. A writer holds an exclusive lock (`flock`) on its temporary file from its creation
/// to its rename ([`write_atomically`]), and the kernel releases it when the writer dies, so
/// a temp file that can be locked belongs to no live writer — whatever PID namespace or
/// machine the writer ran in (a container on a shared volume sees other PIDs, or none, in
/// its `/proc`, so a PID that is not alive here proves nothing). Removed: the files whose PID
/// is not alive here and which this cleaner can lock. Files of live local PIDs, locked
/// files, and anything that does not match the pattern are left alone. Returns the files
/// removed.
pub fn clean_stale_temps(path: &Path) -> Vec<PathBuf> {
    let Some(prefix) = temp_prefix(path) else {
        return Vec::new();
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
            continue;
        };
        let Some((pid, n)) = rest.split_once('-') else {
            continue;
        };
        let (Ok(pid), true) = (
            pid.parse::<u32>(),
            !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()),
        ) else {
            continue;
        };
        // A writer of this PID namespace that is alive keeps its files whether or not it
        // locked them (a version that did not lock, or one between creation and lock).
        if pid == std::process::id() || process_alive(pid) != Some(false) {
            continue;
        }
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        // Removed while locked: a writer that opened it just now and waits for the lock
        // finds it gone and starts another ([`write_atomically`]).
        let Ok(file) = fs::OpenOptions::new().read(true).open(e.path()) else {
            continue;
        };
        if file.try_lock().is_ok() && fs::remove_file(e.path()).is_ok() {
            removed.push(e.path());
        }
    }
    removed
}

/// Creates the temporary file `tmp` and holds an exclusive lock on it (see
/// [`clean_stale_temps`]): `None` when a cleaner removed it between its creation and the
/// lock, so that the caller takes another name.
fn create_locked(tmp: &Path) -> io::Result<Option<fs::File>> {
    let file = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(tmp)?;
    file.lock()?;
    // Locked: still the file under that name, or a cleaner got there first.
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let ours = file.metadata()?;
        match fs::metadata(tmp) {
            Ok(m) if m.ino() == ours.ino() && m.dev() == ours.dev() => {}
            _ => return Ok(None),
        }
    }
    Ok(Some(file))
}

/// Checks, without leaving anything behind, that `path` can be written later: it is not a
/// directory, and its folder (or, if that does not exist yet, the nearest existing ancestor,
/// where the writer will create it) accepts a new file. Renders call this for each output
/// before they start, so a bad output path costs nothing.
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    let io_err = |source| OutputError::Io {
        path: path.to_owned(),
        source,
    };
    if path.file_name().is_none() {
        return Err(io_err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "path has no file name",
        )));
    }
    if path.is_dir() {
        return Err(io_err(io::Error::new(
            io::ErrorKind::IsADirectory,
            "is a directory",
        )));
    }
    let mut dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    while !dir.exists() {
        match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => dir = p.to_owned(),
            _ => dir = PathBuf::from("."),
        }
        if dir == Path::new(".") {
            break;
        }
    }
    if !dir.is_dir() {
        return Err(OutputError::CreateDir {
            path: path.to_owned(),
            dir: dir.clone(),
            source: io::Error::new(io::ErrorKind::NotADirectory, "not a directory"),
        });
    }
    let probe = dir.join(format!(
        ".{}.tmp-{}-probe",
        path.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    match fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
        Err(source) => Err(OutputError::Io {
            path: path.to_owned(),
            source: io::Error::new(
                source.kind(),
                format!("folder {} is not writable: {source}", dir.display()),
            ),
        }),
    }
}

/// Removes the temporary file when dropped, unless disarmed.
struct TempGuard<'a> {
    path: &'a Path,
    armed: bool,
}

impl Drop for TempGuard<'_> {
    fn drop(&mut self) {
        if self.armed {
            let _ = fs::remove_file(self.path);
        }
    }
}

/// Produces `path` atomically: creates missing parent directories, lets `write` fill a
/// temporary file `.{file name}.tmp-{pid}-{n}` in the same directory, fsyncs it, renames
/// it over `path` and (on Unix) fsyncs the directory. When `write`, the sync or the rename
/// fails, the temporary file is removed and any existing file at `path` is left untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);

    let io_err = |source| OutputError::Io {
        path: path.to_owned(),
        source,
    };
    let file_name = path.file_name().ok_or_else(|| {
        io_err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "path has no file name",
        ))
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir).map_err(|source| OutputError::CreateDir {
        path: path.to_owned(),
        dir: dir.clone(),
        source,
    })?;

    for stale in clean_stale_temps(path) {
        tracing::info!("removed {}, left by an interrupted write", stale.display());
    }
    // The temporary file is created and locked before it is written, and stays locked until
    // it is renamed: a cleaner elsewhere removes only unlocked ones.
    let (tmp, _lock) = loop {
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(
            ".tmp-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let tmp = dir.join(tmp_name);
        match create_locked(&tmp) {
            Ok(Some(lock)) => break (tmp, lock),
            Ok(None) => continue,
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(io_err(e)),
        }
    };
    let mut guard = TempGuard {
        path: &tmp,
        armed: true,
    };

    write(&tmp)?;
    // Flush the data to disk before the rename makes it visible under the final name.
    fs::OpenOptions::new()
        .write(true)
        .open(&tmp)
        .and_then(|f| f.sync_all())
        .map_err(io_err)?;
    fs::rename(&tmp, path).map_err(io_err)?;
    guard.armed = false;
    drop(guard);

    #[cfg(unix)]
    {
        // Best effort: persist the directory entry. Failure here does not undo the write.
        if let Ok(d) = fs::File::open(&dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}
