//! `[camera]`'s thin lens: the aperture and the distance in focus
//! (`flowlight_core::thin_lens` for the model).
//!
//! * **Aperture**: `aperture_radius` R in world units (metres in glTF), or `f_number` N with
//!   `sensor_height_mm` h (default 24 mm, a full-frame sensor's height). The focal length that
//!   puts the camera's vertical field of view 2θ on a sensor of height h is
//!   F = h / (2 tan θ), and the aperture's radius is R = F / (2N): a 40° camera on full frame
//!   has F = 33 mm, and f/2 gives R = 8.2 mm. Neither, or R = 0: a pinhole, and the image is
//!   bit for bit the one of a camera without these keys.
//! * **Focus**: `focus_distance` f_d in world units along the viewing axis, or
//!   `focus_on = "node name"`: f_d = (p − o)·forward for the world position p of the glTF
//!   node of that name (the first in traversal order). A lens needs one of them.
//!
//! A lens is for perspective cameras; with an orthographic one the aperture keys are an error.

use super::RenderConfig;
use crate::error::ConfigError;
use crate::scene::Scene;
use flowlight_core::camera::{Camera, Projection};

/// Height of the sensor that `f_number` assumes without `sensor_height_mm`: 24 mm, a
/// full-frame (36 × 24 mm) sensor's.
pub const DEFAULT_SENSOR_HEIGHT_MM: f32 = 24.0;

/// The lens keys as the file gives them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawLens {
    pub aperture_radius: Option<f32>,
    pub f_number: Option<f32>,
    pub sensor_height_mm: Option<f32>,
    pub focus_distance: Option<f32>,
    pub focus_on: Option<String>,
}

/// How large the aperture is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Aperture {
    /// The lens radius in world units.
    Radius(f32),
    /// An f-number on a sensor of this height in millimetres.
    FNumber { n: f32, sensor_height_mm: f32 },
}

/// Where the lens focuses.
#[derive(Clone, Debug, PartialEq)]
pub enum Focus {
    Distance(f32),
    /// The named glTF node's depth along the viewing axis.
    Node(String),
}

/// The checked lens keys of `[camera]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LensKeys {
    pub aperture: Option<Aperture>,
    pub focus: Option<Focus>,
}

/// Checks the lens keys one by one (each error names its key): finite, positive values, one
/// of each exclusive pair, and a perspective projection where the file says which.
pub fn lens_keys(
    raw: RawLens,
    projection: Option<Projection>,
    invalid: &impl Fn(&str, String) -> ConfigError,
) -> Result<LensKeys, ConfigError> {
    if let Some(r) = raw.aperture_radius {
        if !(r >= 0.0 && r.is_finite()) {
            return Err(invalid(
                "camera.aperture_radius",
                format!("{r} is not a radius ≥ 0 in world units"),
            ));
        }
        if raw.f_number.is_some() {
            return Err(invalid(
                "camera.f_number",
                "give either `aperture_radius` or `f_number`, not both".into(),
            ));
        }
    }
    if let Some(n) = raw.f_number {
        if !(n > 0.0 && n.is_finite()) {
            return Err(invalid(
                "camera.f_number",
                format!("{n} is not a positive f-number"),
            ));
        }
    }
    if let Some(h) = raw.sensor_height_mm {
        if raw.f_number.is_none() {
            return Err(invalid(
                "camera.sensor_height_mm",
                "is only used with `f_number`".into(),
            ));
        }
        if !(h > 0.0 && h.is_finite()) {
            return Err(invalid(
                "camera.sensor_height_mm",
                format!("{h} is not a positive height in millimetres"),
            ));
        }
    }
    if let Some(d) = raw.focus_distance {
        if !(d > 0.0 && d.is_finite()) {
            return Err(invalid(
                "camera.focus_distance",
                format!("{d} is not a positive distance in world units"),
            ));
        }
        if raw.focus_on.is_some() {
            return Err(invalid(
                "camera.focus_on",
                "give either `focus_distance` or `focus_on`, not both".into(),
            ));
        }
    }
    let aperture = match (raw.aperture_radius, raw.f_number) {
        (Some(r), _) => Some(Aperture::Radius(r)),
        (None, Some(n)) => Some(Aperture::FNumber {
            n,
            sensor_height_mm: raw.sensor_height_mm.unwrap_or(DEFAULT_SENSOR_HEIGHT_MM),
        }),
        (None, None) => None,
    };
    if aperture.is_some() && projection == Some(Projection::Orthographic) {
        let key = if raw.f_number.is_some() {
            "camera.f_number"
        } else {
            "camera.aperture_radius"
        };
        return Err(invalid(
            key,
            "a thin lens needs a perspective camera".into(),
        ));
    }
    let focus = match (raw.focus_distance, raw.focus_on) {
        (Some(d), _) => Some(Focus::Distance(d)),
        (None, Some(name)) => Some(Focus::Node(name)),
        (None, None) => None,
    };
    Ok(LensKeys { aperture, focus })
}

/// The lens radius R = F / (2N) of f-number `n` for a camera whose vertical half field of
/// view has tangent `tan_half_fov_y`, on a sensor `sensor_height_mm` high: F = h / (2 tan θ)
/// (module docs). In metres, the glTF unit.
pub fn f_number_radius(n: f32, sensor_height_mm: f32, tan_half_fov_y: f32) -> f32 {
    let focal_length = (sensor_height_mm * 1e-3) / (2.0 * tan_half_fov_y);
    focal_length / (2.0 * n)
}

impl RenderConfig {
    /// `camera` with the thin lens of `keys` (module docs); unchanged without an aperture or
    /// with a radius of 0.
    pub(super) fn with_lens(
        &self,
        camera: Camera,
        scene: &Scene,
        keys: &LensKeys,
    ) -> Result<Camera, ConfigError> {
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason,
        };
        let Some(aperture) = keys.aperture else {
            return Ok(camera);
        };
        let key = match aperture {
            Aperture::Radius(_) => "aperture_radius",
            Aperture::FNumber { .. } => "f_number",
        };
        if camera.kind() != Projection::Perspective {
            return Err(invalid(
                key,
                "a thin lens needs a perspective camera (this one is orthographic)".into(),
            ));
        }
        let radius = match aperture {
            Aperture::Radius(r) => r,
            Aperture::FNumber {
                n,
                sensor_height_mm,
            } => f_number_radius(n, sensor_height_mm, camera.tan_half_fov_y),
        };
        let focus = match &keys.focus {
            Some(Focus::Distance(d)) => *d,
            Some(Focus::Node(name)) => {
                let Some(node) = scene.named_nodes.iter().find(|n| &n.name == name) else {
                    return Err(invalid(
                        "focus_on",
                        format!(
                            "no node of the scene is named \"{name}\" ({} named nodes)",
                            scene.named_nodes.len()
                        ),
                    ));
                };
                let depth = (node.position - camera.position).dot(camera.forward);
                if !(depth > 0.0 && depth.is_finite()) {
                    return Err(invalid(
                        "focus_on",
                        format!("node \"{name}\" is not in front of the camera (depth {depth})"),
                    ));
                }
                depth
            }
            None if radius == 0.0 => return Ok(camera),
            None => {
                return Err(invalid(
                    "focus_distance",
                    format!("a lens (`{key}`) needs `focus_distance` or `focus_on`"),
                ))
            }
        };
        if radius == 0.0 {
            return Ok(camera);
        }
        Ok(camera.with_thin_lens(radius, focus))
    }
}
