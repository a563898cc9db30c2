//! Triangle area lights, sampled by power.

use crate::geometry::barycentric_error;
use crate::sampling::{sample_cdf, uniform_triangle};
use crate::Rgb;
use glam::{Vec2, Vec3};

/// One emissive triangle. The scene's emitter table lists every triangle whose material emits.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitter {
    pub p0: Vec3,
    pub p1: Vec3,
    pub p2: Vec3,
    /// Unit geometric normal (counter-clockwise winding is the front).
    pub n: Vec3,
    pub area: f32,
    /// Emitted radiance, constant over the triangle.
    pub radiance: Rgb,
    /// 1 when both faces emit.
    pub double_sided: u32,
    /// Global triangle index (what a ray hit reports).
    pub prim: u32,
}

impl Emitter {
    /// Radiance leaving the emitter in direction `w` (pointing away from it).
    #[inline]
    pub fn radiance_towards(&self, w: Vec3) -> Rgb {
        if self.double_sided != 0 || self.n.dot(w) > 0.0 {
            self.radiance
        } else {
            Rgb::ZERO
        }
    }

    /// Power up to the constant π: area × luminance × faces. Lights are chosen in proportion.
    pub fn power(&self) -> f32 {
        let faces = if self.double_sided != 0 { 2.0 } else { 1.0 };
        self.area * self.radiance.luminance() * faces
    }
}

/// A point sampled on the lights.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub p: Vec3,
    pub p_error: Vec3,
    pub n: Vec3,
    pub emitter: u32,
    /// Density with respect to area: p(choose emitter) / area.
    pub pdf_area: f32,
}

/// The scene's lights: emitter table plus the CDF over their power.
#[derive(Clone, Copy, Debug)]
pub struct Lights<'a> {
    pub emitters: &'a [Emitter],
    pub power_cdf: &'a [f32],
}

impl<'a> Lights<'a> {
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty() || self.power_cdf.len() != self.emitters.len()
    }

    /// Chooses an emitter by power and a uniform point on it.
    #[inline]
    pub fn sample(&self, u_light: f32, u: Vec2) -> Option<LightSample> {
        if self.is_empty() {
            return None;
        }
        let (i, p_choose) = sample_cdf(self.power_cdf, u_light);
        let e = &self.emitters[i];
        if p_choose <= 0.0 || e.area <= 0.0 {
            return None;
        }
        let b = uniform_triangle(u);
        let p = e.p0 * b[0] + e.p1 * b[1] + e.p2 * b[2];
        Some(LightSample {
            p,
            p_error: barycentric_error(b, e.p0, e.p1, e.p2),
            n: e.n,
            emitter: i as u32,
            pdf_area: p_choose / e.area,
        })
    }

    /// Area density with which [`Lights::sample`] picks a point on emitter `i`.
    #[inline]
    pub fn pdf_area(&self, i: usize) -> f32 {
        if self.is_empty() || i >= self.emitters.len() {
            return 0.0;
        }
        let lo = if i == 0 { 0.0 } else { self.power_cdf[i - 1] };
        let area = self.emitters[i].area;
        if area > 0.0 {
            (self.power_cdf[i] - lo) / area
        } else {
            0.0
        }
    }
}

/// Converts an area density at `p_light` (normal `n_light`) seen from `p_ref` to a solid-angle
/// density: p_ω = p_A · d² / |cos θ_light|. Returns 0 for a grazing or coincident point.
#[inline]
pub fn area_to_solid_angle(pdf_area: f32, p_ref: Vec3, p_light: Vec3, n_light: Vec3) -> f32 {
    let d = p_light - p_ref;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return 0.0;
    }
    let cos = n_light.dot(d / dist2.sqrt()).abs();
    if cos <= 0.0 {
        return 0.0;
    }
    pdf_area * dist2 / cos
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::build_cdf;

    #[test]
    fn lights_are_chosen_by_power_and_pdf_matches() {
        let tri = |s: f32, l: f32| Emitter {
            p0: Vec3::ZERO,
            p1: Vec3::X * s,
            p2: Vec3::Y * s,
            n: Vec3::Z,
            area: 0.5 * s * s,
            radiance: Rgb::splat(l),
            double_sided: 0,
            prim: 0,
        };
        let es = [tri(1.0, 1.0), tri(2.0, 1.0)];
        let cdf = build_cdf(&es.iter().map(|e| e.power()).collect::<Vec<_>>()).unwrap();
        let lights = Lights {
            emitters: &es,
            power_cdf: &cdf,
        };
        let mut r = Rng::new(5, 0);
        let mut second = 0;
        for _ in 0..10_000 {
            let s = lights.sample(r.uniform(), r.uniform2()).unwrap();
            assert!((s.pdf_area - lights.pdf_area(s.emitter as usize)).abs() < 1e-6);
            second += s.emitter as usize;
        }
        // Powers 0.5 and 2.0: the big one is chosen 80% of the time.
        assert!((second as f32 / 10_000.0 - 0.8).abs() < 0.02);
        assert_eq!(es[0].radiance_towards(-Vec3::Z), Rgb::ZERO);
    }
}
