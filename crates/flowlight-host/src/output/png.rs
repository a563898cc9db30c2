//! The 8-bit sRGB PNG encoder: the preview of a render (linear radiance through the sRGB
//! OETF) and ready-made 8-bit images such as `flowlight compare`'s false-colour error map.

use std::fs;
use std::io::{BufWriter, Write};
use std::path::Path;

use flowlight_core::spectrum::Rgb;

use super::{check_pixels, pixel_count, write_atomically, OutputError};

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
/// Non-finite pixels (and a non-finite exposure) are rejected like in [`write_exr`](super::write_exr)
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

/// An encoded-to-sRGB 8-bit image held until it is written (3 bytes a pixel): the EXR
/// writer can then take the frame apart without a float copy of the image kept aside. Every
/// PNG the host writes goes through [`PngPreview::write`].
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

    /// An image already in 8-bit sRGB (`width * height` pixels, row-major), such as a
    /// false-colour map, held for the same encoder; `path` only names the file in errors.
    pub fn from_rgb8(
        path: &Path,
        width: usize,
        height: usize,
        pixels: &[[u8; 3]],
    ) -> Result<PngPreview, OutputError> {
        let count = pixel_count(path, width, height)?;
        if pixels.len() != count {
            return Err(OutputError::PixelCount {
                path: path.to_owned(),
                layer: String::new(),
                width,
                height,
                expected: count,
                actual: pixels.len(),
            });
        }
        // `pixel_count` bounds both sides by `i32::MAX`.
        Ok(PngPreview {
            width: width as u32,
            height: height as u32,
            bytes: pixels.iter().flatten().copied().collect(),
        })
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
