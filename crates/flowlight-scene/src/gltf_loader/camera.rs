//! The cameras the nodes place: perspective or orthographic projection, position and frame
//! from the node's world transform. A camera whose transform collapses an axis is skipped
//! with a warning.

use super::Loader;
use crate::error::SceneError;
use crate::scene::{CameraDesc, CameraProjection};
use glam::{Mat4, Vec3};

impl Loader<'_> {
    /// Records the camera that `node` places (world transform `world`). Every camera node is
    /// kept, in traversal order; the render config chooses one ([`crate::config`]).
    pub(super) fn camera(
        &mut self,
        cam: &gltf::Camera,
        node: &gltf::Node,
        world: Mat4,
    ) -> Result<(), SceneError> {
        let err = |reason: String| SceneError::Camera {
            file: self.file(),
            reason,
        };
        let index = cam.index();
        let (projection, aspect) = match cam.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = p.yfov();
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(err(format!(
                        "cameras[{index}].perspective.yfov: {yfov} is not in (0, π)"
                    )));
                }
                let aspect = p.aspect_ratio();
                if aspect.is_some_and(|a| !(a > 0.0 && a.is_finite())) {
                    return Err(err(format!(
                        "cameras[{index}].perspective.aspectRatio must be positive"
                    )));
                }
                (
                    CameraProjection::Perspective {
                        fov_y_degrees: yfov.to_degrees(),
                    },
                    aspect,
                )
            }
            gltf::camera::Projection::Orthographic(o) => {
                // The spec: xmag and ymag MUST NOT be zero and SHOULD NOT be negative; a
                // negative one would mirror the image, so only its magnitude is used.
                let mut mag = [0.0f32; 2];
                for (k, (key, v)) in [("xmag", o.xmag()), ("ymag", o.ymag())]
                    .into_iter()
                    .enumerate()
                {
                    if !(v != 0.0 && v.is_finite()) {
                        return Err(err(format!(
                            "cameras[{index}].orthographic.{key}: {v} must be finite and not zero"
                        )));
                    }
                    if v < 0.0 {
                        tracing::warn!(file = %self.src.file.display(), "cameras[{index}].orthographic.{key} is negative ({v}); its magnitude is used");
                    }
                    mag[k] = v.abs();
                }
                (
                    CameraProjection::Orthographic {
                        half_height: mag[1],
                    },
                    Some(mag[0] / mag[1]),
                )
            }
        };
        let position = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
        if forward == Vec3::ZERO
            || up == Vec3::ZERO
            || forward.cross(up).length_squared() < 1e-12
            || !position.is_finite()
        {
            // A zero scale is valid glTF (it hides a node): such a camera cannot look anywhere,
            // so it is left out with a warning rather than failing the whole file.
            tracing::warn!(file = %self.src.file.display(), "node {} places cameras[{index}] with a degenerate transform (zero scale or a collapsed axis); that camera node is skipped", node.index());
            return Ok(());
        }
        self.scene.cameras.push(CameraDesc {
            index,
            name: cam.name().map(str::to_string),
            node: node.index(),
            node_name: node.name().map(str::to_string),
            position,
            forward,
            up,
            projection,
            aspect,
        });
        Ok(())
    }
}
