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
//! factor (Veach 1997, §8.2; pbrt-v4 §5.1–5.2 for the two projections). A perspective
//! camera with a lens (`lens_radius > 0`) starts its rays at a point on the lens instead of
//! the pinhole: [`crate::thin_lens`], where everything below holds with the eye at that point.
//!
//! ## Importance: connecting light paths to the eye
//!
//! Light tracing and bidirectional methods reach the film from the other side: a vertex x of
//! a light subpath is joined to the eye ([`Camera::connect_eye`]) and lands at some raster
//! position. What it deposits there follows from the film normalisation. A pixel's value is
//! the mean radiance over its raster area (1 in raster units), and a camera ray is generated
//! from a raster position r uniform over the whole film, density 1/(W·H). Let A be the film's
//! area in world units ([`Camera::film_area`]): the image plane at distance 1 for a pinhole,
//! 4·a·tan²θ; the film plane itself for an orthographic camera, (2·a·h)(2·h).
//!
//! * **perspective.** Raster positions are uniform on the image plane at distance 1, density
//!   1/A there. A ray at angle θ from the forward axis (cos θ = dir·forward) meets that plane
//!   at distance 1/cos θ and obliquely, so dA_plane = dω / cos³θ and the ray's solid-angle
//!   density is 1/(A cos³θ). At a surface point at distance d whose normal makes |cos θ_s|
//!   with the ray, dω = |cos θ_s| dA / d²:
//!
//!   ```text
//!   p_A(x) = |cos θ_s| / (d² · A · cos³θ)
//!   ```
//!
//! * **orthographic.** The direction is a Dirac along forward and the origin is uniform on the
//!   film plane, density 1/A; a surface element dA projects to |cos θ_s| dA on it:
//!
//!   ```text
//!   p_A(x) = |cos θ_s| / A
//!   ```
//!
//! [`Camera::hit_density`] is this p_A, the density of a camera subpath's first vertex in
//! area measure (what MIS weights need). It is also the factor a light vertex splats with.
//! Pixel j's value is I_j = ∫ h_j(r) L(r) dr, h_j the pixel's indicator, and changing
//! variables from r to the surface point x seen through r gives dr = W·H · p_A(x) dA(x), so
//!
//! ```text
//! I_j = ∫ h_j(r(x)) · W·H · p_A(x) · L(x → eye) dA(x).
//! ```
//!
//! W·H·h_j·p_A is W_e·G — the camera's importance times the geometry term to the eye
//! (Veach 1997 §10.2; for the pinhole pbrt-v3 §16.1.1, whose `PerspectiveCamera::We`, also
//! in pbrt-v4's source, is W_e(ω) = 1/(A cos⁴θ) for lens area 1, and W_e·cos θ·|cos θ_s|/d²
//! = p_A; the orthographic case is the Dirac in direction above). A light subpath vertex x with
//! throughput β (the light's L_e and every f·|cos|/p up to x) connecting to the eye through a
//! BSDF value f therefore deposits
//!
//! ```text
//! β · f · p_A(x)      at raster position r(x), per light path,
//! ```
//!
//! and a render that traces one light path per pixel sample (W·H light paths per sample
//! pass) divides the deposits by the samples per pixel, as it divides a pixel's camera
//! samples: the W·H light paths per pass supply the W·H factor. Visibility between x and the
//! eye is the caller's test.

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
    /// Radius of a perspective camera's thin lens in world units; 0 (and anything not
    /// positive) is the pinhole ([`crate::thin_lens`]). Orthographic cameras ignore it.
    pub lens_radius: f32,
    /// Distance along `forward` from the lens to the plane in focus (world units); used only
    /// with a lens.
    pub focus_distance: f32,
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
            lens_radius: 0.0,
            focus_distance: 0.0,
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
            lens_radius: 0.0,
            focus_distance: 0.0,
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
    pub(crate) fn ndc(&self, raster: Vec2) -> Vec2 {
        Vec2::new(
            2.0 * raster.x / self.width as f32 - 1.0,
            1.0 - 2.0 * raster.y / self.height as f32,
        )
    }

    /// Raster position of normalised device coordinates; `None` off the film.
    #[inline]
    pub(crate) fn raster_of(&self, ndc: Vec2) -> Option<Vec2> {
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
    pub(crate) fn half_extent(&self) -> Vec2 {
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

/// A world point seen by the camera: what a light-path vertex needs to connect to the eye.
#[derive(Clone, Copy, Debug)]
pub struct EyeConnection {
    /// Where the point lands on the film, inside [0, W) × [0, H).
    pub raster: Vec2,
    /// The eye vertex: the pinhole, or for an orthographic camera the point projected onto
    /// the film plane.
    pub eye: Vec3,
    /// Unit direction from the point towards the eye.
    pub to_eye: Vec3,
    /// |eye − p|.
    pub distance: f32,
}

impl EyeConnection {
    /// The connection of world point `p`, landing at `raster`, to eye vertex `eye`; `None`
    /// where the two coincide or the distance is not finite.
    #[inline]
    pub fn between(raster: Vec2, eye: Vec3, p: Vec3) -> Option<EyeConnection> {
        let d = eye - p;
        let distance = d.length();
        if !(distance > 0.0 && distance.is_finite()) {
            return None;
        }
        Some(EyeConnection {
            raster,
            eye,
            to_eye: d / distance,
            distance,
        })
    }
}

impl Camera {
    /// Area of the film in world units (module docs): perspective — the image plane at
    /// distance 1, 4·a·tan²θ; orthographic — the film plane, (2·a·h)(2·h).
    #[inline]
    pub fn film_area(&self) -> f32 {
        let e = self.half_extent();
        4.0 * e.x * e.y
    }

    /// How world point `p` connects to the eye: its raster position, the eye vertex and the
    /// direction and distance to it. `None` when `p` is behind the camera (or its film plane)
    /// or off the film, as for [`Camera::project`].
    pub fn connect_eye(&self, p: Vec3) -> Option<EyeConnection> {
        let raster = self.project(p)?;
        let eye = match self.kind() {
            Projection::Perspective => self.position,
            Projection::Orthographic => {
                // p moved back along forward onto the film plane through the position.
                p - self.forward * (p - self.position).dot(self.forward)
            }
        };
        EyeConnection::between(raster, eye, p)
    }

    /// Density, in area measure at a surface point, with which a camera ray through a
    /// uniformly random raster position of the whole film first reaches that point at
    /// `distance` along unit `dir` (the ray direction, from the eye), the surface's normal
    /// making |`cos_surface`| with the ray; visibility is not included. Perspective:
    /// |cos_surface| / (distance² · film_area · cos³θ), cos θ = dir·forward; orthographic:
    /// |cos_surface| / film_area. 0 where cos θ ≤ 0. Also the factor a light vertex splats
    /// with (module docs).
    #[inline]
    pub fn hit_density(&self, dir: Vec3, distance: f32, cos_surface: f32) -> f32 {
        let cos_theta = dir.dot(self.forward);
        if cos_theta <= 0.0 || cos_theta.is_nan() {
            return 0.0;
        }
        let area = self.film_area();
        match self.kind() {
            Projection::Perspective => {
                let c3 = cos_theta * cos_theta * cos_theta;
                cos_surface.abs() / (distance * distance * area * c3)
            }
            Projection::Orthographic => cos_surface.abs() / area,
        }
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

    #[test]
    fn film_areas_follow_the_view() {
        // tan 45° = 1, aspect 2: the image plane at distance 1 is 4 × 2.
        let cam = Camera::look_along(Vec3::ZERO, -Vec3::Z, Vec3::Y, 90.0, 200, 100);
        assert!((cam.film_area() - 8.0).abs() < 1e-5);
        // Half height 2, aspect 2: the film plane is 8 × 4.
        let cam = Camera::orthographic(Vec3::ZERO, -Vec3::Z, Vec3::Y, 2.0, 200, 100);
        assert!((cam.film_area() - 32.0).abs() < 1e-5);
    }

    #[test]
    fn connect_eye_inverts_generate_ray_for_both_projections() {
        for cam in cameras() {
            for raster in [
                Vec2::new(0.5, 0.5),
                Vec2::new(32.0, 24.0),
                Vec2::new(63.2, 40.7),
                Vec2::new(0.01, 47.9),
            ] {
                let ray = cam.generate_ray(raster);
                for t in [0.3, 5.0, 40.0] {
                    let c = cam.connect_eye(ray.at(t)).unwrap();
                    let what = format!("{:?} {raster} t {t}: {c:?}", cam.kind());
                    assert!((c.raster - raster).length() < 2e-3, "{what}");
                    assert!(
                        (c.eye - cam.eye_point(raster)).length() < 1e-4 * t,
                        "{what}"
                    );
                    assert!((c.to_eye + ray.dir).length() < 1e-4, "{what}");
                    assert!((c.distance - t).abs() < 1e-4 * t, "{what}");
                }
            }
            assert!(cam.connect_eye(cam.position - cam.forward).is_none());
            let off_film = cam.position + cam.forward * 2.0 + cam.up * 1e3;
            assert!(cam.connect_eye(off_film).is_none());
            // Behind the camera or sideways: no density.
            assert_eq!(cam.hit_density(-cam.forward, 1.0, 1.0), 0.0);
            assert_eq!(cam.hit_density(cam.right, 1.0, 1.0), 0.0);
        }
    }

    /// A plane through `centre` with unit normal `normal`, as (origin, s axis, t axis).
    fn plane_frame(centre: Vec3, normal: Vec3) -> (Vec3, Vec3, Vec3) {
        let f = crate::geometry::Frame::from_z(normal);
        (centre, f.x, f.y)
    }

    /// Where the ray through `raster` meets the plane (centre, normal), in the plane's (s, t).
    fn plane_hit(cam: &Camera, raster: Vec2, centre: Vec3, normal: Vec3) -> Vec2 {
        let ray = cam.generate_ray(raster);
        let t = (centre - ray.origin).dot(normal) / ray.dir.dot(normal);
        assert!(t > 0.0);
        let (o, a, b) = plane_frame(centre, normal);
        let x = ray.at(t) - o;
        Vec2::new(x.dot(a), x.dot(b))
    }

    /// The camera's planes: one facing it, one tilted 35° about its right axis, both 5 ahead.
    fn planes(cam: &Camera) -> [(Vec3, Vec3); 2] {
        let centre = cam.position + cam.forward * 5.0;
        let (c, s) = (35f32.to_radians().cos(), 35f32.to_radians().sin());
        [
            (centre, -cam.forward),
            (centre, -(cam.forward * c + cam.up * s).normalize()),
        ]
    }

    /// ∫ hit_density dA over a plane that covers the whole view is 1: every camera ray hits
    /// it exactly once. Midpoint rule over the bounding box, in the plane, of where the
    /// film's corner rays land; points off the film count 0.
    #[test]
    fn hit_density_integrates_to_one_over_a_plane_covering_the_view() {
        for cam in cameras() {
            for (centre, normal) in planes(&cam) {
                let (w, h) = (cam.width as f32, cam.height as f32);
                let corners = [
                    Vec2::ZERO,
                    Vec2::new(w, 0.0),
                    Vec2::new(0.0, h),
                    Vec2::new(w, h),
                ]
                .map(|r| plane_hit(&cam, r, centre, normal));
                let lo = corners.iter().fold(Vec2::INFINITY, |m, c| m.min(*c)) - 0.01;
                let hi = corners.iter().fold(-Vec2::INFINITY, |m, c| m.max(*c)) + 0.01;
                let (o, a, b) = plane_frame(centre, normal);
                let n = 1200;
                let cell = (hi - lo) / n as f32;
                let mut total = 0.0f64;
                for i in 0..n {
                    for j in 0..n {
                        let st = lo + cell * Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
                        let x = o + a * st.x + b * st.y;
                        if let Some(c) = cam.connect_eye(x) {
                            let dir = -c.to_eye;
                            let density = cam.hit_density(dir, c.distance, normal.dot(dir));
                            total += (density * cell.x * cell.y) as f64;
                        }
                    }
                }
                assert!(
                    (total - 1.0).abs() < 5e-3,
                    "{:?} {normal}: {total}",
                    cam.kind()
                );
            }
        }
    }

    /// The density where it is not uniform: the share of camera rays through uniform raster
    /// positions that hit a patch off the axis of the tilted plane matches ∫ hit_density
    /// over the patch.
    #[test]
    fn hit_density_matches_the_hits_of_uniform_raster_rays() {
        use crate::rng::Rng;
        for cam in cameras() {
            let (centre, normal) = planes(&cam)[1];
            let (o, a, b) = plane_frame(centre, normal);
            // The patch around where raster (50, 10) lands, a tenth of the view across.
            let mid = plane_hit(&cam, Vec2::new(50.0, 10.0), centre, normal);
            let half = 0.05 * (plane_hit(&cam, Vec2::ZERO, centre, normal) - mid).length();
            let (lo, hi) = (mid - half, mid + half);
            let n = 200;
            let cell = (hi - lo) / n as f32;
            let mut want = 0.0f64;
            for i in 0..n {
                for j in 0..n {
                    let st = lo + cell * Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
                    let c = cam.connect_eye(o + a * st.x + b * st.y).unwrap();
                    let density = cam.hit_density(-c.to_eye, c.distance, normal.dot(c.to_eye));
                    want += (density * cell.x * cell.y) as f64;
                }
            }
            let mut r = Rng::new(3, 1);
            let rays = 400_000;
            let film = Vec2::new(cam.width as f32, cam.height as f32);
            let hits = (0..rays)
                .filter(|_| {
                    let st = plane_hit(&cam, r.uniform2() * film, centre, normal);
                    st.cmpge(lo).all() && st.cmplt(hi).all()
                })
                .count();
            let got = hits as f64 / rays as f64;
            let sigma = (want * (1.0 - want) / rays as f64).sqrt();
            assert!(want > 1e-3, "{want}");
            assert!(
                (got - want).abs() < 4.0 * sigma,
                "{:?}: {got} vs {want}",
                cam.kind()
            );
        }
    }
}
