//! What the render config says about loading a glTF file, beyond the file itself: the
//! per-material overrides, what to do with a texture whose image file is missing, and whether
//! the GGX lobes get multiple-scattering energy compensation.
//!
//! A missing texture file refuses the whole asset by default ([`MissingTextures::Error`]): a
//! render without a texture the artist meant is wrong, and a typo in a path should not pass
//! unnoticed. Assets are shipped with a missing texture often enough (an image left out of an
//! archive, a path with the wrong case) that [`MissingTextures::Warn`] (`[textures]
//! missing = "warn"` in the config) loads them anyway: each texture whose image file cannot be
//! read is dropped (the factor it would have multiplied stays as it is, as if the file had no
//! texture there), with one warning line naming the image file. Only a file that cannot be
//! read is dropped so; an image that is there but cannot be decoded is still an error.

use crate::material::MaterialOverride;
use std::collections::BTreeMap;

/// What to do with a texture whose image file cannot be read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissingTextures {
    /// Refuse the asset with an error naming the file (the default).
    #[default]
    Error,
    /// Drop the texture with one warning line naming the file.
    Warn,
}

impl MissingTextures {
    /// Parses the config value (`"error"` or `"warn"`).
    pub fn parse(s: &str) -> Result<MissingTextures, String> {
        match s {
            "error" => Ok(MissingTextures::Error),
            "warn" => Ok(MissingTextures::Warn),
            other => Err(format!("must be \"error\" or \"warn\", got \"{other}\"")),
        }
    }
}

/// No overrides (for [`LoadOptions::default`]).
static NO_OVERRIDES: BTreeMap<String, MaterialOverride> = BTreeMap::new();

/// Options of one glTF load ([`crate::gltf_loader::load_gltf_with`]).
#[derive(Clone, Copy, Debug)]
pub struct LoadOptions<'a> {
    /// Material name to diffuse-model override (`[materials.NAME]`).
    pub overrides: &'a BTreeMap<String, MaterialOverride>,
    /// `[textures] missing`.
    pub missing_textures: MissingTextures,
    /// `[render] multiscatter`: every material's GGX lobes get multiple-scattering energy
    /// compensation (`flowlight_core::bsdf::multiscatter`).
    pub multiscatter: bool,
}

impl Default for LoadOptions<'_> {
    fn default() -> Self {
        LoadOptions {
            overrides: &NO_OVERRIDES,
            missing_textures: MissingTextures::Error,
            multiscatter: false,
        }
    }
}

impl<'a> LoadOptions<'a> {
    /// The defaults with `overrides`.
    pub fn with_overrides(overrides: &'a BTreeMap<String, MaterialOverride>) -> LoadOptions<'a> {
        LoadOptions {
            overrides,
            ..LoadOptions::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_two_values_and_names_a_wrong_one() {
        assert_eq!(MissingTextures::parse("warn"), Ok(MissingTextures::Warn));
        assert_eq!(MissingTextures::parse("error"), Ok(MissingTextures::Error));
        let e = MissingTextures::parse("skip").unwrap_err();
        assert!(e.contains("skip") && e.contains("warn"), "{e}");
        assert_eq!(
            LoadOptions::default().missing_textures,
            MissingTextures::Error
        );
        assert!(!LoadOptions::default().multiscatter);
    }
}
