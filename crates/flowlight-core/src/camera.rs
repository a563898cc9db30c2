//! Perspective pinhole camera.

use crate::geometry::Ray;
use glam::{Vec2, Vec3};

/// A pinhole camera. Raster coordinates run from (0,0) at the top-left corner of the image to
/// (width, height) at the bottom-right; pixel (i, j) covers [i, i+1) × [j, j+1).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit vector towards the right of the image.
    pub right: Vec3,
    /// Unit vector towards the top of the image.
    pub up: Vec3,
    /// tan(vertical field of view / 2).
    pub tan_half_fov_y: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Builds a camera at `position` looking along `forward` with the given approximate `up`.
    pub fn look_along(
        position: Vec3,
        forward: Vec3,
        up: Vec3,
        fov_y_degrees: f32,
        width: u32,
        height: u32,
    ) -> Camera {
        let forward = forward.normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        Camera {
            position,
            forward,
            right,
            up,
            tan_half_fov_y: (fov_y_degrees.to_radians() * 0.5).tan(),
            width,
            height,
        }
    }

    #[inline]
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Primary ray through raster position `raster` (pixel coordinates, may be fractional).
    #[inline]
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let ndc_x = 2.0 * raster.x / self.width as f32 - 1.0;
        let ndc_y = 1.0 - 2.0 * raster.y / self.height as f32;
        let dir = self.forward
            + self.right * (ndc_x * self.tan_half_fov_y * self.aspect())
            + self.up * (ndc_y * self.tan_half_fov_y);
        Ray::new(self.position, dir.normalize(), f32::INFINITY)
    }

    /// Raster position of world point `p`, or `None` when it is behind the camera or off the
    /// film. Inverse of [`Camera::generate_ray`]; used by mutations that move the eye vertex.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let d = p - self.position;
        let z = d.dot(self.forward);
        if z <= 0.0 {
            return None;
        }
        let x = d.dot(self.right) / (z * self.tan_half_fov_y * self.aspect());
        let y = d.dot(self.up) / (z * self.tan_half_fov_y);
        let raster = Vec2::new(
            (x + 1.0) * 0.5 * self.width as f32,
            (1.0 - y) * 0.5 * self.height as f32,
        );
        (raster.x >= 0.0
            && raster.y >= 0.0
            && raster.x < self.width as f32
            && raster.y < self.height as f32)
            .then_some(raster)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_generate_ray() {
        let cam = Camera::look_along(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(0.2, -0.1, 1.0),
            Vec3::Y,
            40.0,
            64,
            48,
        );
        for raster in [
            Vec2::new(0.5, 0.5),
            Vec2::new(32.0, 24.0),
            Vec2::new(63.2, 40.7),
        ] {
            let r = cam.generate_ray(raster);
            let back = cam.project(r.at(5.0)).unwrap();
            assert!((back - raster).length() < 1e-3, "{raster} -> {back}");
        }
        let centre = cam.generate_ray(Vec2::new(32.0, 24.0));
        assert!((centre.dir - cam.forward).length() < 1e-5);
    }
}
