//! Punctual lights of `KHR_lights_punctual`: point, spot and directional.
//!
//! All three are Dirac lights: a point (spot) light is a Dirac in position, a directional light
//! a Dirac in direction. They are reached only by next-event estimation (no ray can hit them,
//! so there is no MIS), and a path vertex on one is never moved by a mutation.
//!
//! Units. The glTF extension gives intensities in photometric units: candela (lm/sr) for point
//! and spot lights, lux (lm/m²) for directional lights. Flowlight renders radiometric RGB
//! (the unit of glTF's emissive factor, which Blender exports as its emission strength), so
//! the loader divides by [`LUMENS_PER_WATT`] = 683 lm/W, the luminous efficacy the photometric
//! units are defined with — exactly what Blender's glTF importer does (its exporter
//! multiplies by it). A point light of I cd and colour c therefore has radiant intensity
//! I·c/683 W/sr, and a Lambert surface of albedo ρ at distance r lit at incidence θ has
//! radiance ρ/π · (I/683)·cos θ / r². A Blender lamp of P watts exported and rendered here
//! has P/(4π) W/sr, as in Blender. `range` is ignored: the inverse-square fall-off is exact
//! and the spec calls the range a hint.
//!
//! Spot cone (the spec's reference implementation): with s = 1 / max(0.001, cos θ_inner −
//! cos θ_outer) and c = cos of the angle between the spot axis and the direction to the point,
//!
//! ```text
//! falloff = clamp(c·s − cos θ_outer · s, 0, 1)²
//! ```
//!
//! so it is 1 inside the inner cone, 0 outside the outer cone and a smooth square in between.
//!
//! Power (for light selection): point 4π·I, spot 2π·(1 − (cos θ_inner + cos θ_outer)/2)·I
//! (pbrt-v4's estimate), directional π·r²·E with r the scene's bounding-sphere radius.

/// Lumens per watt of the photometric units (candela, lux) that `KHR_lights_punctual` uses.
pub const LUMENS_PER_WATT: f32 = 683.0;

use crate::Rgb;
use glam::Vec3;
use std::f32::consts::PI;

/// Which kind of punctual light.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PunctualKind {
    Point = 0,
    Spot = 1,
    Directional = 2,
}

/// One `KHR_lights_punctual` light placed by its node.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PunctualLight {
    pub kind: PunctualKind,
    /// World position (point, spot).
    pub position: Vec3,
    /// Unit direction the light travels along (the node's local −Z), for spot and directional.
    pub direction: Vec3,
    /// colour × intensity: radiant intensity (point, spot) or irradiance at normal incidence
    /// (directional), in renderer units (module docs).
    pub intensity: Rgb,
    pub cos_inner: f32,
    pub cos_outer: f32,
}

impl PunctualLight {
    pub fn point(position: Vec3, intensity: Rgb) -> PunctualLight {
        PunctualLight {
            kind: PunctualKind::Point,
            position,
            direction: -Vec3::Z,
            intensity,
            cos_inner: -1.0,
            cos_outer: -1.0,
        }
    }

    /// A spot light with cone half-angles in radians (glTF defaults: 0 and π/4).
    pub fn spot(
        position: Vec3,
        direction: Vec3,
        intensity: Rgb,
        inner: f32,
        outer: f32,
    ) -> PunctualLight {
        PunctualLight {
            kind: PunctualKind::Spot,
            position,
            direction: direction.normalize(),
            intensity,
            cos_inner: inner.cos(),
            cos_outer: outer.cos(),
        }
    }

    pub fn directional(direction: Vec3, irradiance: Rgb) -> PunctualLight {
        PunctualLight {
            kind: PunctualKind::Directional,
            position: Vec3::ZERO,
            direction: direction.normalize(),
            intensity: irradiance,
            cos_inner: 1.0,
            cos_outer: 1.0,
        }
    }

    /// True for a light at infinity (directional).
    #[inline]
    pub fn is_distant(&self) -> bool {
        self.kind == PunctualKind::Directional
    }

    /// The spec's smooth cone fall-off for a direction `w` leaving the light (unit).
    #[inline]
    pub fn spot_falloff(&self, w: Vec3) -> f32 {
        if self.kind != PunctualKind::Spot {
            return 1.0;
        }
        let scale = 1.0 / (self.cos_inner - self.cos_outer).max(0.001);
        let offset = -self.cos_outer * scale;
        let a = (self.direction.dot(w) * scale + offset).clamp(0.0, 1.0);
        a * a
    }

    /// Radiant intensity leaving a point or spot light in unit direction `w`.
    #[inline]
    pub fn intensity_towards(&self, w: Vec3) -> Rgb {
        self.intensity * self.spot_falloff(w)
    }

    /// Power in renderer units; `scene_radius` sizes a directional light's footprint.
    pub fn power(&self, scene_radius: f32) -> f32 {
        let i = self.intensity.luminance();
        match self.kind {
            PunctualKind::Point => 4.0 * PI * i,
            PunctualKind::Spot => {
                2.0 * PI * (1.0 - 0.5 * (self.cos_inner + self.cos_outer)).max(0.0) * i
            }
            PunctualKind::Directional => PI * scene_radius * scene_radius * i,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir_at(angle_deg: f32) -> Vec3 {
        let a = angle_deg.to_radians();
        Vec3::new(a.sin(), 0.0, -a.cos())
    }

    #[test]
    fn spot_falloff_follows_the_spec_curve() {
        let (inner, outer) = (10f32.to_radians(), 30f32.to_radians());
        let s = PunctualLight::spot(Vec3::ZERO, -Vec3::Z, Rgb::ONE, inner, outer);
        // Inside the inner cone: full intensity.
        for a in [0.0, 5.0, 9.9] {
            assert!((s.spot_falloff(dir_at(a)) - 1.0).abs() < 1e-5, "{a}");
        }
        // Outside the outer cone: nothing (also behind the light).
        for a in [30.1, 45.0, 120.0] {
            assert_eq!(s.spot_falloff(dir_at(a)), 0.0, "{a}");
        }
        // Between: ((cos a − cos outer)/(cos inner − cos outer))², computed here in f64.
        for a in [12.0f64, 20.0, 28.0] {
            let (ci, co, c) = (
                10f64.to_radians().cos(),
                30f64.to_radians().cos(),
                a.to_radians().cos(),
            );
            let want = ((c - co) / (ci - co)).powi(2);
            let got = s.spot_falloff(dir_at(a as f32)) as f64;
            assert!((got - want).abs() < 1e-4, "{a}: {got} vs {want}");
        }
        // The curve decreases monotonically between the cones.
        let mut last = 1.0;
        for k in 0..=40 {
            let f = s.spot_falloff(dir_at(10.0 + k as f32 * 0.5));
            assert!(f <= last + 1e-6);
            last = f;
        }
    }

    #[test]
    fn point_light_is_isotropic_and_powers_follow_solid_angle() {
        let p = PunctualLight::point(Vec3::ONE, Rgb::splat(2.0));
        assert_eq!(p.intensity_towards(Vec3::X), Rgb::splat(2.0));
        assert!((p.power(1.0) - 8.0 * PI).abs() < 1e-4);
        // A spot whose cones are both the hemisphere emits half the point light's power.
        let s = PunctualLight::spot(Vec3::ZERO, Vec3::Z, Rgb::splat(2.0), PI / 2.0, PI / 2.0);
        assert!((s.power(1.0) - 4.0 * PI).abs() < 1e-3);
        let d = PunctualLight::directional(-Vec3::Y, Rgb::splat(3.0));
        assert!((d.power(2.0) - 12.0 * PI).abs() < 1e-3);
    }
}
