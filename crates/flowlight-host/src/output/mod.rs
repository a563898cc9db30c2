//! Image output: multi-layer OpenEXR (the render result) and an 8-bit sRGB PNG preview,
//! both written atomically.
//!
//! - [`exr`](mod@self::exr): the EXR layout, its writers and the header ordering that makes
//!   identical images give identical files; [`exr_read`]: reading those files back.
//! - [`png`](mod@self::png): the 8-bit sRGB PNG encoder (previews and false-colour maps).
//! - [`atomic`]: temporary file, fsync, rename; stale temporary files; writability probes.
//! - [`live`]: the preview while rendering (tev over [`tev`]'s protocol, the PNG rewritten).
//!
//! # Safety of existing files
//!
//! Both writers go through [`write_atomically`]: the data are written to a temporary file in
//! the destination directory, flushed to disk, then renamed over the destination. A failed
//! write therefore never leaves a truncated image behind nor damages an existing one. All
//! input is validated (sizes, finiteness, names) before anything touches the file system.

use std::io;
use std::path::{Path, PathBuf};

use flowlight_core::spectrum::Rgb;

pub mod atomic;
pub mod exr;
pub mod exr_read;
pub mod live;
pub mod png;
pub mod tev;

pub use self::atomic::{check_writable, clean_stale_temps, write_atomically};
pub use self::exr::{
    frame_layers, sort_header_attributes, write_exr, write_exr_planar, write_exr_with_raw,
    ExrMetadata, ImageLayer, PlanarLayer, RawChannel,
};
pub use self::exr_read::{
    check_exr_size, read_exr_metadata, read_exr_rgb, read_exr_u32, NamedLayers, U32Channels,
};
pub use self::png::{write_png_preview, PngPreview};

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
        source: ::exr::error::Error,
    },

    #[error("cannot read EXR {path}: {source}")]
    ExrDecode {
        path: PathBuf,
        source: ::exr::error::Error,
    },

    #[error("cannot encode PNG {path}: {source}")]
    PngEncode {
        path: PathBuf,
        source: ::png::EncodingError,
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
