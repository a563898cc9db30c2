//! The render's camera: a glTF camera the config selects and adjusts, the config's own, or
//! an automatic one framing the scene.
//!
//! # Cameras
//!
//! [`RenderConfig::camera`] builds the render's camera in this order:
//!
//! 1. **A glTF camera**: `[camera] name` selects the first camera node, in traversal order,
//!    whose camera or node has that name; `[camera] index = N` the first node that places
//!    `cameras[N]` (the glTF camera index, not the node order); neither: the first camera
//!    node. A name or index that matches nothing is an error listing the scene's cameras. The
//!    other `[camera]` keys replace parts of it (position, direction, up, projection, field of
//!    view or orthographic height).
//! 2. **The config's camera**, when the file has none: `position` and `look_at` (or
//!    `forward`) are required, `up` defaults to +Y, `fov_y` to 40°; an orthographic one needs
//!    `ortho_height`.
//! 3. **An automatic camera**, when neither places one: it looks at the centre c of the
//!    scene's bounding box from the direction
//!    d = (sin 30° cos 20°, sin 20°, cos 30° cos 20°) — front (+Z, glTF's front), right (+X)
//!    and above (+Y, glTF's up) — with up +Y and fov_y 40° (or the config's `fov_y`,
//!    `projection`, `ortho_height`, `up`). The bounding sphere (centre c, radius r = half the
//!    box's diagonal) fits the frustum exactly: a pinhole at c + d·r / sin θ, θ the smaller of
//!    the vertical and horizontal half angles (a pyramid contains the circular cone of its
//!    smaller half angle); an orthographic camera at c + 2r·d with half height
//!    r / min(1, W/H). One info line says where it was put.
//!
//! Any of them takes the thin lens of `aperture_radius` or `f_number` and `focus_distance`
//! or `focus_on` ([`super::lens`]).
//!
//! The image size is always the config's (`[render] width`, `height`): `yfov` and `ymag` are
//! kept and the horizontal extent follows W/H, as glTF viewers do in a window of another
//! shape; a glTF `aspectRatio` (or `xmag/ymag`) that differs gets a warning.

use super::RenderConfig;
use crate::error::ConfigError;
use crate::scene::{CameraDesc, CameraProjection, Scene};
use flowlight_core::camera::{Camera, Projection};
use glam::Vec3;

/// The optional `[camera]` table: which glTF camera, and the parts that replace its own
/// (module docs, "Cameras").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraOverride {
    /// Select the glTF camera whose camera or node has this name.
    pub name: Option<String>,
    /// Select glTF camera `cameras[index]`.
    pub index: Option<usize>,
    pub position: Option<Vec3>,
    pub look_at: Option<Vec3>,
    pub forward: Option<Vec3>,
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees (perspective).
    pub fov_y: Option<f32>,
    pub projection: Option<Projection>,
    /// Full height of the view in world units (orthographic).
    pub ortho_height: Option<f32>,
    /// The thin lens's keys (aperture and focus), checked one by one.
    pub lens: super::lens::LensKeys,
}

/// Vertical field of view of a camera that does not give one (the automatic camera, or a
/// config camera without `fov_y`).
pub const DEFAULT_FOV_Y_DEGREES: f32 = 40.0;
/// Azimuth of the automatic camera's direction from +Z towards +X, degrees.
pub const AUTO_AZIMUTH_DEGREES: f32 = 30.0;
/// Elevation of the automatic camera's direction above the XZ plane, degrees.
pub const AUTO_ELEVATION_DEGREES: f32 = 20.0;

/// Unit direction from the scene's centre towards the automatic camera (module docs).
pub fn auto_camera_direction() -> Vec3 {
    let (az, el) = (
        AUTO_AZIMUTH_DEGREES.to_radians(),
        AUTO_ELEVATION_DEGREES.to_radians(),
    );
    Vec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos())
}

impl RenderConfig {
    /// The camera at this config's resolution (module docs, "Cameras"): the selected glTF
    /// camera with the `[camera]` keys replacing its parts, else the config's camera, else an
    /// automatic one framing the scene.
    pub fn camera(&self, scene: &Scene) -> Result<Camera, ConfigError> {
        let o = self.camera_override.clone().unwrap_or_default();
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason,
        };
        let g = self.select_camera(scene, &o)?;
        let places = o.position.is_some() || o.look_at.is_some() || o.forward.is_some();
        if g.is_none() && !places {
            let cam = self.auto_camera(scene, &o);
            return self.with_lens(cam, scene, &o.lens);
        }
        let missing = |key: &str| {
            invalid(
                key,
                "required: the scene has no camera to take it from".into(),
            )
        };
        let position = o
            .position
            .or(g.map(|g| g.position))
            .ok_or_else(|| missing("position"))?;
        let (forward, key) = match (o.look_at, o.forward) {
            (Some(l), _) => (l.as_dvec3() - position.as_dvec3(), "look_at"),
            (None, Some(f)) => (f.as_dvec3(), "forward"),
            (None, None) => (
                g.map(|g| g.forward)
                    .ok_or_else(|| missing("look_at"))?
                    .as_dvec3(),
                "look_at",
            ),
        };
        let up = o.up.or(g.map(|g| g.up)).unwrap_or(Vec3::Y);
        // Normalised in f64: a direction such as [0, 0, 1e30] overflows f32's squared length.
        let f = forward.normalize_or_zero().as_vec3();
        if f == Vec3::ZERO {
            return Err(invalid(
                key,
                if key == "forward" {
                    "has no direction (too short)".into()
                } else {
                    "the camera looks at its own position".into()
                },
            ));
        }
        if f.cross(up.normalize_or_zero()).length_squared() < 1e-12 {
            return Err(invalid("up", "is parallel to the viewing direction".into()));
        }
        let from_file = g.map(|g| g.projection);
        if let Some(a) = g.and_then(|g| g.aspect) {
            let ours = self.width as f32 / self.height as f32;
            if (a - ours).abs() > 1e-3 * ours {
                tracing::warn!(file = %self.path.display(), "the glTF camera's aspect ratio {a} differs from the image's {ours}; the image's is used (the vertical extent is kept)");
            }
        }
        let cam = self.projected_camera(&o, from_file, position, f, up)?;
        self.with_lens(cam, scene, &o.lens)
    }

    /// The camera at `position` looking along unit `f` with the projection of `[camera]`,
    /// else the glTF camera's (`from_file`), else perspective; the field of view or the
    /// orthographic height likewise, a key of the other projection being an error.
    fn projected_camera(
        &self,
        o: &CameraOverride,
        from_file: Option<CameraProjection>,
        position: Vec3,
        f: Vec3,
        up: Vec3,
    ) -> Result<Camera, ConfigError> {
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason,
        };
        let projection = o.projection.unwrap_or(match from_file {
            Some(CameraProjection::Orthographic { .. }) => Projection::Orthographic,
            _ => Projection::Perspective,
        });
        match projection {
            Projection::Perspective => {
                if o.ortho_height.is_some() {
                    return Err(invalid(
                        "ortho_height",
                        "the camera is perspective: give `projection = \"orthographic\"` too, or use `fov_y`".into(),
                    ));
                }
                let fov = o
                    .fov_y
                    .or(match from_file {
                        Some(CameraProjection::Perspective { fov_y_degrees }) => {
                            Some(fov_y_degrees)
                        }
                        _ => None,
                    })
                    .unwrap_or(DEFAULT_FOV_Y_DEGREES);
                Ok(Camera::look_along(
                    position,
                    f,
                    up,
                    fov,
                    self.width,
                    self.height,
                ))
            }
            Projection::Orthographic => {
                if o.fov_y.is_some() {
                    return Err(invalid(
                        "fov_y",
                        "the camera is orthographic: use `ortho_height`".into(),
                    ));
                }
                let half_height = match (o.ortho_height, from_file) {
                    (Some(h), _) => 0.5 * h,
                    (None, Some(CameraProjection::Orthographic { half_height })) => half_height,
                    _ => {
                        return Err(invalid(
                            "ortho_height",
                            "required for an orthographic camera that the file does not give"
                                .into(),
                        ))
                    }
                };
                Ok(Camera::orthographic(
                    position,
                    f,
                    up,
                    half_height,
                    self.width,
                    self.height,
                ))
            }
        }
    }

    /// The glTF camera that `[camera] name` / `index` selects, else the first camera node.
    fn select_camera<'s>(
        &self,
        scene: &'s Scene,
        o: &CameraOverride,
    ) -> Result<Option<&'s CameraDesc>, ConfigError> {
        let not_found = |key: &str, what: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason: format!("{what}; {}", list_cameras(&scene.cameras)),
        };
        if let Some(name) = &o.name {
            let found = scene.cameras.iter().find(|c| {
                c.name.as_deref() == Some(name.as_str())
                    || c.node_name.as_deref() == Some(name.as_str())
            });
            return found.map(Some).ok_or_else(|| {
                not_found(
                    "name",
                    format!("no camera or camera node is named \"{name}\""),
                )
            });
        }
        if let Some(index) = o.index {
            let found = scene.cameras.iter().find(|c| c.index == index);
            return found.map(Some).ok_or_else(|| {
                not_found(
                    "index",
                    format!("no node of the scene places cameras[{index}]"),
                )
            });
        }
        Ok(scene.cameras.first())
    }

    /// The automatic camera (module docs), with the config's projection keys and `up`.
    fn auto_camera(&self, scene: &Scene, o: &CameraOverride) -> Camera {
        let (centre, radius) = match scene.bounds() {
            Some((lo, hi)) => (0.5 * (lo + hi), 0.5 * (hi - lo).length()),
            None => (Vec3::ZERO, 1.0),
        };
        let radius = if radius > 0.0 && radius.is_finite() {
            radius
        } else {
            1.0
        };
        let d = auto_camera_direction();
        let up = o.up.unwrap_or(Vec3::Y);
        let aspect = self.width as f32 / self.height as f32;
        let cam = match o.projection.unwrap_or(Projection::Perspective) {
            Projection::Perspective => {
                let fov = o.fov_y.unwrap_or(DEFAULT_FOV_Y_DEGREES);
                let tan_y = (0.5 * fov.to_radians()).tan();
                let half_angle = tan_y.atan().min((aspect * tan_y).atan());
                let position = centre + d * (radius / half_angle.sin());
                Camera::look_along(position, -d, up, fov, self.width, self.height)
            }
            Projection::Orthographic => {
                let half_height = o.ortho_height.map_or(radius / aspect.min(1.0), |h| 0.5 * h);
                let position = centre + d * (2.0 * radius);
                Camera::orthographic(position, -d, up, half_height, self.width, self.height)
            }
        };
        let p = cam.position;
        tracing::info!(
            file = %self.path.display(),
            "no camera in the scene or the config: an automatic {} camera at ({:.4}, {:.4}, {:.4}) looks at the bounding box centre ({:.4}, {:.4}, {:.4}) from the front-right-above and frames its bounding sphere (radius {:.4})",
            cam.kind().name(),
            p.x, p.y, p.z, centre.x, centre.y, centre.z, radius
        );
        cam
    }
}

/// `the scene's cameras: 0 "Main" (node 2 "Cam", perspective), …` for error messages.
fn list_cameras(cameras: &[CameraDesc]) -> String {
    if cameras.is_empty() {
        return "the scene has no cameras".into();
    }
    let all: Vec<String> = cameras.iter().map(CameraDesc::label).collect();
    format!("the scene's cameras: {}", all.join(", "))
}
