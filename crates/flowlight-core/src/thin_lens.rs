//! The thin lens: depth of field for a perspective [`Camera`] (pbrt-v4 §5.2.3; Kolb et al.
//! 1995 for the model).
//!
//! A lens of radius R ([`Camera::lens_radius`]) lies in the plane through the camera position
//! o perpendicular to the forward axis f; the plane in focus is at distance f_d
//! ([`Camera::focus_distance`]) along f. The pinhole ray through raster position r has
//! direction d(r) = f + r·s_x + t·s_y (the [`crate::camera`] module docs) and meets the plane
//! in focus at q(r) = o + f_d·d(r). With a lens, the ray through r starts at a lens point
//!
//! ```text
//! l = o + R·(r·x + t·y),   (x, y) = concentric_disk(u_lens),   u_lens uniform in [0, 1)²
//! ```
//!
//! (uniform on the lens disk, area density 1/(πR²)) and goes towards q(r). A point on the
//! plane in focus is reached from every lens point through the same raster position: it is
//! sharp. A point p at depth z = (p − o)·f, seen from l, crosses the plane in focus at
//! l + (p − l)·f_d/z, which differs from the pinhole's image o + (p − o)·f_d/z by
//! (l − o)·(1 − f_d/z): the image of p is a disk — the circle of confusion — of diameter
//!
//! ```text
//! c = 2R · |z − f_d| / z             on the plane in focus (world units),
//! c_px = c · H / (2 f_d tan θ)        on the film, in pixels (θ the half vertical fov)
//! ```
//!
//! (the thin-lens formula c = A·|z − f_d|/z with aperture diameter A = 2R, scaled by the
//! plane in focus's height 2 f_d tan θ onto the film's H pixels; [`Camera::circle_of_confusion_px`]).
//! The camera stands for a thin lens of focal length F and f-number N with R = F/(2N); the
//! config derives F from a sensor height and the field of view (docs/config.md).
//!
//! **Sampling.** A path that starts at the camera draws the lens point's pair right after the
//! raster position's ([`Camera::sample_ray`]); a pinhole draws nothing, so its numbers (and
//! its images) are those of a camera without a lens, bit for bit. The path's eye vertex is
//! the lens point (the ray's origin).
//!
//! **Importance and densities.** Given the lens point l, the raster position is uniform over
//! the film and the ray goes from l to a point uniform on the in-focus rectangle q(film),
//! whose area is A·f_d² (A the film area at distance 1, [`Camera::film_area`]). A ray at angle
//! θ from f meets that plane at distance f_d / cos θ, so dA_q = f_d² dω / cos³θ and the ray's
//! solid-angle density is 1/(A cos³θ): the pinhole's, with the eye at l. So every formula of
//! [`crate::camera`] holds conditioned on l — [`Camera::hit_density`] with the direction and
//! distance from l is the density with which the camera's first vertex lands on a surface
//! point, and a light vertex connected to a lens point l drawn with the camera's own density
//! ([`Camera::connect_eye_through_lens`]) splats β·f·hit_density at the raster position through
//! which l sees it. In pbrt-v4's terms (`PerspectiveCamera::We`, `PDF_We`, `SampleWi`): W_e =
//! 1/(A·πR²·cos⁴θ), the lens point drawn with area density 1/(πR²), and W_e·cos θ·|cos θ_s|/d²
//! divided by that density is our hit_density. The lens point's density is the same in every
//! strategy that makes it (camera rays and eye connections), so it cancels from every MIS ratio.
//!
//! **Markov chains.** The lens point is one more coordinate of the path measure (film ×
//! lens with density 1/(πR²) × the vertices' measures), in which the target function needs
//! no camera factor, as for the pinhole. The mutations keep the current path's lens point
//! ([`Camera::ray_from_eye`], [`Camera::project_from_eye`]): a move of the raster position
//! or of the light side then is the pinhole's move with the eye at l, with the same
//! densities, and detailed balance holds on each set of paths sharing a lens point (a Dirac
//! in the lens coordinate, symmetric). Chains do not move across the lens; the seeds, drawn
//! by path tracing, cover it.

use crate::camera::{Camera, EyeConnection, Projection};
use crate::geometry::Ray;
use crate::sampler::SampleStream;
use crate::sampling::concentric_disk;
use glam::{Vec2, Vec3};

impl Camera {
    /// This camera with a thin lens of radius `lens_radius` focused at `focus_distance`
    /// (module docs); a radius of 0 keeps the pinhole.
    pub fn with_thin_lens(mut self, lens_radius: f32, focus_distance: f32) -> Camera {
        self.lens_radius = lens_radius;
        self.focus_distance = focus_distance;
        self
    }

    /// Whether rays start on a lens (a perspective camera with a positive lens radius and
    /// focus distance) rather than at the pinhole.
    #[inline]
    pub fn has_lens(&self) -> bool {
        self.kind() == Projection::Perspective
            && self.lens_radius > 0.0
            && self.focus_distance > 0.0
    }

    /// The lens point of `u` ∈ [0, 1)² (uniform on the lens disk for uniform `u`).
    #[inline]
    pub fn lens_point(&self, u: Vec2) -> Vec3 {
        let d = concentric_disk(u) * self.lens_radius;
        self.position + self.right * d.x + self.up * d.y
    }

    /// The ray through raster position `raster` from lens point `lens_point(u)`; the pinhole
    /// ray ([`Camera::generate_ray`]) without a lens.
    #[inline]
    pub fn generate_ray_lens(&self, raster: Vec2, u: Vec2) -> Ray {
        if !self.has_lens() {
            return self.generate_ray(raster);
        }
        self.ray_from_eye(raster, self.lens_point(u))
    }

    /// A path's camera ray through `raster`: with a lens, the lens point takes the next pair
    /// of `rng`; a pinhole draws nothing (module docs, "Sampling").
    #[inline]
    pub fn sample_ray<S: SampleStream>(&self, raster: Vec2, rng: &mut S) -> Ray {
        if !self.has_lens() {
            return self.generate_ray(raster);
        }
        let u = rng.uniform2();
        self.ray_from_eye(raster, self.lens_point(u))
    }

    /// The ray through raster position `raster` that starts at the eye vertex `eye` (a lens
    /// point): towards the point `raster` shows on the plane in focus. Without a lens, the
    /// ray of [`Camera::generate_ray`] (`eye` is ignored: the pinhole, or the orthographic
    /// film point of `raster`). What mutations use to move the raster position and keep the
    /// lens point.
    #[inline]
    pub fn ray_from_eye(&self, raster: Vec2, eye: Vec3) -> Ray {
        if !self.has_lens() {
            return self.generate_ray(raster);
        }
        let s = self.ndc(raster) * self.half_extent();
        let focus =
            self.position + (self.forward + self.right * s.x + self.up * s.y) * self.focus_distance;
        Ray::new(eye, (focus - eye).normalize(), f32::INFINITY)
    }

    /// Raster position through which eye vertex `eye` (a lens point) sees world point `p`:
    /// where the line from `eye` through `p` crosses the plane in focus. `None` behind the
    /// lens or off the film. Without a lens, [`Camera::project`].
    pub fn project_from_eye(&self, eye: Vec3, p: Vec3) -> Option<Vec2> {
        if !self.has_lens() {
            return self.project(p);
        }
        let d = p - eye;
        let z = d.dot(self.forward);
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        // Depth of the plane in focus as seen from the eye (0 for a point on the lens).
        let depth = self.focus_distance - (eye - self.position).dot(self.forward);
        let q = eye + d * (depth / z) - self.position;
        let e = self.half_extent() * self.focus_distance;
        self.raster_of(Vec2::new(q.dot(self.right), q.dot(self.up)) / e)
    }

    /// How world point `p` connects to the eye through lens point `lens_point(u)`
    /// ([`Camera::connect_eye`] for a pinhole or an orthographic camera, which ignore `u`).
    pub fn connect_eye_through_lens(&self, p: Vec3, u: Vec2) -> Option<EyeConnection> {
        if !self.has_lens() {
            return self.connect_eye(p);
        }
        let eye = self.lens_point(u);
        let raster = self.project_from_eye(eye, p)?;
        EyeConnection::between(raster, eye, p)
    }

    /// [`Camera::connect_eye_through_lens`] with the lens point drawn from the next pair of
    /// `rng`; a camera without a lens draws nothing.
    #[inline]
    pub fn sample_eye_connection<S: SampleStream>(
        &self,
        p: Vec3,
        rng: &mut S,
    ) -> Option<EyeConnection> {
        if !self.has_lens() {
            return self.connect_eye(p);
        }
        let u = rng.uniform2();
        self.connect_eye_through_lens(p, u)
    }

    /// Diameter in pixels of the circle of confusion of a point at depth `z` (module docs):
    /// 2R·|z − f_d|/z on the plane in focus, scaled by H / (2 f_d tan θ). 0 without a lens.
    pub fn circle_of_confusion_px(&self, z: f32) -> f32 {
        if !self.has_lens() {
            return 0.0;
        }
        let c = 2.0 * self.lens_radius * (z - self.focus_distance).abs() / z;
        c * self.height as f32 / (2.0 * self.focus_distance * self.tan_half_fov_y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn lens_camera(radius: f32, focus: f32) -> Camera {
        Camera::look_along(
            Vec3::new(0.5, 1.0, 4.0),
            Vec3::new(0.1, -0.2, -1.0),
            Vec3::Y,
            40.0,
            96,
            64,
        )
        .with_thin_lens(radius, focus)
    }

    #[test]
    fn a_pinhole_draws_nothing_and_gives_the_pinhole_ray() {
        let cam = lens_camera(0.0, 3.0);
        assert!(!cam.has_lens());
        let mut a = Rng::new(5, 0);
        let mut b = a.clone();
        let raster = Vec2::new(12.3, 40.1);
        let r = cam.sample_ray(raster, &mut a);
        assert_eq!(
            a.uniform(),
            b.uniform(),
            "a pinhole must not draw a lens sample"
        );
        assert_eq!(r, cam.generate_ray(raster));
        assert_eq!(cam.generate_ray_lens(raster, Vec2::new(0.9, 0.1)), r);
        assert_eq!(
            cam.project_from_eye(cam.position, r.at(2.0)),
            cam.project(r.at(2.0))
        );
        // An orthographic camera ignores a lens.
        let ortho =
            Camera::orthographic(Vec3::ZERO, -Vec3::Z, Vec3::Y, 1.0, 8, 8).with_thin_lens(0.5, 2.0);
        assert!(!ortho.has_lens());
    }

    #[test]
    fn lens_rays_meet_at_the_plane_in_focus_and_project_back() {
        let cam = lens_camera(0.2, 3.0);
        let mut rng = Rng::new(9, 1);
        for raster in [
            Vec2::new(48.0, 32.0),
            Vec2::new(3.5, 60.2),
            Vec2::new(90.1, 1.7),
        ] {
            let pinhole = cam.generate_ray(raster);
            let focus = pinhole.at(3.0 / pinhole.dir.dot(cam.forward));
            for _ in 0..16 {
                let u = rng.uniform2();
                let r = cam.generate_ray_lens(raster, u);
                let l = cam.lens_point(u);
                assert_eq!(r.origin, l);
                assert!((l - cam.position).dot(cam.forward).abs() < 1e-5);
                assert!((l - cam.position).length() <= 0.2 + 1e-5);
                // The ray passes through the pinhole ray's point on the plane in focus.
                let t = (focus - r.origin).dot(r.dir);
                assert!((r.at(t) - focus).length() < 1e-4, "{raster} {u}");
                // Any point along it projects back to `raster` through its lens point.
                for s in [0.5, 3.0, 20.0] {
                    let back = cam.project_from_eye(l, r.at(s)).unwrap();
                    assert!((back - raster).length() < 2e-3, "{raster} {s}: {back}");
                    let c = cam.connect_eye_through_lens(r.at(s), u).unwrap();
                    assert!((c.raster - raster).length() < 2e-3);
                    assert!((c.to_eye + r.dir).length() < 1e-4);
                    assert_eq!(cam.ray_from_eye(raster, l).origin, l);
                }
            }
        }
    }

    /// The spread of the raster positions at which a point is seen through the whole lens is
    /// the circle of confusion; a point on the plane in focus has none.
    #[test]
    fn the_blur_of_a_point_is_the_circle_of_confusion() {
        let cam = lens_camera(0.1, 3.0);
        for z in [1.5f32, 3.0, 8.0] {
            let p = cam.position + cam.forward * z + cam.right * 0.05;
            let centre = cam.project(p).unwrap();
            let mut widest = 0.0f32;
            for i in 0..64 {
                let a = i as f32 / 64.0 * std::f32::consts::TAU;
                // Points on the lens rim: the blur disk's boundary.
                let rim = cam.position + (cam.right * a.cos() + cam.up * a.sin()) * 0.1;
                let r = cam.project_from_eye(rim, p).unwrap();
                widest = widest.max((r - centre).length());
            }
            let want = cam.circle_of_confusion_px(z);
            assert!(
                (2.0 * widest - want).abs() < 1e-2 * want.max(1.0),
                "z {z}: {widest} vs {want}"
            );
            if z == 3.0 {
                assert!(widest < 1e-3);
            }
        }
    }
}
