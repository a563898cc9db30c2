//! The camera: a pinhole (perspective) or an orthographic projection onto the film.
//!
//! Raster coordinates run from (0,0) at the top-left corner of the image to (W, H) at the
//! bottom-right; pixel (i, j) covers [i, i+1) × [j, j+1). A raster position (x, y) has
//! normalised device coordinates
//!
//! ```text
//! u = 2x/W − 1 ∈ [−1, 1] (right),   v = 1 − 2y/H ∈ [−1, 1] (up),   a = W/H.
//! ```
//!
//! With the camera frame (position o, unit forward f, right r, up t):
//!
//! * **perspective** (pinhole, half vertical field of view θ): every ray starts at o with
//!   direction normalize(f + r·u·a·tan θ + t·v·tan θ). Inverse: for d = p − o and
//!   z = d·f > 0, u = (d·r) / (z·a·tan θ), v = (d·t) / (z·tan θ).
//! * **orthographic** (half view height h in world units): every ray has direction f and
//!   starts on the film plane through o at o + r·u·a·h + t·v·h. Inverse: u = (d·r)/(a·h),
//!   v = (d·t)/h, for z = d·f > 0 (points behind the film plane are not seen).
//!
//! The vertical extent (θ or h) is fixed and the horizontal one follows the image's aspect
//! ratio a, as glTF viewers do with a viewport of another shape (glTF 2.0 spec, "Cameras":
//! `yfov` and `ymag` are vertical; the image size comes from the render config).
//!
//! The eye vertex of a path is the ray's origin ([`Camera::eye_point`]): the same point for
//! every raster position of a pinhole, a point on the film plane for an orthographic camera.
//! In the film (raster-area) measure both projections have the constant importance
//! 1 / (pixel area), so path estimates and Markov-chain target functions need no camera
//! factor (Veach 1997, §8.2; pbrt-v4 §5.1–5.2 for the two projections).

use crate::geometry::Ray;
use glam::{Vec2, Vec3};

/// Which projection a [`Camera`] uses (stored as `Camera::projection`, a plain `u32`, so
/// that no invalid bit pattern can cross the plugin boundary).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    Perspective,
    Orthographic,
}

impl Projection {
    /// The value stored in [`Camera::projection`].
    pub const fn code(self) -> u32 {
        match self {
            Projection::Perspective => 0,
            Projection::Orthographic => 1,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Projection::Perspective => "perspective",
            Projection::Orthographic => "orthographic",
        }
    }
}

/// A camera (module docs for the projections).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The pinhole; for an orthographic camera, the centre of the film plane.
    pub position: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit vector towards the right of the image.
    pub right: Vec3,
    /// Unit vector towards the top of the image.
    pub up: Vec3,
    /// Perspective: tan(vertical field of view / 2). Orthographic: 0 (unused).
    pub tan_half_fov_y: f32,
    /// Orthographic: half the height of the view in world units. Perspective: 0 (unused).
    pub ortho_half_height: f32,
    /// [`Projection::code`]: 0 perspective, 1 orthographic (anything else reads as
    /// perspective).
    pub projection: u32,
    pub width: u32,
    pub height: u32,
}

/// Right-handed orthonormal frame (forward, right, up) from a forward and an approximate up.
fn frame(forward: Vec3, up: Vec3) -> (Vec3, Vec3, Vec3) {
    let forward = forward.normalize();
    let right = forward.cross(up).normalize();
    let up = right.cross(forward);
    (forward, right, up)
}

impl Camera {
    /// A pinhole camera at `position` looking along `forward` with the given approximate `up`.
    pub fn look_along(
        position: Vec3,
        forward: Vec3,
        up: Vec3,
        fov_y_degrees: f32,
        width: u32,
        height: u32,
    ) -> Camera {
        let (forward, right, up) = frame(forward, up);
        Camera {
            position,
            forward,
            right,
            up,
            tan_half_fov_y: (fov_y_degrees.to_radians() * 0.5).tan(),
            ortho_half_height: 0.0,
            projection: Projection::Perspective.code(),
            width,
            height,
        }
    }

    /// An orthographic camera whose film plane is centred at `position`, looking along
    /// `forward`, showing `2 · half_height` world units vertically (and `aspect` times that
    /// horizontally).
    pub fn orthographic(
        position: Vec3,
        forward: Vec3,
        up: Vec3,
        half_height: f32,
        width: u32,
        height: u32,
    ) -> Camera {
        let (forward, right, up) = frame(forward, up);
        Camera {
            position,
            forward,
            right,
            up,
            tan_half_fov_y: 0.0,
            ortho_half_height: half_height,
            projection: Projection::Orthographic.code(),
            width,
            height,
        }
    }

    #[inline]
    pub fn kind(&self) -> Projection {
        if self.projection == Projection::Orthographic.code() {
            Projection::Orthographic
        } else {
            Projection::Perspective
        }
    }

    #[inline]
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Normalised device coordinates (u, v) ∈ [−1, 1]² of a raster position (module docs).
    #[inline]
    fn ndc(&self, raster: Vec2) -> Vec2 {
        Vec2::new(
            2.0 * raster.x / self.width as f32 - 1.0,
            1.0 - 2.0 * raster.y / self.height as f32,
        )
    }

    /// Raster position of normalised device coordinates; `None` off the film.
    #[inline]
    fn raster_of(&self, ndc: Vec2) -> Option<Vec2> {
        let raster = Vec2::new(
            (ndc.x + 1.0) * 0.5 * self.width as f32,
            (1.0 - ndc.y) * 0.5 * self.height as f32,
        );
        (raster.x >= 0.0
            && raster.y >= 0.0
            && raster.x < self.width as f32
            && raster.y < self.height as f32)
            .then_some(raster)
    }

    /// Half extents of the view: tan of the half angles (perspective) or world units
    /// (orthographic), horizontal then vertical.
    #[inline]
    fn half_extent(&self) -> Vec2 {
        let h = match self.kind() {
            Projection::Perspective => self.tan_half_fov_y,
            Projection::Orthographic => self.ortho_half_height,
        };
        Vec2::new(h * self.aspect(), h)
    }

    /// Where the ray through raster position `raster` starts: the pinhole, or the point on
    /// the orthographic film plane. This is the path's eye vertex.
    #[inline]
    pub fn eye_point(&self, raster: Vec2) -> Vec3 {
        match self.kind() {
            Projection::Perspective => self.position,
            Projection::Orthographic => {
                let s = self.ndc(raster) * self.half_extent();
                self.position + self.right * s.x + self.up * s.y
            }
        }
    }

    /// Primary ray through raster position `raster` (pixel coordinates, may be fractional).
    #[inline]
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let s = self.ndc(raster) * self.half_extent();
        match self.kind() {
            Projection::Perspective => {
                let dir = self.forward + self.right * s.x + self.up * s.y;
                Ray::new(self.position, dir.normalize(), f32::INFINITY)
            }
            Projection::Orthographic => Ray::new(
                self.position + self.right * s.x + self.up * s.y,
                self.forward,
                f32::INFINITY,
            ),
        }
    }

    /// Raster position of world point `p`, or `None` when it is behind the camera (behind
    /// the film plane of an orthographic camera) or off the film. Inverse of
    /// [`Camera::generate_ray`], for code that moves the eye vertex or connects to the camera.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let d = p - self.position;
        let z = d.dot(self.forward);
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        let e = self.half_extent();
        let s = Vec2::new(d.dot(self.right), d.dot(self.up));
        let ndc = match self.kind() {
            Projection::Perspective => s / (z * e),
            Projection::Orthographic => s / e,
        };
        self.raster_of(ndc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cameras() -> [Camera; 2] {
        let (o, f) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.2, -0.1, 1.0));
        [
            Camera::look_along(o, f, Vec3::Y, 40.0, 64, 48),
            Camera::orthographic(o, f, Vec3::Y, 1.5, 64, 48),
        ]
    }

    #[test]
    fn project_inverts_generate_ray_for_both_projections() {
        for cam in cameras() {
            for raster in [
                Vec2::new(0.5, 0.5),
                Vec2::new(32.0, 24.0),
                Vec2::new(63.2, 40.7),
                Vec2::new(0.01, 47.9),
            ] {
                let r = cam.generate_ray(raster);
                assert!((r.dir.length() - 1.0).abs() < 1e-5);
                assert!((r.origin - cam.eye_point(raster)).length() < 1e-6);
                for t in [0.3, 5.0, 40.0] {
                    let back = cam.project(r.at(t)).unwrap();
                    assert!(
                        (back - raster).length() < 2e-3,
                        "{:?} t {t}: {raster} -> {back}",
                        cam.kind()
                    );
                }
            }
            let centre = cam.generate_ray(Vec2::new(32.0, 24.0));
            assert!((centre.dir - cam.forward).length() < 1e-5);
            assert!((centre.origin - cam.position).length() < 1e-5);
            // Behind the camera (or the film plane) and off the film: no raster position.
            assert_eq!(cam.project(cam.position - cam.forward), None);
            assert_eq!(
                cam.project(cam.position + cam.forward * 2.0 + cam.up * 1e3),
                None
            );
        }
    }

    #[test]
    fn perspective_corners_follow_fov_and_aspect() {
        let cam = Camera::look_along(Vec3::ZERO, -Vec3::Z, Vec3::Y, 90.0, 200, 100);
        // tan 45° = 1: the top-right corner's direction is (a, 1, −1) normalised, a = 2.
        let r = cam.generate_ray(Vec2::new(200.0, 0.0));
        assert!((r.dir - Vec3::new(2.0, 1.0, -1.0).normalize()).length() < 1e-6);
        assert_eq!(r.origin, Vec3::ZERO);
        // A point 10 in front, 5 up: v = 5/10 = 0.5 → y = (1 − 0.5)·50 = 25; centred in x.
        let p = cam.project(Vec3::new(0.0, 5.0, -10.0)).unwrap();
        assert!((p - Vec2::new(100.0, 25.0)).length() < 1e-4, "{p}");
    }

    #[test]
    fn orthographic_rays_are_parallel_and_span_the_view() {
        // Looking down −Z from z = 4, half height 2, 200×100 → half width 4.
        let cam = Camera::orthographic(Vec3::new(0.0, 0.0, 4.0), -Vec3::Z, Vec3::Y, 2.0, 200, 100);
        assert_eq!(cam.kind(), Projection::Orthographic);
        let corner = cam.generate_ray(Vec2::new(0.0, 0.0));
        assert!((corner.origin - Vec3::new(-4.0, 2.0, 4.0)).length() < 1e-6);
        assert_eq!(corner.dir, -Vec3::Z);
        let other = cam.generate_ray(Vec2::new(150.0, 75.0));
        assert_eq!(other.dir, corner.dir);
        assert!((other.origin - Vec3::new(2.0, -1.0, 4.0)).length() < 1e-6);
        // The raster position of a point does not depend on its depth.
        let near = cam.project(Vec3::new(1.0, 1.0, 3.9)).unwrap();
        let far = cam.project(Vec3::new(1.0, 1.0, -100.0)).unwrap();
        assert!((near - Vec2::new(125.0, 25.0)).length() < 1e-4, "{near}");
        assert!((far - near).length() < 1e-3);
        assert_eq!(cam.project(Vec3::new(1.0, 1.0, 4.5)), None);
    }

    #[test]
    fn projection_codes_decode() {
        for p in [Projection::Perspective, Projection::Orthographic] {
            let mut c = cameras()[0];
            c.projection = p.code();
            assert_eq!(c.kind(), p);
        }
    }
}
