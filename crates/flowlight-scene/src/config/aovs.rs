//! `[output] aovs`: the arbitrary output variables a render writes beside the beauty, and
//! `[output] aov_spp`, how many camera samples per pixel estimate them (the host's AOV
//! pass, `flowlight_host::aov`, documents what each holds).

/// One AOV, named in the config as [`Aov::name`] and written as the EXR layer of that name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Aov {
    /// Reflectance (directional albedo) of the first non-Dirac surface.
    Albedo,
    /// World-space shading normal of the first non-Dirac surface.
    Normal,
    /// Path length from the camera to the first non-Dirac surface.
    Depth,
    /// World-space position of the first non-Dirac surface.
    Position,
    /// Material index of the first non-Dirac surface (not filtered).
    MaterialId,
    /// Object (mesh placement) index of the first non-Dirac surface (not filtered).
    ObjectId,
}

impl Aov {
    /// Every AOV, in the order their layers are written.
    pub const ALL: [Aov; 6] = [
        Aov::Albedo,
        Aov::Normal,
        Aov::Depth,
        Aov::Position,
        Aov::MaterialId,
        Aov::ObjectId,
    ];

    /// The name in the config and of the EXR layer.
    pub fn name(self) -> &'static str {
        match self {
            Aov::Albedo => "albedo",
            Aov::Normal => "normal",
            Aov::Depth => "depth",
            Aov::Position => "position",
            Aov::MaterialId => "material_id",
            Aov::ObjectId => "object_id",
        }
    }

    /// The AOV named `name`, or a one-line reason listing the valid names.
    pub fn parse(name: &str) -> Result<Aov, String> {
        Aov::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| {
                let names: Vec<String> = Aov::ALL
                    .iter()
                    .map(|a| format!("\"{}\"", a.name()))
                    .collect();
                format!("\"{name}\" is not one of {}", names.join(", "))
            })
    }
}

/// Default of `[output] aov_spp`: AOVs converge far faster than the beauty (only edges and
/// textures vary within a pixel), so 16 well-spread positions per pixel are enough, and they
/// keep the pass cheap next to a render of many samples.
pub const DEFAULT_AOV_SPP: u32 = 16;

/// Parses `[output] aovs`: each name once, in [`Aov::ALL`] order.
pub fn parse_aovs(names: &[String]) -> Result<Vec<Aov>, String> {
    let mut out = Vec::new();
    for n in names {
        let a = Aov::parse(n)?;
        if out.contains(&a) {
            return Err(format!("\"{n}\" is listed twice"));
        }
        out.push(a);
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_bad_ones_are_named() {
        for a in Aov::ALL {
            assert_eq!(Aov::parse(a.name()), Ok(a));
        }
        let e = Aov::parse("albedoo").unwrap_err();
        assert!(
            e.contains("\"albedoo\"") && e.contains("\"object_id\""),
            "{e}"
        );
        let names = ["depth".to_string(), "albedo".to_string()];
        assert_eq!(parse_aovs(&names), Ok(vec![Aov::Albedo, Aov::Depth]));
        let twice = ["depth".to_string(), "depth".to_string()];
        assert!(parse_aovs(&twice).unwrap_err().contains("twice"));
    }

    /// A bad name in a config file is one line naming the file, the key and the value.
    #[test]
    fn a_bad_aov_in_a_config_is_one_line_naming_file_key_and_value() {
        let path = std::path::Path::new("/tmp/scene.toml");
        let text = "scene = \"s.gltf\"\n[integrator]\nplugin = \"mcpt\"\n[output]\naovs = [\"albedo\", \"normals\"]\n";
        let e = crate::config::parse_config(path, text)
            .unwrap_err()
            .to_string();
        assert!(!e.contains('\n'), "{e}");
        for part in ["scene.toml", "output.aovs", "\"normals\"", "\"normal\""] {
            assert!(e.contains(part), "{e} lacks {part}");
        }
        let ok = text.replace("normals", "normal");
        let c = crate::config::parse_config(path, &ok).unwrap();
        assert_eq!(c.aovs, vec![Aov::Albedo, Aov::Normal]);
        assert_eq!(c.aov_spp, DEFAULT_AOV_SPP);
        let zero = format!("{ok}aov_spp = 0\n");
        let e = crate::config::parse_config(path, &zero)
            .unwrap_err()
            .to_string();
        assert!(e.contains("output.aov_spp"), "{e}");
    }
}
