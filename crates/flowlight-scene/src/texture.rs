//! Image decoding (PNG, JPEG and WebP — `EXT_texture_webp` — from files, data URIs or buffer
//! views) into compact texel storage, and glTF samplers.
//!
//! Images keep the precision and channel count they were decoded with: an 8-bit RGB image is
//! 3 bytes per texel, 8-bit RGBA 4, grey 1, 16-bit images 2 bytes per channel, float images
//! 4. The sRGB decode of colour textures happens on lookup
//! ([`flowlight_core::material::Texture::sample`]), so the same image can serve as a colour
//! and as a data texture, and a FlightHelmet-class set (5 materials × 3–4 textures of 2048²)
//! stays at 3–4 bytes per texel instead of the 12 of linear `f32` RGB.
//!
//! One decoded image is shared (by reference count) by every glTF texture that uses it,
//! each with its own sampler.

use crate::error::SceneError;
use crate::source::GltfSource;
pub use flowlight_core::material::srgb_to_linear;
use flowlight_core::material::{Filter, TexelFormat, Texture, Wrap};
use std::sync::Arc;

/// Texel storage of a decoded image, in its own precision.
#[derive(Clone, Debug, PartialEq)]
pub enum Texels {
    U8(Arc<[u8]>),
    U16(Arc<[u16]>),
    F32(Arc<[f32]>),
}

impl Texels {
    fn format(&self) -> TexelFormat {
        match self {
            Texels::U8(_) => TexelFormat::U8,
            Texels::U16(_) => TexelFormat::U16,
            Texels::F32(_) => TexelFormat::F32,
        }
    }

    fn ptr(&self) -> *const u8 {
        match self {
            Texels::U8(v) => v.as_ptr(),
            Texels::U16(v) => v.as_ptr() as *const u8,
            Texels::F32(v) => v.as_ptr() as *const u8,
        }
    }

    /// Bytes of storage.
    pub fn bytes(&self) -> usize {
        match self {
            Texels::U8(v) => v.len(),
            Texels::U16(v) => v.len() * 2,
            Texels::F32(v) => v.len() * 4,
        }
    }
}

/// A decoded image: `width × height × channels` values, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageData {
    pub width: u32,
    pub height: u32,
    /// 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA).
    pub channels: u32,
    pub texels: Texels,
}

/// A glTF sampler: wrap modes per axis and the filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sampler {
    pub wrap_s: Wrap,
    pub wrap_t: Wrap,
    pub filter: Filter,
}

impl Default for Sampler {
    /// glTF's default sampler: REPEAT on both axes, linear filtering.
    fn default() -> Self {
        Sampler {
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            filter: Filter::Linear,
        }
    }
}

impl Sampler {
    /// The sampler of a glTF texture. Filtering follows `magFilter` (NEAREST or LINEAR,
    /// LINEAR when absent); minification and mipmap modes have no separate path here (there
    /// are no mip levels: many samples per pixel average the footprint), so a texture whose
    /// `magFilter` is absent but whose `minFilter` is NEAREST is NEAREST.
    pub fn from_gltf(s: &gltf::texture::Sampler) -> Sampler {
        use gltf::texture::{MagFilter, MinFilter, WrappingMode};
        let wrap = |w: WrappingMode| match w {
            WrappingMode::Repeat => Wrap::Repeat,
            WrappingMode::ClampToEdge => Wrap::ClampToEdge,
            WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        };
        let filter = match (s.mag_filter(), s.min_filter()) {
            (Some(MagFilter::Nearest), _) => Filter::Nearest,
            (Some(MagFilter::Linear), _) => Filter::Linear,
            (None, Some(MinFilter::Nearest)) => Filter::Nearest,
            _ => Filter::Linear,
        };
        Sampler {
            wrap_s: wrap(s.wrap_s()),
            wrap_t: wrap(s.wrap_t()),
            filter,
        }
    }
}

/// A texture of the scene: a shared decoded image and its sampler.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureData {
    pub image: ImageData,
    pub sampler: Sampler,
}

impl TextureData {
    /// A borrowed view for [`flowlight_core::material::Material::resolve`]; valid while the
    /// image's storage lives (it is shared, so clones of `self` keep it alive too).
    pub fn view(&self) -> Texture {
        Texture {
            width: self.image.width,
            height: self.image.height,
            channels: self.image.channels,
            format: self.image.texels.format(),
            wrap_s: self.sampler.wrap_s,
            wrap_t: self.sampler.wrap_t,
            filter: self.sampler.filter,
            texels: self.image.texels.ptr(),
        }
    }
}

/// Decodes encoded image bytes into their own precision and channel count (see the module
/// docs). No colour conversion happens here.
pub fn decode_image(bytes: &[u8]) -> Result<ImageData, String> {
    use image::DynamicImage as D;
    // The decoder's own default cap (512 MiB) refuses a valid 16k texture with a bare
    // "Memory limit exceeded": the cap is the memory this process may allocate instead, and
    // a refusal names the image's size and the cap.
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let cap = crate::memory::available_memory().unwrap_or(u64::MAX);
    let mut limits = image::Limits::no_limits();
    limits.max_alloc = Some(cap);
    reader.limits(limits);
    let size = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .ok()
        .and_then(|r| r.into_dimensions().ok());
    let img = reader.decode().map_err(|e| match (e, size) {
        (image::ImageError::Limits(_), Some((w, h))) => format!(
            "a {w}x{h} image needs more than the {} MiB of memory available to decode it",
            cap >> 20
        ),
        (e, _) => e.to_string(),
    })?;
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err("image has zero size".into());
    }
    let (channels, texels) = match img {
        D::ImageLuma8(i) => (1, Texels::U8(i.into_raw().into())),
        D::ImageLumaA8(i) => (2, Texels::U8(i.into_raw().into())),
        D::ImageRgb8(i) => (3, Texels::U8(i.into_raw().into())),
        D::ImageRgba8(i) => (4, Texels::U8(i.into_raw().into())),
        D::ImageLuma16(i) => (1, Texels::U16(i.into_raw().into())),
        D::ImageLumaA16(i) => (2, Texels::U16(i.into_raw().into())),
        D::ImageRgb16(i) => (3, Texels::U16(i.into_raw().into())),
        D::ImageRgba16(i) => (4, Texels::U16(i.into_raw().into())),
        D::ImageRgb32F(i) => (3, Texels::F32(i.into_raw().into())),
        other if other.color().has_alpha() => {
            (4, Texels::F32(other.to_rgba32f().into_raw().into()))
        }
        other => (3, Texels::F32(other.to_rgb32f().into_raw().into())),
    };
    Ok(ImageData {
        width,
        height,
        channels,
        texels,
    })
}

/// Loads and decodes glTF image `image`.
pub fn load_image(src: &mut GltfSource, image: &gltf::Image) -> Result<ImageData, SceneError> {
    match load_image_or_unreadable(src, image)? {
        Ok(d) => Ok(d),
        Err(unreadable) => Err(SceneError::Image {
            file: src.file.clone(),
            image: image.index(),
            reason: unreadable.reason,
        }),
    }
}

/// An image whose file could not be read (missing, unreadable): the file and why.
#[derive(Clone, Debug)]
pub struct UnreadableImage {
    pub path: std::path::PathBuf,
    /// "cannot read PATH: REASON", as [`load_image`]'s error says it.
    pub reason: String,
}

/// [`load_image`], telling an image file that cannot be read (`Ok(Err(_))`, which
/// `[textures] missing = "warn"` drops, [`crate::load_options`]) from every other failure.
pub fn load_image_or_unreadable(
    src: &mut GltfSource,
    image: &gltf::Image,
) -> Result<Result<ImageData, UnreadableImage>, SceneError> {
    let err = |src: &GltfSource, reason: String| SceneError::Image {
        file: src.file.clone(),
        image: image.index(),
        reason,
    };
    // `Image::source` unwraps the MIME type of an image in a buffer view, which the glTF
    // spec requires there but a hand-written file may leave out.
    let json = &src.document.as_json().images[image.index()];
    if json.buffer_view.is_some() && json.mime_type.is_none() {
        return Err(err(
            src,
            "it is stored in a bufferView but has no mimeType (the glTF spec requires \"image/png\", \"image/jpeg\" or, with EXT_texture_webp, \"image/webp\" there)".into(),
        ));
    }
    let bytes = match image.source() {
        gltf::image::Source::View { view, .. } => src.view_bytes(&view)?.to_vec(),
        gltf::image::Source::Uri { uri, .. } => match src.read_uri(uri) {
            Ok(b) => b,
            Err(crate::source::UriError::Io(path, e)) => {
                let reason = format!("cannot read {}: {e}", path.display());
                return Ok(Err(UnreadableImage { path, reason }));
            }
            Err(e) => return Err(err(src, e.to_string())),
        },
    };
    decode_image(&bytes).map(Ok).map_err(|e| err(src, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    fn png<P: image::PixelWithColorType>(img: image::ImageBuffer<P, Vec<P::Subpixel>>) -> Vec<u8>
    where
        [P::Subpixel]: image::EncodableLayout,
    {
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn srgb_decoding_matches_reference_points() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-7);
    }

    #[test]
    fn png_texels_stay_eight_bit_and_decode_on_lookup() {
        let bytes = png(image::RgbImage::from_raw(2, 1, vec![255, 128, 0, 0, 0, 255]).unwrap());
        let img = decode_image(&bytes).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 1, 3));
        assert_eq!(img.texels, Texels::U8(vec![255, 128, 0, 0, 0, 255].into()));
        assert_eq!(img.texels.bytes(), 6);
        let t = TextureData {
            image: img,
            sampler: Sampler {
                filter: Filter::Nearest,
                ..Sampler::default()
            },
        };
        let v = t.view();
        let s = v.sample(Vec2::new(0.25, 0.5), true);
        assert!((s.x - 1.0).abs() < 1e-6);
        assert!((s.y - srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
        assert_eq!(s.w, 1.0);
        let d = v.sample(Vec2::new(0.25, 0.5), false);
        assert!((d.y - 128.0 / 255.0).abs() < 1e-6);
        assert_eq!(v.sample(Vec2::new(0.75, 0.5), true).z, 1.0);
        assert!(decode_image(b"not an image").is_err());
    }

    #[test]
    fn sixteen_bit_grey_alpha_png_keeps_its_precision() {
        let raw: Vec<u16> = vec![0, 65535, 32768, 1000];
        let bytes =
            png(image::ImageBuffer::<image::LumaA<u16>, _>::from_raw(2, 1, raw.clone()).unwrap());
        let img = decode_image(&bytes).unwrap();
        assert_eq!(img.channels, 2);
        assert_eq!(img.texels, Texels::U16(raw.into()));
        let t = TextureData {
            image: img,
            sampler: Sampler {
                filter: Filter::Nearest,
                ..Sampler::default()
            },
        }
        .view();
        let s = t.sample(Vec2::new(0.75, 0.5), false);
        assert!((s.x - 32768.0 / 65535.0).abs() < 1e-6);
        assert!((s.w - 1000.0 / 65535.0).abs() < 1e-6);
    }

    /// Resident texel memory of a FlightHelmet-class texture set, before (linear f32 RGB,
    /// 12 bytes a texel, as the loader stored textures before) and now. Run with
    /// `--ignored --nocapture` to print the figure; the assertion checks the storage size.
    #[test]
    #[ignore = "decodes 20 PNGs of 2048²; run on demand for the memory figure"]
    fn flight_helmet_class_texture_memory() {
        let side = 2048u32;
        let (mut before, mut after) = (0usize, 0usize);
        // 5 materials × (base colour RGBA, metallic-roughness RGB, normal RGB, occlusion RGB).
        for m in 0..5u32 {
            for (k, channels) in [4u32, 3, 3, 3].into_iter().enumerate() {
                let raw: Vec<u8> = (0..side * side * channels)
                    .map(|i| ((i * 31 + m * 7 + k as u32) % 251) as u8)
                    .collect();
                let bytes = if channels == 4 {
                    png(image::RgbaImage::from_raw(side, side, raw).unwrap())
                } else {
                    png(image::RgbImage::from_raw(side, side, raw).unwrap())
                };
                let img = decode_image(&bytes).unwrap();
                assert_eq!(img.texels.bytes(), (side * side * channels) as usize);
                before += (side * side) as usize * 12;
                after += img.texels.bytes();
            }
        }
        println!(
            "FlightHelmet-class set (5 × 4 textures of {side}²): before {:.1} MiB, after {:.1} MiB ({:.2}×)",
            before as f64 / (1 << 20) as f64,
            after as f64 / (1 << 20) as f64,
            before as f64 / after as f64
        );
        assert!(after * 3 < before);
    }
}
