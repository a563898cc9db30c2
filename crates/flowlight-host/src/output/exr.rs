//! Writing the render result as a multi-layer OpenEXR file.
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

use std::collections::HashSet;
use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Blocks, Compression, Encoding, FlatSamples, Image,
    Layer, LayerAttributes, LineOrder, Text, Vec2, WritableImage,
};
use flowlight_core::spectrum::Rgb;

use super::{check_pixels, pixel_count, write_atomically, OutputError};

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

pub(super) fn text_to_string(t: &Text) -> String {
    match std::str::from_utf8(t.as_slice()) {
        Ok(s) => s.to_owned(),
        // Not UTF-8: treat as Latin-1, which every byte maps to.
        Err(_) => t.as_slice().iter().map(|&b| b as char).collect(),
    }
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
    check_raw_channels(path, width, height, count, raw)?;
    check_planar_layers(path, width, height, count, &layers)?;
    let attributes = header_attributes(path, meta)?;
    let channels = exr_channels(layers, raw);

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

/// Checks the integer channels: names that no RGB reader mistakes for a colour channel,
/// `count` samples each.
fn check_raw_channels(
    path: &Path,
    width: usize,
    height: usize,
    count: usize,
    raw: &[RawChannel],
) -> Result<(), OutputError> {
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
    Ok(())
}

/// Checks the RGB layers: at least one, valid and unique names, `count` finite samples in
/// each channel (the first non-finite pixel is reported with its position).
fn check_planar_layers(
    path: &Path,
    width: usize,
    height: usize,
    count: usize,
    layers: &[PlanarLayer],
) -> Result<(), OutputError> {
    if layers.is_empty() {
        return Err(OutputError::InvalidLayer {
            path: path.to_owned(),
            layer: String::new(),
            reason: "no layers to write".to_owned(),
        });
    }
    let mut names = HashSet::new();
    for layer in layers {
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
    Ok(())
}

/// The header attributes of `meta`: the standard text attributes where a key names one,
/// `string` attributes otherwise. Keys that are empty, hold a NUL byte, are longer than 255
/// bytes, repeat, or name a structural attribute are refused.
fn header_attributes(path: &Path, meta: &ExrMetadata) -> Result<LayerAttributes, OutputError> {
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
    Ok(attributes)
}

/// The file's channels, named by the layout of the module documentation: each layer's
/// `R`, `G`, `B` (moved, not copied), then the integer channels.
fn exr_channels(
    layers: Vec<PlanarLayer>,
    raw: &[RawChannel],
) -> exr::prelude::SmallVec<[AnyChannel<FlatSamples>; 4]> {
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
    channels
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
