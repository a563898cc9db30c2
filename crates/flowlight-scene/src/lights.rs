//! Lights of a loaded scene: `KHR_lights_punctual` lights placed by their nodes, the
//! emissive-triangle integration behind the emitter table, the `[environment]` of the render
//! config, and the one power CDF over all of them.
//!
//! - Punctual lights: position = the node's world origin, direction = its world −Z (scale
//!   ignored, as the extension says); intensity = `color × intensity / 683` (candela for point
//!   and spot, lux for directional, converted to W/sr and W/m² as Blender's importer does, see
//!   [`flowlight_core::light::punctual`]). `range` is ignored (one info line per file).
//! - Emissive triangles: the mean emitted radiance over a triangle is estimated from
//!   n² stratified points (Heitz's uniform triangle map of a jitter-free grid of cell
//!   centres), n from [`emission_strata`] (about two points per covered texel), each
//!   `Material::emission_at` of both uv sets. A triangle whose mean
//!   is zero is not a light; its mean times π·area is its power.
//! - Environment: `color` (constant) or `map` (`.exr` or `.hdr`, equirectangular, +Y up),
//!   times `strength`, turned by `rotation_degrees` about +Y.

use crate::config::EnvironmentConfig;
use crate::error::{ConfigError, SceneError};
use crate::scene::Scene;
use flowlight_core::light::environment::{build_map_distribution, MapDistribution};
use flowlight_core::light::{light_powers, Emitter, Environment, PunctualLight};
use flowlight_core::material::{Texture, TextureRef};
use flowlight_core::sampling::{build_cdf, uniform_triangle};
use flowlight_core::Rgb;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::path::{Path, PathBuf};

/// Strata per side for the emission integral of one triangle (16 points).
pub const EMISSION_STRATA: usize = 4;

/// Mean of `emission(b)` over a triangle, from stratified points (`b` their barycentrics).
pub fn mean_emission(strata: usize, mut emission: impl FnMut([f32; 3]) -> Rgb) -> Rgb {
    let n = strata.max(1);
    let mut sum = Rgb::ZERO;
    for i in 0..n {
        for j in 0..n {
            let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            sum += emission(uniform_triangle(u));
        }
    }
    sum / (n * n) as f32
}

/// Most strata per side [`emission_strata`] gives a triangle (256² = 65,536 look-ups).
pub const MAX_EMISSION_STRATA: usize = 256;

/// Strata per side for [`mean_emission`] on emitter `e` whose emission texture is `tex`:
/// enough that every texel the triangle covers gets about two samples,
/// n = ⌈√(2·T)⌉ with T the triangle's uv area × the texture's texels (× the texture
/// transform's area scale), between [`EMISSION_STRATA`] and [`MAX_EMISSION_STRATA`]. Fewer
/// would miss a small lit feature in a big triangle and drop the triangle as black (its light
/// lost); the cost is about twice the texture's texel count per uv layout.
pub fn emission_strata(e: &Emitter, tex: &TextureRef, textures: &[Texture]) -> usize {
    let Some(t) = usize::try_from(tex.index)
        .ok()
        .and_then(|i| textures.get(i))
    else {
        return EMISSION_STRATA;
    };
    let uv = if tex.tex_coord == 1 { e.uv1 } else { e.uv0 };
    let (a, b) = (uv[1] - uv[0], uv[2] - uv[0]);
    let m = tex.transform;
    let det = (m[0] * m[3] - m[2] * m[1]).abs();
    let texels = 0.5 * a.perp_dot(b).abs() * det * t.width as f32 * t.height as f32;
    if !texels.is_finite() {
        return MAX_EMISSION_STRATA;
    }
    ((2.0 * texels).sqrt().ceil() as usize).clamp(EMISSION_STRATA, MAX_EMISSION_STRATA)
}

use flowlight_core::light::punctual::LUMENS_PER_WATT;

/// A `KHR_lights_punctual` light at a node with world transform `world`.
pub fn punctual_light(
    file: &Path,
    light: &gltf::khr_lights_punctual::Light,
    world: Mat4,
) -> Result<PunctualLight, SceneError> {
    let err = |reason: String| SceneError::Light {
        file: file.to_path_buf(),
        light: light.index(),
        reason,
    };
    let color = Rgb::from_array(light.color());
    let intensity = light.intensity();
    if !(color.is_valid_radiance() && intensity >= 0.0 && intensity.is_finite()) {
        return Err(err(format!(
            "color {:?} and intensity {intensity} must be finite and non-negative",
            light.color()
        )));
    }
    let position = world.transform_point3(Vec3::ZERO);
    let direction = (Mat3::from_mat4(world) * -Vec3::Z).normalize_or_zero();
    if !position.is_finite() || direction == Vec3::ZERO || !direction.is_finite() {
        return Err(err("its node transform is degenerate".into()));
    }
    // Photometric (cd, lx) to radiometric (W/sr, W/m²) units, as Blender's importer does.
    let i = color * (intensity / LUMENS_PER_WATT);
    use gltf::khr_lights_punctual::Kind;
    Ok(match light.kind() {
        Kind::Point => PunctualLight::point(position, i),
        Kind::Directional => PunctualLight::directional(direction, i),
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let half_pi = std::f32::consts::FRAC_PI_2;
            if !(inner_cone_angle >= 0.0
                && inner_cone_angle < outer_cone_angle
                && outer_cone_angle <= half_pi + 1e-6)
            {
                return Err(err(format!(
                    "spot cone angles must satisfy 0 ≤ innerConeAngle ({inner_cone_angle}) < outerConeAngle ({outer_cone_angle}) ≤ π/2"
                )));
            }
            PunctualLight::spot(position, direction, i, inner_cone_angle, outer_cone_angle)
        }
    })
}

/// A loaded environment: owns the map and its sampling tables that [`EnvironmentData::view`]
/// points into.
#[derive(Clone, Debug, Default)]
pub struct EnvironmentData {
    pub constant: Option<Rgb>,
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Rgb>,
    pub distribution: Option<MapDistribution>,
    pub strength: f32,
    pub rotation_degrees: f32,
    pub source: Option<PathBuf>,
}

impl EnvironmentData {
    /// The plugin-side view; valid while `self` lives (its buffers never move).
    pub fn view(&self) -> Environment {
        if let Some(c) = self.constant {
            if c.is_black() {
                return Environment::none();
            }
            return Environment::constant(c);
        }
        match &self.distribution {
            Some(d) => Environment::map(
                self.width,
                self.height,
                &self.texels,
                d,
                self.strength,
                self.rotation_degrees,
            ),
            None => Environment::none(),
        }
    }
}

/// Loads the config's `[environment]`: a constant colour or a decoded lat-long map.
pub fn load_environment(
    config_file: &Path,
    env: &EnvironmentConfig,
) -> Result<EnvironmentData, ConfigError> {
    let invalid = |key: &str, reason: String| ConfigError::Invalid {
        file: config_file.to_path_buf(),
        key: key.into(),
        reason,
    };
    if let Some(c) = env.color {
        return Ok(EnvironmentData {
            constant: Some(Rgb::from_array(c) * env.strength),
            strength: env.strength,
            rotation_degrees: env.rotation_degrees,
            ..Default::default()
        });
    }
    let Some(map) = &env.map else {
        return Ok(EnvironmentData::default());
    };
    // Read as any input file (a regular file, its size known first), then decoded without
    // the decoder's own 512 MiB cap, which a valid 16k map exceeds.
    let bytes = crate::files::read_regular_file(map, crate::files::MAX_INPUT_FILE_BYTES)
        .map_err(|e| invalid("environment.map", format!("{}: {e}", map.display())))?;
    let format = image::ImageFormat::from_path(map)
        .map_err(|e| invalid("environment.map", format!("{}: {e}", map.display())))?;
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(&bytes), format);
    let mut limits = image::Limits::no_limits();
    limits.max_alloc = crate::memory::available_memory();
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| invalid("environment.map", format!("{}: {e}", map.display())))?
        .into_rgb32f();
    let (width, height) = img.dimensions();
    let texels: Vec<Rgb> = img
        .pixels()
        .map(|p| Rgb::new(p.0[0], p.0[1], p.0[2]))
        .collect();
    if let Some(bad) = texels.iter().position(|t| !t.is_valid_radiance()) {
        return Err(invalid(
            "environment.map",
            format!(
                "{}: texel ({}, {}) is negative or not finite",
                map.display(),
                bad as u32 % width.max(1),
                bad as u32 / width.max(1)
            ),
        ));
    }
    let distribution = build_map_distribution(width, height, &texels);
    if distribution.is_none() {
        tracing::warn!(file = %config_file.display(), "environment map {} is black everywhere: no environment light", map.display());
    }
    Ok(EnvironmentData {
        constant: None,
        width,
        height,
        texels,
        distribution,
        strength: env.strength,
        rotation_degrees: env.rotation_degrees,
        source: Some(map.clone()),
    })
}

/// Radius of the bounding sphere of the scene's triangles (for distant lights' power).
pub fn scene_radius(scene: &Scene) -> f32 {
    scene
        .bounds()
        .map_or(1.0, |(lo, hi)| ((hi - lo).length() * 0.5).max(1e-6))
}

/// The power CDF over all lights (area emitters, punctual lights, environment); empty only
/// when there is no light. Lights that all carry no power (a lamp switched off, a black
/// colour, a spot cone closed to nothing) get a uniform CDF: the plugins' light tables hold
/// one CDF entry per light, and sampling such a light adds nothing.
pub fn light_power_cdf(scene: &Scene, environment: &Environment) -> Vec<f32> {
    let powers = scene_light_powers(scene, environment);
    build_cdf(&powers).unwrap_or_else(|| {
        let n = powers.len();
        (1..=n).map(|i| i as f32 / n as f32).collect()
    })
}

fn scene_light_powers(scene: &Scene, environment: &Environment) -> Vec<f32> {
    light_powers(
        &scene.emitters,
        &scene.punctual_lights,
        environment,
        scene_radius(scene),
    )
}

/// What the scene's lights give the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightPresence {
    /// No emissive triangle, punctual light or environment.
    NoLight,
    /// Lights, none of which carries power: the image is black.
    NoPower,
    /// At least one light carries power.
    Lit,
}

impl LightPresence {
    /// The warning a render of a scene without power gives, naming the cause.
    pub fn warning(self) -> Option<&'static str> {
        match self {
            LightPresence::NoLight => Some("the scene has no light (no emissive triangle, no KHR_lights_punctual light, no [environment]): the image will be black; add e.g. `[environment] color = [1, 1, 1]` to the config"),
            LightPresence::NoPower => Some("the scene's lights all carry no power (intensity 0, a black colour or a spot cone closed to nothing, as a lamp switched off in Blender): the image will be black"),
            LightPresence::Lit => None,
        }
    }
}

/// Whether the scene has lights that carry power; an error naming the light whose power is
/// not finite (radiance beyond what 32-bit floats hold once multiplied by its area, its
/// cone or the scene's size), which would otherwise leave no usable light CDF and a black
/// image.
pub fn light_presence(scene: &Scene, environment: &Environment) -> Result<LightPresence, String> {
    let powers = scene_light_powers(scene, environment);
    let (na, np) = (scene.emitters.len(), scene.punctual_lights.len());
    if let Some(i) = powers.iter().position(|p| !p.is_finite()) {
        let what = if i < na {
            format!(
                "the emissive triangle {} (material {})",
                scene.emitters[i].prim, scene.emitters[i].material
            )
        } else if i < na + np {
            format!("KHR_lights_punctual light {} (in scene order)", i - na)
        } else {
            "[environment]".to_string()
        };
        return Err(format!(
            "{what} carries an infinite power: its radiance times its extent overflows 32-bit floats (3.4e38); lower its strength or intensity"
        ));
    }
    Ok(if powers.is_empty() {
        LightPresence::NoLight
    } else if powers.iter().all(|&p| p == 0.0) {
        LightPresence::NoPower
    } else {
        LightPresence::Lit
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_emission_sees_a_black_half() {
        let e = Emitter {
            p0: Vec3::ZERO,
            p1: Vec3::X,
            p2: Vec3::Y,
            n: Vec3::Z,
            area: 0.5,
            radiance: Rgb::ZERO,
            double_sided: 0,
            prim: 0,
            material: 0,
            uv0: [Vec2::ZERO, Vec2::X, Vec2::Y],
            uv1: [Vec2::ZERO; 3],
            color: [Rgb::ONE; 3],
            vertex_colored: 0,
        };
        // Emits 2 where u < 0.5: the mean over the triangle is the emitting area's share
        // (3/4 of the triangle has u < 1/2) times 2, up to the strata's resolution.
        let m = mean_emission(EMISSION_STRATA, |b| {
            if e.uv_at(b)[0].x < 0.5 {
                Rgb::splat(2.0)
            } else {
                Rgb::ZERO
            }
        });
        assert!((m.r - 1.5).abs() < 0.2, "{m:?}");
        // Black where the triangle lies entirely in the black half: no light.
        let mut black = e;
        black.uv0 = [
            Vec2::new(0.6, 0.0),
            Vec2::new(0.9, 0.0),
            Vec2::new(0.6, 0.3),
        ];
        let m = mean_emission(EMISSION_STRATA, |b| {
            if black.uv_at(b)[0].x < 0.5 {
                Rgb::splat(2.0)
            } else {
                Rgb::ZERO
            }
        });
        assert!(m.is_black());
    }
}
