//! `KHR_materials_sheen`, `KHR_materials_diffuse_transmission`, `KHR_materials_iridescence`
//! and `KHR_materials_anisotropy` of a glTF material to
//! [`flowlight_core::material_layers::MaterialLayers`], read from the raw extension JSON (the
//! `gltf` crate has no types for them). Every value is checked; a bad one is an error naming
//! the extension and field. The texture references are returned by [`layer_textures`] for
//! the loader to assign (texCoord, `KHR_texture_transform`, sampler), like the clearcoat ones.

use crate::material::RawTextureInfo;
use flowlight_core::material_layers::MaterialLayers;
use flowlight_core::Rgb;
use gltf::json::Value;

/// The extensions this module reads.
pub const LAYER_EXTENSIONS: [&str; 4] = [
    "KHR_materials_sheen",
    "KHR_materials_diffuse_transmission",
    "KHR_materials_iridescence",
    "KHR_materials_anisotropy",
];

/// Which texture of [`MaterialLayers`] a reference is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerTexture {
    SheenColor,
    SheenRoughness,
    DiffuseTransmission,
    DiffuseTransmissionColor,
    Iridescence,
    IridescenceThickness,
    Anisotropy,
}

/// Every layer texture: the extension, its key and the slot.
const TEXTURES: [(&str, &str, LayerTexture); 7] = [
    (
        LAYER_EXTENSIONS[0],
        "sheenColorTexture",
        LayerTexture::SheenColor,
    ),
    (
        LAYER_EXTENSIONS[0],
        "sheenRoughnessTexture",
        LayerTexture::SheenRoughness,
    ),
    (
        LAYER_EXTENSIONS[1],
        "diffuseTransmissionTexture",
        LayerTexture::DiffuseTransmission,
    ),
    (
        LAYER_EXTENSIONS[1],
        "diffuseTransmissionColorTexture",
        LayerTexture::DiffuseTransmissionColor,
    ),
    (
        LAYER_EXTENSIONS[2],
        "iridescenceTexture",
        LayerTexture::Iridescence,
    ),
    (
        LAYER_EXTENSIONS[2],
        "iridescenceThicknessTexture",
        LayerTexture::IridescenceThickness,
    ),
    (
        LAYER_EXTENSIONS[3],
        "anisotropyTexture",
        LayerTexture::Anisotropy,
    ),
];

/// The extension's JSON object, if the material has it.
fn object<'a>(m: &'a gltf::Material, ext: &str) -> Result<Option<&'a Value>, String> {
    match m.extension_value(ext) {
        None => Ok(None),
        Some(v) if v.is_object() => Ok(Some(v)),
        Some(_) => Err(format!("{ext} is not a JSON object")),
    }
}

/// A number field: its value, `default` when absent; an error when it is not a number or
/// fails `ok` (whose message says the allowed range).
fn number(
    obj: &Value,
    ext: &str,
    key: &str,
    default: f32,
    ok: (fn(f32) -> bool, &str),
) -> Result<f32, String> {
    let Some(v) = obj.get(key) else {
        return Ok(default);
    };
    let x = v
        .as_f64()
        .ok_or_else(|| format!("{ext}.{key} is not a number"))? as f32;
    if !x.is_finite() || !(ok.0)(x) {
        return Err(format!("{ext}.{key} = {x} {}", ok.1));
    }
    Ok(x)
}

const UNIT: (fn(f32) -> bool, &str) = (|x| (0.0..=1.0).contains(&x), "is outside [0, 1]");
const NON_NEGATIVE: (fn(f32) -> bool, &str) = (|x| x >= 0.0, "must be >= 0");
const IOR: (fn(f32) -> bool, &str) = (|x| x >= 1.0, "must be >= 1");
const ANY: (fn(f32) -> bool, &str) = (|_| true, "must be finite");

/// A colour field of three numbers in [0, 1]; `default` when absent.
fn colour(obj: &Value, ext: &str, key: &str, default: Rgb) -> Result<Rgb, String> {
    let Some(v) = obj.get(key) else {
        return Ok(default);
    };
    let a = v
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| format!("{ext}.{key} is not an array of three numbers"))?;
    let mut c = [0.0f32; 3];
    for (k, (x, ch)) in a.iter().zip(["r", "g", "b"]).enumerate() {
        let x = x
            .as_f64()
            .ok_or_else(|| format!("{ext}.{key}.{ch} is not a number"))? as f32;
        if !(0.0..=1.0).contains(&x) {
            return Err(format!("{ext}.{key}.{ch} = {x} is outside [0, 1]"));
        }
        c[k] = x;
    }
    Ok(Rgb::from_array(c))
}

/// The factors of the four layer extensions (textures not assigned: [`layer_textures`]).
pub fn convert_layers(m: &gltf::Material) -> Result<MaterialLayers, String> {
    let mut l = MaterialLayers::default();
    if let Some(o) = object(m, LAYER_EXTENSIONS[0])? {
        let e = LAYER_EXTENSIONS[0];
        l.sheen_color = colour(o, e, "sheenColorFactor", Rgb::ZERO)?;
        l.sheen_roughness = number(o, e, "sheenRoughnessFactor", 0.0, UNIT)?;
    }
    if let Some(o) = object(m, LAYER_EXTENSIONS[1])? {
        let e = LAYER_EXTENSIONS[1];
        l.diffuse_transmission = number(o, e, "diffuseTransmissionFactor", 0.0, UNIT)?;
        l.diffuse_transmission_color = colour(o, e, "diffuseTransmissionColorFactor", Rgb::ONE)?;
    }
    if let Some(o) = object(m, LAYER_EXTENSIONS[2])? {
        let e = LAYER_EXTENSIONS[2];
        l.iridescence = number(o, e, "iridescenceFactor", 0.0, UNIT)?;
        l.iridescence_ior = number(o, e, "iridescenceIor", 1.3, IOR)?;
        l.iridescence_thickness_min =
            number(o, e, "iridescenceThicknessMinimum", 100.0, NON_NEGATIVE)?;
        l.iridescence_thickness_max =
            number(o, e, "iridescenceThicknessMaximum", 400.0, NON_NEGATIVE)?;
    }
    if let Some(o) = object(m, LAYER_EXTENSIONS[3])? {
        let e = LAYER_EXTENSIONS[3];
        l.anisotropy_strength = number(o, e, "anisotropyStrength", 0.0, UNIT)?;
        l.anisotropy_rotation = number(o, e, "anisotropyRotation", 0.0, ANY)?;
    }
    Ok(l)
}

/// The layer textures of `m` with their slots, checked against the document's
/// `texture_count`.
pub fn layer_textures(
    m: &gltf::Material,
    texture_count: usize,
) -> Result<Vec<(LayerTexture, RawTextureInfo)>, String> {
    let mut out = Vec::new();
    for (ext, key, slot) in TEXTURES {
        let Some(o) = object(m, ext)? else { continue };
        let Some(v) = o.get(key) else { continue };
        out.push((
            slot,
            crate::material::parse_texture_info(v, &format!("{ext}.{key}"), texture_count)?,
        ));
    }
    Ok(out)
}

/// Sets the texture reference of `slot` in `layers`.
pub fn assign(
    layers: &mut MaterialLayers,
    slot: LayerTexture,
    r: flowlight_core::material::TextureRef,
) {
    match slot {
        LayerTexture::SheenColor => layers.sheen_color_texture = r,
        LayerTexture::SheenRoughness => layers.sheen_roughness_texture = r,
        LayerTexture::DiffuseTransmission => layers.diffuse_transmission_texture = r,
        LayerTexture::DiffuseTransmissionColor => layers.diffuse_transmission_color_texture = r,
        LayerTexture::Iridescence => layers.iridescence_texture = r,
        LayerTexture::IridescenceThickness => layers.iridescence_thickness_texture = r,
        LayerTexture::Anisotropy => layers.anisotropy_texture = r,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-material document with `extensions` on the material.
    fn doc(extensions: &str) -> gltf::Document {
        let json = format!(
            r#"{{"asset": {{"version": "2.0"}},
                "images": [{{"uri": "a.png"}}], "textures": [{{"source": 0}}],
                "materials": [{{"name": "m", "extensions": {extensions}}}]}}"#
        );
        gltf::Gltf::from_slice(json.as_bytes()).unwrap().document
    }

    #[test]
    fn layer_factors_are_parsed_from_gltf_json() {
        let d = doc(
            r#"{"KHR_materials_sheen": {"sheenColorFactor": [0.9, 0.5, 0.25],
                   "sheenRoughnessFactor": 0.4, "sheenColorTexture": {"index": 0, "texCoord": 1}},
                "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.75,
                   "diffuseTransmissionColorFactor": [0.2, 1.0, 0.3],
                   "diffuseTransmissionTexture": {"index": 0}},
                "KHR_materials_iridescence": {"iridescenceFactor": 0.8, "iridescenceIor": 1.45,
                   "iridescenceThicknessMinimum": 120, "iridescenceThicknessMaximum": 560,
                   "iridescenceThicknessTexture": {"index": 0,
                      "extensions": {"KHR_texture_transform": {"scale": [2, 2]}}}},
                "KHR_materials_anisotropy": {"anisotropyStrength": 0.6, "anisotropyRotation": -0.5,
                   "anisotropyTexture": {"index": 0}}}"#,
        );
        let m = d.materials().next().unwrap();
        let l = convert_layers(&m).unwrap();
        assert_eq!(l.sheen_color, Rgb::new(0.9, 0.5, 0.25));
        assert_eq!(l.sheen_roughness, 0.4);
        assert_eq!(l.diffuse_transmission, 0.75);
        assert_eq!(l.diffuse_transmission_color, Rgb::new(0.2, 1.0, 0.3));
        assert_eq!(l.iridescence, 0.8);
        assert_eq!(l.iridescence_ior, 1.45);
        assert_eq!(l.iridescence_thickness_min, 120.0);
        assert_eq!(l.iridescence_thickness_max, 560.0);
        assert_eq!((l.anisotropy_strength, l.anisotropy_rotation), (0.6, -0.5));
        let t = layer_textures(&m, 1).unwrap();
        let slots: Vec<_> = t.iter().map(|(s, r)| (*s, r.index, r.tex_coord)).collect();
        assert_eq!(
            slots,
            vec![
                (LayerTexture::SheenColor, 0, 1),
                (LayerTexture::DiffuseTransmission, 0, 0),
                (LayerTexture::IridescenceThickness, 0, 0),
                (LayerTexture::Anisotropy, 0, 0),
            ]
        );
        assert!(t[2].1.transform.is_some());
    }

    #[test]
    fn absent_fields_take_the_extensions_defaults() {
        let d = doc(
            r#"{"KHR_materials_sheen": {}, "KHR_materials_diffuse_transmission": {},
                "KHR_materials_iridescence": {}, "KHR_materials_anisotropy": {}}"#,
        );
        let l = convert_layers(&d.materials().next().unwrap()).unwrap();
        assert_eq!(l, MaterialLayers::default());
    }

    #[test]
    fn bad_values_name_the_extension_and_field() {
        for (ext, want) in [
            (
                r#"{"KHR_materials_sheen": {"sheenRoughnessFactor": 1.5}}"#,
                "KHR_materials_sheen.sheenRoughnessFactor = 1.5 is outside [0, 1]",
            ),
            (
                r#"{"KHR_materials_sheen": {"sheenColorFactor": [1, 2]}}"#,
                "KHR_materials_sheen.sheenColorFactor is not an array of three numbers",
            ),
            (
                r#"{"KHR_materials_anisotropy": {"anisotropyStrength": -0.1}}"#,
                "KHR_materials_anisotropy.anisotropyStrength = -0.1 is outside [0, 1]",
            ),
            (
                r#"{"KHR_materials_iridescence": {"iridescenceIor": 0.5}}"#,
                "KHR_materials_iridescence.iridescenceIor = 0.5 must be >= 1",
            ),
            (
                r#"{"KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": "x"}}"#,
                "KHR_materials_diffuse_transmission.diffuseTransmissionFactor is not a number",
            ),
        ] {
            let d = doc(ext);
            let e = convert_layers(&d.materials().next().unwrap()).unwrap_err();
            assert_eq!(e, want);
        }
        let d = doc(r#"{"KHR_materials_sheen": {"sheenColorTexture": {"index": 3}}}"#);
        let e = layer_textures(&d.materials().next().unwrap(), 1).unwrap_err();
        assert!(
            e.contains("sheenColorTexture.index = 3 is out of range"),
            "{e}"
        );
    }
}
