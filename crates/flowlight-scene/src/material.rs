//! glTF metallic-roughness materials (with the `KHR_materials_ior`, `_specular`,
//! `_transmission`, `_volume`, `_clearcoat` and `_emissive_strength` extensions) to
//! [`flowlight_core::material::Material`], and per-material diffuse overrides. The BSDF these
//! parameters stand for is `flowlight_core::bsdf::gltf`; `docs/gltf.md` ("Materials") lists
//! what is supported.
//!
//! The diffuse model comes from, in increasing priority: Lambert by default; the material's
//! glTF extras `{"flowlight": {"diffuse": "oren-nayar", "sigma_degrees": 20}}`; a
//! `[materials.NAME]` table of the render config ([`MaterialOverride`]).
//!
//! The extensions' textures (`transmissionTexture`, `thicknessTexture`, `specularTexture`,
//! `specularColorTexture`, `clearcoatTexture`, `clearcoatRoughnessTexture`) are assigned by the
//! loader like the core ones (texCoord, `KHR_texture_transform`, sampler); the clearcoat ones
//! come from the raw extension JSON through [`clearcoat_textures`]. Which channel multiplies
//! which factor, and why the thickness texture is read but not applied, is in
//! `flowlight_core::material`'s module docs. `clearcoatNormalTexture` is ignored with a
//! warning: the BSDF has one shading frame for all its lobes.

use flowlight_core::material::{DiffuseModel, Material};
use flowlight_core::Rgb;
use serde::Deserialize;

/// Diffuse model chosen by an override.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DiffuseChoice {
    Lambert,
    OrenNayar,
}

/// A per-material override of the diffuse model (a `[materials.NAME]` table, or the
/// `flowlight` object of a material's glTF extras).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialOverride {
    #[serde(default)]
    pub diffuse: Option<DiffuseChoice>,
    /// Oren–Nayar roughness σ in degrees; required for `oren-nayar`, in [0, 90].
    #[serde(default)]
    pub sigma_degrees: Option<f32>,
    /// Emit from both faces instead of the front face only.
    #[serde(default)]
    pub two_sided_emission: Option<bool>,
    /// Replaces the base colour factor (linear RGB, each in [0, 1]).
    #[serde(default)]
    pub base_color: Option<[f32; 3]>,
}

impl MaterialOverride {
    /// Checks the values; the error says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        match (self.diffuse, self.sigma_degrees) {
            (Some(DiffuseChoice::OrenNayar), None) => {
                Err("`sigma_degrees` is required for diffuse = \"oren-nayar\"".into())
            }
            (_, Some(s)) if !(0.0..=90.0).contains(&s) => {
                Err(format!("`sigma_degrees` = {s} is outside [0, 90]"))
            }
            _ => Ok(()),
        }?;
        match self.base_color {
            Some(c) if !c.iter().all(|v| (0.0..=1.0).contains(v)) => Err(format!(
                "`base_color` = {c:?} must have components in [0, 1]"
            )),
            _ => Ok(()),
        }
    }

    /// Applies the override to `m`.
    pub fn apply(&self, m: &mut Material) {
        match self.diffuse {
            Some(DiffuseChoice::Lambert) => {
                m.diffuse_model = DiffuseModel::Lambert;
                m.oren_nayar_sigma = 0.0;
            }
            Some(DiffuseChoice::OrenNayar) => {
                m.diffuse_model = DiffuseModel::OrenNayar;
                m.oren_nayar_sigma = self.sigma_degrees.unwrap_or(0.0).to_radians();
            }
            None => {}
        }
        if let Some(two) = self.two_sided_emission {
            m.two_sided_emission = two as u32;
        }
        if let Some(c) = self.base_color {
            m.base_color = flowlight_core::Rgb::from_array(c);
        }
    }
}

/// Reads the `flowlight` object of a material's extras, if any.
pub fn extras_override(extras: &gltf::json::Extras) -> Result<Option<MaterialOverride>, String> {
    let Some(raw) = extras else { return Ok(None) };
    let value: gltf::json::Value = gltf::json::deserialize::from_str(raw.get())
        .map_err(|e| format!("extras are not valid JSON: {e}"))?;
    let Some(fl) = value.get("flowlight") else {
        return Ok(None);
    };
    let o: MaterialOverride = gltf::json::deserialize::from_value(fl.clone())
        .map_err(|e| format!("extras.flowlight: {e}"))?;
    o.validate().map_err(|e| format!("extras.flowlight: {e}"))?;
    Ok(Some(o))
}

fn check_unit(name: &str, v: f32) -> Result<f32, String> {
    if !v.is_finite() {
        return Err(format!("{name} is not finite ({v})"));
    }
    if !(0.0..=1.0).contains(&v) {
        return Err(format!("{name} = {v} is outside [0, 1]"));
    }
    Ok(v)
}

fn check_rgb_unit(name: &str, c: [f32; 3]) -> Result<Rgb, String> {
    for (ch, v) in ["r", "g", "b"].iter().zip(c) {
        check_unit(&format!("{name}.{ch}"), v)?;
    }
    Ok(Rgb::from_array(c))
}

/// The material's name for messages.
fn label(m: &gltf::Material) -> String {
    match (m.index(), m.name()) {
        (None, _) => "default".to_string(),
        (Some(_), Some(n)) => n.to_string(),
        (Some(i), None) => format!("material{i}"),
    }
}

/// The scalar factors of `KHR_materials_clearcoat` (clearcoatFactor, clearcoatRoughnessFactor),
/// read from the raw extension object (the gltf crate has no type for it).
fn clearcoat(m: &gltf::Material) -> Result<(f32, f32), String> {
    let Some(v) = m.extension_value("KHR_materials_clearcoat") else {
        return Ok((0.0, 0.0));
    };
    let obj = v
        .as_object()
        .ok_or("KHR_materials_clearcoat is not a JSON object")?;
    let factor = |key: &str| -> Result<f32, String> {
        match obj.get(key) {
            None => Ok(0.0),
            Some(x) => {
                let f = x
                    .as_f64()
                    .ok_or(format!("KHR_materials_clearcoat.{key} is not a number"))?;
                check_unit(&format!("KHR_materials_clearcoat.{key}"), f as f32)
            }
        }
    };
    let c = factor("clearcoatFactor")?;
    let r = factor("clearcoatRoughnessFactor")?;
    if obj.contains_key("clearcoatNormalTexture") {
        tracing::warn!(
            "material '{}': KHR_materials_clearcoat clearcoatNormalTexture not applied (the coat \
             shares the base's shading normal)",
            label(m)
        );
    }
    Ok((c, r))
}

/// A texture reference of `KHR_materials_clearcoat`, read from the raw extension JSON (the
/// gltf crate has no type for it): texture index, `texCoord`, and the raw
/// `KHR_texture_transform` object, if any.
#[derive(Clone, Debug, PartialEq)]
pub struct RawTextureInfo {
    pub index: usize,
    pub tex_coord: u32,
    pub transform: Option<gltf::json::Value>,
}

/// A `textureInfo` object at `what` (the field, for errors): its index, checked against the
/// document's `texture_count`, its texCoord and its `KHR_texture_transform`. Every texture
/// reference of an extension the `gltf` crate does not parse goes through here.
pub(crate) fn parse_texture_info(
    v: &gltf::json::Value,
    what: &str,
    texture_count: usize,
) -> Result<RawTextureInfo, String> {
    let v = v
        .as_object()
        .ok_or_else(|| format!("{what} is not a JSON object"))?;
    let index = v
        .get("index")
        .and_then(|i| i.as_u64())
        .ok_or_else(|| format!("{what}.index is missing or not a non-negative integer"))?;
    let index = usize::try_from(index)
        .ok()
        .filter(|&i| i < texture_count)
        .ok_or_else(|| {
            format!("{what}.index = {index} is out of range ({texture_count} textures)")
        })?;
    let tex_coord = match v.get("texCoord") {
        None => 0,
        Some(c) => c
            .as_u64()
            .and_then(|c| u32::try_from(c).ok())
            .ok_or_else(|| format!("{what}.texCoord is not a non-negative integer"))?,
    };
    let transform = v
        .get("extensions")
        .and_then(|e| e.get("KHR_texture_transform"))
        .cloned();
    Ok(RawTextureInfo {
        index,
        tex_coord,
        transform,
    })
}

/// The `clearcoatTexture` and `clearcoatRoughnessTexture` of `m` (`None` where absent),
/// checked against the document's `texture_count`.
pub fn clearcoat_textures(
    m: &gltf::Material,
    texture_count: usize,
) -> Result<[Option<RawTextureInfo>; 2], String> {
    let Some(obj) = m
        .extension_value("KHR_materials_clearcoat")
        .and_then(|v| v.as_object())
    else {
        return Ok([None, None]);
    };
    let info = |key: &str| -> Result<Option<RawTextureInfo>, String> {
        obj.get(key)
            .map(|v| {
                parse_texture_info(v, &format!("KHR_materials_clearcoat.{key}"), texture_count)
            })
            .transpose()
    };
    Ok([
        info("clearcoatTexture")?,
        info("clearcoatRoughnessTexture")?,
    ])
}

/// Converts the scalar parts of a glTF material (everything but the texture references, which
/// the loader assigns) and checks every value. Material extensions this renderer does not know
/// are ignored with a warning naming them, and so is `clearcoatNormalTexture`.
pub fn convert(m: &gltf::Material) -> Result<Material, String> {
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, a] = pbr.base_color_factor();
    for (c, v) in ["r", "g", "b", "a"].iter().zip([r, g, b, a]) {
        check_unit(&format!("baseColorFactor.{c}"), v)?;
    }
    let metallic = check_unit("metallicFactor", pbr.metallic_factor())?;
    let roughness = check_unit("roughnessFactor", pbr.roughness_factor())?;
    let transmission = match m.transmission() {
        Some(t) => check_unit(
            "KHR_materials_transmission.transmissionFactor",
            t.transmission_factor(),
        )?,
        None => 0.0,
    };
    let ior = m.ior().unwrap_or(1.5);
    if !(ior.is_finite() && (ior >= 1.0 || ior == 0.0)) {
        return Err(format!(
            "KHR_materials_ior.ior = {ior} must be finite and 0 or >= 1"
        ));
    }
    let (specular, specular_color) = match m.specular() {
        Some(s) => {
            let f = check_unit("KHR_materials_specular.specularFactor", s.specular_factor())?;
            let c = s.specular_color_factor();
            for (ch, v) in ["r", "g", "b"].iter().zip(c) {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!(
                        "KHR_materials_specular.specularColorFactor.{ch} = {v} must be finite and >= 0"
                    ));
                }
            }
            (f, Rgb::from_array(c))
        }
        None => (1.0, Rgb::ONE),
    };
    let (thickness, attenuation_color, attenuation_distance) = match m.volume() {
        Some(v) => {
            let t = v.thickness_factor();
            if !(t.is_finite() && t >= 0.0) {
                return Err(format!(
                    "KHR_materials_volume.thicknessFactor = {t} must be finite and >= 0"
                ));
            }
            let d = v.attenuation_distance();
            if d.is_nan() || d <= 0.0 {
                return Err(format!(
                    "KHR_materials_volume.attenuationDistance = {d} must be > 0"
                ));
            }
            let c = check_rgb_unit(
                "KHR_materials_volume.attenuationColor",
                v.attenuation_color(),
            )?;
            (t, c, d)
        }
        None => (0.0, Rgb::ONE, f32::INFINITY),
    };
    let (clearcoat, clearcoat_roughness) = clearcoat(m)?;
    let strength = m.emissive_strength().unwrap_or(1.0);
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(format!(
            "KHR_materials_emissive_strength.emissiveStrength = {strength} must be finite and >= 0"
        ));
    }
    let [er, eg, eb] = m.emissive_factor();
    for (c, v) in ["r", "g", "b"].iter().zip([er, eg, eb]) {
        check_unit(&format!("emissiveFactor.{c}"), v)?;
    }
    let emission = Rgb::new(er, eg, eb) * strength;
    if !emission.is_valid_radiance() {
        return Err("emissive factor × strength overflows".into());
    }
    if let Some(others) = m.extensions() {
        let unknown: Vec<&str> = others
            .keys()
            .map(String::as_str)
            .filter(|k| !crate::extensions::is_supported(k))
            .collect();
        if !unknown.is_empty() {
            tracing::warn!(
                "material '{}': extension {} not supported; ignored",
                label(m),
                unknown.join(", ")
            );
        }
    }
    let mut out = Material {
        base_color: Rgb::new(r, g, b),
        metallic,
        roughness,
        transmission,
        ior,
        emission,
        two_sided_emission: 0,
        specular,
        specular_color,
        thickness,
        attenuation_color,
        attenuation_distance,
        clearcoat,
        clearcoat_roughness,
        layers: crate::material_layers::convert_layers(m)?,
        ..Material::default()
    };
    if let Some(o) = extras_override(m.extras())? {
        o.apply(&mut out);
    }
    Ok(out)
}
