//! Image decoding (PNG and JPEG, from files, data URIs or buffer views) into linear RGB.

use crate::error::SceneError;
use crate::scene::TextureData;
use crate::source::GltfSource;
use flowlight_core::Rgb;

/// The sRGB electro-optical transfer function: encoded value in [0, 1] to linear.
#[inline]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Decodes encoded image bytes; `srgb` selects whether texels are sRGB-decoded to linear
/// (base colour textures) or taken as they are. Alpha is ignored.
pub fn decode_image(bytes: &[u8], srgb: bool) -> Result<TextureData, String> {
    let img = image::load_from_memory(bytes).map_err(|e| e.to_string())?;
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err("image has zero size".into());
    }
    let rgb = img.to_rgb32f();
    let conv = |v: f32| {
        if srgb {
            srgb_to_linear(v.clamp(0.0, 1.0))
        } else {
            v
        }
    };
    let texels = rgb
        .pixels()
        .map(|p| Rgb::new(conv(p.0[0]), conv(p.0[1]), conv(p.0[2])))
        .collect();
    Ok(TextureData {
        width,
        height,
        texels,
    })
}

/// Loads and decodes glTF image `image`.
pub fn load_image(
    src: &mut GltfSource,
    image: &gltf::Image,
    srgb: bool,
) -> Result<TextureData, SceneError> {
    let err = |src: &GltfSource, reason: String| SceneError::Image {
        file: src.file.clone(),
        image: image.index(),
        reason,
    };
    let bytes = match image.source() {
        gltf::image::Source::View { view, .. } => src.view_bytes(&view)?.to_vec(),
        gltf::image::Source::Uri { uri, .. } => {
            src.read_uri(uri).map_err(|e| err(src, e.to_string()))?
        }
    };
    decode_image(&bytes, srgb).map_err(|e| err(src, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decoding_matches_reference_points() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-7);
    }

    #[test]
    fn png_texels_are_linearised() {
        let mut png = Vec::new();
        let img = image::RgbImage::from_raw(2, 1, vec![255, 128, 0, 0, 0, 255]).unwrap();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let t = decode_image(&png, true).unwrap();
        assert_eq!((t.width, t.height), (2, 1));
        assert!((t.texels[0].r - 1.0).abs() < 1e-6);
        assert!((t.texels[0].g - srgb_to_linear(128.0 / 255.0)).abs() < 1e-5);
        assert_eq!(t.texels[1], Rgb::new(0.0, 0.0, 1.0));
        assert!(decode_image(b"not an image", true).is_err());
    }
}
