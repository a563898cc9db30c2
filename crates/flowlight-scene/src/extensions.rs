//! The glTF extensions this loader knows, as data, and the check of a file's
//! `extensionsUsed` / `extensionsRequired` against them.
//!
//! glTF 2.0 §3.12: every extension a file uses is listed in `extensionsUsed`; those a loader
//! must understand to load the file at all are also in `extensionsRequired`. So:
//!
//! * an extension in [`KNOWN`] with [`Status::Supported`] is honoured;
//! * one with [`Status::Ignored`] is skipped with one warning line naming it when it is
//!   optional, and refused with an error when it is required (a required extension cannot be
//!   ignored: the file's data is wrong without it);
//! * one with [`Status::Refused`] is an error whether optional or required, with its note
//!   saying what to do instead;
//! * an unknown optional extension gives one warning line naming it; an unknown required one is
//!   an error naming it.
//!
//! `docs/gltf.md` ("Geometry, compression and instancing" and the sections after it) lists the
//! same names and statuses; `tests/extensions_doc.rs` checks that the two agree.

/// What the loader does with an extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// Decoded or honoured.
    Supported,
    /// Skipped with a warning when optional; an error when required.
    Ignored,
    /// Always an error, with the note saying what to do.
    Refused,
}

impl Status {
    /// The word used in `docs/gltf.md`.
    pub fn doc_name(self) -> &'static str {
        match self {
            Status::Supported => "supported",
            Status::Ignored => "ignored-with-warning",
            Status::Refused => "refused",
        }
    }
}

/// One known extension.
#[derive(Clone, Copy, Debug)]
pub struct Extension {
    pub name: &'static str,
    pub status: Status,
    /// One line for the docs and for warnings.
    pub note: &'static str,
}

const fn ext(name: &'static str, status: Status, note: &'static str) -> Extension {
    Extension { name, status, note }
}

/// Every extension the loader knows. Material, texture, light and camera entries are kept
/// here too so that one table decides; their owners update the status as support lands.
pub const KNOWN: &[Extension] = &[
    // Geometry, compression and instancing.
    ext(
        "KHR_mesh_quantization",
        Status::Supported,
        "(normalized) byte/short POSITION, NORMAL, TANGENT, TEXCOORD; normalized to [-1,1]/[0,1] as the spec says, otherwise plain integer values",
    ),
    ext(
        "EXT_meshopt_compression",
        Status::Supported,
        "buffer views decoded with meshoptimizer (modes ATTRIBUTES, TRIANGLES, INDICES; filters NONE, OCTAHEDRAL, QUATERNION, EXPONENTIAL); the fallback buffer is never read",
    ),
    ext(
        "KHR_draco_mesh_compression",
        Status::Supported,
        "decoded with draco-core (pure Rust); float attributes and indices; an accessor with uncompressed fallback data is read as it is",
    ),
    ext(
        "EXT_mesh_gpu_instancing",
        Status::Supported,
        "TRANSLATION / ROTATION / SCALE per instance, composed after the node's world transform; every instance renders",
    ),
    // Materials.
    ext(
        "KHR_materials_emissive_strength",
        Status::Supported,
        "multiplies emissiveFactor",
    ),
    ext(
        "KHR_materials_ior",
        Status::Supported,
        "see the materials section",
    ),
    ext(
        "KHR_materials_transmission",
        Status::Supported,
        "see the materials section",
    ),
    ext(
        "KHR_materials_volume",
        Status::Supported,
        "thickness, attenuation colour and distance: refraction and Beer–Lambert absorption inside closed meshes (see the materials section)",
    ),
    ext(
        "KHR_materials_specular",
        Status::Supported,
        "specularFactor and specularColorFactor, times specularTexture (A) and specularColorTexture (RGB, sRGB), set the dielectric's F0 colour and F90 (see the materials section)",
    ),
    ext(
        "KHR_materials_clearcoat",
        Status::Supported,
        "a GGX layer with F0 0.04 over the rest; clearcoatTexture (R) and clearcoatRoughnessTexture (G) applied, clearcoatNormalTexture ignored with a warning (see the materials section)",
    ),
    ext(
        "KHR_materials_sheen",
        Status::Supported,
        "Charlie sheen layer with the extension's albedo scaling of the layers beneath; sheenColorTexture (RGB, sRGB) and sheenRoughnessTexture (A) applied (see the materials section)",
    ),
    ext(
        "KHR_materials_iridescence",
        Status::Supported,
        "thin-film Fresnel in RGB (Belcour & Barla 2017) mixed into the specular layer; iridescenceTexture (R) and iridescenceThicknessTexture (G) applied (see the materials section)",
    ),
    ext(
        "KHR_materials_anisotropy",
        Status::Supported,
        "anisotropic GGX specular layer along the direction in the tangent frame; anisotropyTexture (RG direction, B strength) applied (see the materials section)",
    ),
    ext(
        "KHR_materials_dispersion",
        Status::Ignored,
        "renders in RGB, no dispersion",
    ),
    ext(
        "KHR_materials_diffuse_transmission",
        Status::Supported,
        "a Lambertian transmission part of the diffuse base to the back side; diffuseTransmissionTexture (A) and diffuseTransmissionColorTexture (RGB, sRGB) applied (see the materials section)",
    ),
    ext(
        "KHR_materials_unlit",
        Status::Supported,
        "the surface emits its base colour (factor × texture) and scatters nothing; it casts light like any emitter (see the materials section)",
    ),
    ext(
        "KHR_materials_variants",
        Status::Ignored,
        "the default material of each primitive is used",
    ),
    ext(
        "KHR_materials_pbrSpecularGlossiness",
        Status::Supported,
        "converted as KHR_materials_specular says: diffuse → base colour, specular → specular colour with ior 0 (F0 = specular), roughness 1 − glossiness, metallic 0 (see the materials section)",
    ),
    // Textures.
    ext(
        "KHR_texture_transform",
        Status::Supported,
        "offset, rotation, scale and texCoord override on every texture reference (see the textures section)",
    ),
    ext(
        "KHR_texture_basisu",
        Status::Ignored,
        "KTX2/Basis images are not decoded; the fallback image is used when there is one",
    ),
    ext(
        "EXT_texture_webp",
        Status::Supported,
        "WebP images (lossy and lossless, with alpha) decoded with image-webp (pure Rust); the extension's source is used, the fallback image is not read",
    ),
    ext(
        "EXT_texture_avif",
        Status::Ignored,
        "AVIF images are not decoded; the fallback image is used when there is one",
    ),
    ext(
        "MSFT_texture_dds",
        Status::Ignored,
        "DDS images are not decoded; the fallback image is used when there is one",
    ),
    // Lights.
    ext(
        "KHR_lights_punctual",
        Status::Supported,
        "point, spot and directional lights, sampled by next-event estimation (see the lights section)",
    ),
    // Metadata and animation: nothing to render.
    ext(
        "KHR_xmp_json_ld",
        Status::Ignored,
        "metadata only",
    ),
    ext(
        "KHR_animation_pointer",
        Status::Ignored,
        "a still image renders the rest pose",
    ),
];

/// Whether the loader supports extension `name` (a known one with [`Status::Supported`]).
pub fn is_supported(name: &str) -> bool {
    lookup(name).is_some_and(|e| e.status == Status::Supported)
}

/// The entry for `name`, if the loader knows it.
pub fn lookup(name: &str) -> Option<&'static Extension> {
    KNOWN.iter().find(|e| e.name == name)
}

/// The refusal of a known extension that the file requires but the loader does not support:
/// one line naming it. The note of an ignored extension is left out, since it says what
/// happens when the extension is optional (a fallback used, a feature skipped), which is not
/// what happens here; a refused extension's note says what to do instead, so it stays.
fn required_unsupported(name: &str, e: &Extension) -> String {
    let head = format!(
        "extensionsRequired: the file requires extension {name}, which this renderer does not support"
    );
    match e.status {
        Status::Refused => format!("{head} ({})", e.note),
        _ => head,
    }
}

/// Checks a file's `extensionsUsed` and `extensionsRequired`. Returns the warning lines to log
/// (one per ignored or unknown optional extension, in file order), or the error reason for the
/// first extension that cannot be loaded.
pub fn check(used: &[String], required: &[String]) -> Result<Vec<String>, String> {
    for name in required {
        match lookup(name) {
            None => {
                return Err(format!(
                    "extensionsRequired: unknown extension {name}; the file cannot be loaded without it"
                ))
            }
            Some(e) if e.status == Status::Supported => {}
            Some(e) => return Err(required_unsupported(name, e)),
        }
    }
    let mut warnings = Vec::new();
    let mut seen = Vec::new();
    for name in used.iter().chain(required) {
        if seen.contains(&name) || required.contains(name) {
            continue;
        }
        seen.push(name);
        match lookup(name) {
            None => warnings.push(format!(
                "extensionsUsed: unknown optional extension {name} is ignored"
            )),
            Some(e) => match e.status {
                Status::Supported => {}
                Status::Ignored => warnings.push(format!(
                    "extensionsUsed: optional extension {name} is ignored ({})",
                    e.note
                )),
                Status::Refused => {
                    return Err(format!(
                        "extensionsUsed: extension {name} is not supported ({})",
                        e.note
                    ))
                }
            },
        }
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn names_are_unique() {
        for (i, a) in KNOWN.iter().enumerate() {
            assert!(
                KNOWN[i + 1..].iter().all(|b| b.name != a.name),
                "{} listed twice",
                a.name
            );
        }
    }

    #[test]
    fn unknown_optional_warns_once_unknown_required_fails() {
        let w = check(&s(&["EXT_foo", "KHR_mesh_quantization", "EXT_foo"]), &[]).unwrap();
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("EXT_foo"), "{w:?}");
        let e = check(&s(&["EXT_foo"]), &s(&["EXT_foo"])).unwrap_err();
        assert!(
            e.contains("EXT_foo") && e.contains("extensionsRequired"),
            "{e}"
        );
    }

    #[test]
    fn an_ignored_required_extension_is_refused_in_one_line_without_its_fallback_note() {
        for e in KNOWN.iter().filter(|e| e.status == Status::Ignored) {
            let err = check(&s(&[e.name]), &s(&[e.name])).unwrap_err();
            assert!(!err.contains('\n'), "{err}");
            assert!(err.contains(e.name), "{err}");
            assert!(
                err.contains("requires") && err.contains("does not support"),
                "{err}"
            );
            // The optional case's note ("the fallback image is used", "ignored") would
            // contradict the refusal.
            assert!(!err.contains(e.note), "{err}");
        }
    }

    #[test]
    fn supported_required_passes_ignored_required_fails() {
        assert_eq!(
            check(
                &s(&["KHR_mesh_quantization"]),
                &s(&["KHR_mesh_quantization"])
            )
            .unwrap(),
            Vec::<String>::new()
        );
        let w = check(&s(&["KHR_materials_dispersion"]), &[]).unwrap();
        assert!(w[0].contains("KHR_materials_dispersion"), "{w:?}");
        assert!(check(&[], &s(&["KHR_materials_dispersion"])).is_err());
    }
}
