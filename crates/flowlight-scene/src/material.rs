//! glTF metallic-roughness materials (with the transmission, IOR and emissive-strength
//! extensions) to [`flowlight_core::material::Material`], and per-material diffuse overrides.
//!
//! The diffuse model comes from, in increasing priority: Lambert by default; the material's
//! glTF extras `{"flowlight": {"diffuse": "oren-nayar", "sigma_degrees": 20}}`; a
//! `[materials.NAME]` table of the render config ([`MaterialOverride`]).

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

/// Converts the scalar parts of a glTF material (everything but the texture index, which the
/// loader assigns) and checks every value.
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
    if !(ior.is_finite() && ior >= 1.0) {
        return Err(format!(
            "KHR_materials_ior.ior = {ior} must be finite and >= 1"
        ));
    }
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
    let mut out = Material {
        base_color: Rgb::new(r, g, b),
        metallic,
        roughness,
        transmission,
        ior,
        emission,
        two_sided_emission: 0,
        ..Material::default()
    };
    if let Some(o) = extras_override(m.extras())? {
        o.apply(&mut out);
    }
    Ok(out)
}
