//! Emitted rays: the first vertex of a light subpath (light tracing, BDPT, VCM) and the
//! densities with which it was drawn (Veach 1997 §10.2; pbrt-v3 §16.1.2 "Sampling light
//! rays", `Light::Sample_Le`, and §16.3 for its use in bidirectional path tracing).
//!
//! [`Lights::sample_emission`] chooses a light by power (the same CDF as next-event
//! estimation) and then a point and a direction on it, each from its own numbers. The
//! densities are returned separately — `pdf_choose`, `pdf_pos` (area measure, selection not
//! included) and `pdf_dir` (solid angle at the point) — because a bidirectional estimator
//! needs each of them in its multiple-importance weights:
//!
//! ```text
//! light          position p                         direction ω               radiance
//! area           uniform on the triangle, 1/A       cos-weighted about the   L_e(p, ω)
//!                                                   emitting face, |cos|/π
//!                                                   (|cos|/2π double-sided)
//! point          the light, 1 (Dirac)               uniform sphere, 1/4π     I(ω)
//! spot           the light, 1 (Dirac)               uniform in the outer     I(ω)·falloff
//!                                                   cone, 1/2π(1 − cos θ_o)
//! directional    disk ⟂ ω, 1/(π r²)                 the light's, 1 (Dirac)   E
//! environment    disk ⟂ ω, 1/(π r²)                 −(map sample), p_env(−ω) L_env(−ω)
//! ```
//!
//! Distant lights emit from a disk of the scene's bounding-sphere radius r ([`scene_sphere`])
//! perpendicular to the direction of travel ω, centred at c − ω·r (c the sphere's centre):
//! every line along ω through the scene crosses it exactly once, in front of the scene.
//!
//! With these densities the estimator of a light's power,
//!
//! ```text
//! Φ̂ = L · cos / (p_choose · p_pos · p_dir),
//! ```
//!
//! has expectation, for each light, its emitted power — π·A·L̄ (×2 double-sided), 4π·I,
//! ∫_cone I·falloff dω, π r²·E and π r²·∫L dω — which the tests check by Monte Carlo against
//! [`light_powers`](super::light_powers). One difference is by design: a spot's power for
//! light selection is pbrt-v4's estimate 2π(1 − (cos θ_i + cos θ_o)/2)·I, which takes the
//! fall-off between the cones as linear; the glTF curve is quadratic, so the emitted power is
//! 2π((1 − cos θ_i) + (cos θ_i − cos θ_o)/3)·I. The two agree for a hard-edged cone.
//!
//! Conventions (light.rs): a directional light's
//! [`PunctualLight::direction`](super::PunctualLight::direction) is the direction its light
//! travels; [`Environment::sample`](super::Environment::sample) returns the direction
//! *towards* the environment, so the emitted ray travels along its negation; a spot's
//! intensity is [`PunctualLight::intensity_towards`](super::PunctualLight::intensity_towards)
//! of the direction leaving it.

use super::{LightKind, Lights, PunctualKind};
use crate::geometry::{barycentric_error, Frame};
use crate::sampling::{
    concentric_disk, cosine_hemisphere, cosine_hemisphere_pdf, sample_cdf_remapped, uniform_cone,
    uniform_cone_pdf, uniform_sphere, uniform_triangle, ONE_MINUS_EPSILON,
};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A ray leaving a light: the first vertex of a light subpath and its densities.
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    /// Unified light index (light.rs module docs).
    pub light: u32,
    pub kind: LightKind,
    /// Ray origin: the point on the emitter; the punctual light's position; the point on the
    /// disk for distant lights.
    pub p: Vec3,
    /// Rounding bound of `p` (the barycentric error for triangles; zero otherwise).
    pub p_error: Vec3,
    /// Area lights: the emitter's normal turned to the side emitted into (n·dir > 0).
    /// Other lights: equal to `dir`.
    pub n: Vec3,
    /// Unit direction the light travels.
    pub dir: Vec3,
    /// Area and environment: radiance L_e along `dir`. Point and spot: intensity I(dir).
    /// Directional: irradiance E.
    pub radiance: Rgb,
    /// Probability of choosing this light (power CDF).
    pub pdf_choose: f32,
    /// Density of `p` in area measure, selection not included: area 1/A; distant lights
    /// 1/(π r²) on the disk; point and spot 1 (Dirac).
    pub pdf_pos: f32,
    /// Density of `dir` given `p` in solid angle, selection not included: area |cos|/π
    /// (half that when double-sided); point 1/4π; spot 1/(2π(1 − cos θ_outer)); directional 1
    /// (Dirac); environment [`Environment::pdf`](super::Environment::pdf) of −dir.
    pub pdf_dir: f32,
    /// |n·dir| for area lights, 1 otherwise.
    pub cos: f32,
}

/// Centre and radius of a sphere holding the axis-aligned box [`min`, `max`]: the box's
/// centre and half its diagonal, padded by 0.1% and 10⁻⁶ so that points on the box's corners
/// lie strictly inside and a box of one point still has a positive radius. A box that is
/// empty or not finite (`min` > `max` on an axis, as an empty scene's bounds are) gives the
/// unit sphere at the origin. The host's power estimate uses the unpadded half diagonal;
/// the 0.1% only changes the disk distant lights emit from, not what they deliver.
pub fn scene_sphere(min: Vec3, max: Vec3) -> (Vec3, f32) {
    let extent = max - min;
    if !(extent.min_element() >= 0.0 && extent.is_finite()) {
        return (Vec3::ZERO, 1.0);
    }
    let centre = 0.5 * (min + max);
    (centre, 0.5 * extent.length() * 1.001 + 1e-6)
}

/// x > 0, false for NaN: the guard of every density and size here.
#[inline]
fn positive(x: f32) -> bool {
    x > 0.0
}

/// A point on the disk of radius `radius` perpendicular to `dir`, centred at
/// `centre − dir·radius`, uniform from `u`; density 1/(π r²).
#[inline]
fn disk_point(dir: Vec3, (centre, radius): (Vec3, f32), u: Vec2) -> Vec3 {
    let frame = Frame::from_z(dir);
    let d = concentric_disk(u) * radius;
    centre - dir * radius + frame.x * d.x + frame.y * d.y
}

impl<'a> Lights<'a> {
    /// Chooses a light by power with `u_light` ([`sample_cdf_remapped`], as
    /// [`Lights::sample_from_pair`] chooses; the rescaled remainder is not consumed here, since
    /// the position and the direction have their own numbers) and samples a ray it emits:
    /// the position from `u_pos`, the direction from `u_dir` (module docs for each kind).
    /// `bounds` = (centre, radius) of a sphere holding the scene ([`scene_sphere`]): distant
    /// lights emit from the disk of that radius perpendicular to the ray, centred at
    /// centre − dir·radius. A double-sided area light takes its front face where
    /// `u_dir.x < 0.5` and its back face otherwise, `u_dir.x` rescaled to [0, 1). `None` where
    /// nothing is emitted: no lights, a zero density or a black radiance.
    pub fn sample_emission(
        &self,
        u_light: f32,
        u_pos: Vec2,
        u_dir: Vec2,
        bounds: (Vec3, f32),
    ) -> Option<EmissionSample> {
        if self.is_empty() {
            return None;
        }
        let (i, pdf_choose, _) = sample_cdf_remapped(self.power_cdf, u_light);
        if pdf_choose <= 0.0 {
            return None;
        }
        let kind = self.kind(i);
        let base = EmissionSample {
            light: i as u32,
            kind,
            p: Vec3::ZERO,
            p_error: Vec3::ZERO,
            n: Vec3::Z,
            dir: Vec3::Z,
            radiance: Rgb::ZERO,
            pdf_choose,
            pdf_pos: 1.0,
            pdf_dir: 1.0,
            cos: 1.0,
        };
        let s = match kind {
            LightKind::Area => self.emission_area(i, u_pos, u_dir, base)?,
            LightKind::Positional => {
                let l = self.punctual_at(i)?;
                let (dir, pdf_dir) = if l.kind == PunctualKind::Spot {
                    if l.cos_outer >= 1.0 {
                        return None;
                    }
                    let local = uniform_cone(u_dir, l.cos_outer);
                    let dir = Frame::from_z(l.direction).to_world(local).normalize();
                    (dir, uniform_cone_pdf(l.cos_outer))
                } else {
                    (uniform_sphere(u_dir), 1.0 / (4.0 * PI))
                };
                EmissionSample {
                    p: l.position,
                    n: dir,
                    dir,
                    radiance: l.intensity_towards(dir),
                    pdf_dir,
                    ..base
                }
            }
            LightKind::Directional => {
                let dir = self.punctual_at(i)?.direction;
                if !positive(bounds.1) {
                    return None;
                }
                EmissionSample {
                    p: disk_point(dir, bounds, u_pos),
                    n: dir,
                    dir,
                    radiance: self.punctual_at(i)?.intensity,
                    pdf_pos: 1.0 / (PI * bounds.1 * bounds.1),
                    ..base
                }
            }
            LightKind::Environment => {
                if !positive(bounds.1) {
                    return None;
                }
                let e = self.environment.sample(u_dir)?;
                let dir = -e.dir;
                EmissionSample {
                    p: disk_point(dir, bounds, u_pos),
                    n: dir,
                    dir,
                    radiance: e.radiance,
                    pdf_pos: 1.0 / (PI * bounds.1 * bounds.1),
                    pdf_dir: e.pdf,
                    ..base
                }
            }
        };
        let densities = s.pdf_pos * s.pdf_dir;
        (densities > 0.0 && densities.is_finite() && !s.radiance.is_black()).then_some(s)
    }

    /// The area-light part of [`Lights::sample_emission`].
    #[inline]
    fn emission_area(
        &self,
        i: usize,
        u_pos: Vec2,
        u_dir: Vec2,
        base: EmissionSample,
    ) -> Option<EmissionSample> {
        let e = self.emitters.get(i)?;
        if !positive(e.area) {
            return None;
        }
        let b = uniform_triangle(u_pos);
        // The face emitted from, and the direction number left for the hemisphere.
        let (n, u_dir, faces) = if e.double_sided == 0 {
            (e.n, u_dir, 1.0)
        } else if u_dir.x < 0.5 {
            (e.n, Vec2::new(2.0 * u_dir.x, u_dir.y), 2.0)
        } else {
            let x = (2.0 * u_dir.x - 1.0).min(ONE_MINUS_EPSILON);
            (-e.n, Vec2::new(x, u_dir.y), 2.0)
        };
        let dir = Frame::from_z(n)
            .to_world(cosine_hemisphere(u_dir))
            .normalize();
        let cos = n.dot(dir);
        if !positive(cos) {
            return None;
        }
        Some(EmissionSample {
            p: e.p0 * b[0] + e.p1 * b[1] + e.p2 * b[2],
            p_error: barycentric_error(b, e.p0, e.p1, e.p2),
            n,
            dir,
            radiance: e.emission_at(b, self.materials, self.textures),
            pdf_pos: 1.0 / e.area,
            pdf_dir: cosine_hemisphere_pdf(cos) / faces,
            cos,
            ..base
        })
    }

    /// Densities with which [`Lights::sample_emission`] would have produced a ray leaving
    /// area emitter `i` from a point on it in unit direction `w` (pointing away from the
    /// emitter): (pdf_pos·pdf_choose in area measure, pdf_dir in solid angle). (0, 0) where
    /// the face does not emit towards `w` (or `i` is not an area emitter).
    pub fn emission_pdf_area(&self, i: usize, w: Vec3) -> (f32, f32) {
        let Some(e) = self.emitters.get(i) else {
            return (0.0, 0.0);
        };
        let cos = e.n.dot(w);
        let pdf_dir = if e.double_sided != 0 {
            cosine_hemisphere_pdf(cos.abs()) * 0.5
        } else {
            cosine_hemisphere_pdf(cos)
        };
        let pdf_pos = self.pdf_area(i);
        if pdf_dir > 0.0 && pdf_pos > 0.0 {
            (pdf_pos, pdf_dir)
        } else {
            (0.0, 0.0)
        }
    }

    /// For the environment seen along unit direction `to_env` (from the scene towards the
    /// sky): (pdf_pos·pdf_choose = pdf_choose/(π r²), pdf_dir = [`Environment::pdf`] of
    /// `to_env`), with r = `radius` as in `sample_emission`'s bounds. (0, 0) without an
    /// environment or a positive radius; pdf_dir alone is 0 where the map is black.
    ///
    /// [`Environment::pdf`]: super::Environment::pdf
    pub fn emission_pdf_environment(&self, to_env: Vec3, radius: f32) -> (f32, f32) {
        let Some(i) = self.environment_index() else {
            return (0.0, 0.0);
        };
        let pdf_dir = self.environment.pdf(to_env);
        let pdf_pos = self.choose_pdf(i) / (PI * radius * radius);
        if radius > 0.0 && pdf_pos.is_finite() {
            (pdf_pos, pdf_dir)
        } else {
            (0.0, 0.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::environment::build_map_distribution;
    use crate::light::{light_powers, Emitter, Environment, PunctualLight};
    use crate::rng::Rng;
    use crate::sampling::build_cdf;

    fn triangle(p0: Vec3, p1: Vec3, p2: Vec3, radiance: f32, double_sided: bool) -> Emitter {
        let c = (p1 - p0).cross(p2 - p0);
        Emitter {
            p0,
            p1,
            p2,
            n: c.normalize(),
            area: 0.5 * c.length(),
            radiance: Rgb::splat(radiance),
            double_sided: u32::from(double_sided),
            prim: 0,
            material: u32::MAX,
            uv0: [Vec2::ZERO; 3],
            uv1: [Vec2::ZERO; 3],
            color: [Rgb::ONE; 3],
            vertex_colored: 0,
        }
    }

    fn emitters() -> [Emitter; 2] {
        [
            triangle(Vec3::ZERO, Vec3::X, Vec3::Y, 2.0, false),
            triangle(
                Vec3::new(0.0, 1.0, 1.0),
                Vec3::new(2.0, 0.0, 1.0),
                Vec3::new(0.5, 2.0, -0.5),
                0.5,
                true,
            ),
        ]
    }

    /// A point light, a hard-edged spot, a soft spot and a directional light.
    fn punctual() -> [PunctualLight; 4] {
        let (d30, d10) = (30f32.to_radians(), 10f32.to_radians());
        let axis = Vec3::new(0.3, -1.0, 0.2);
        [
            PunctualLight::point(Vec3::new(0.5, 3.0, 0.0), Rgb::splat(1.5)),
            PunctualLight::spot(Vec3::Y * 2.0, axis, Rgb::splat(4.0), d30, d30),
            PunctualLight::spot(Vec3::Y * 2.0, -axis, Rgb::splat(4.0), d10, d30),
            PunctualLight::directional(Vec3::new(-0.2, -1.0, 0.4), Rgb::splat(0.7)),
        ]
    }

    /// A 16×8 map with a bright texel and a black row (as environment.rs's tests use).
    fn map_texels() -> Vec<Rgb> {
        (0..8)
            .flat_map(|y| (0..16).map(move |x| (x, y)))
            .map(|(x, y)| match (x, y) {
                (_, 5) => Rgb::ZERO,
                (3, 2) => Rgb::new(40.0, 20.0, 80.0),
                _ => Rgb::splat(0.1 + 0.05 * x as f32),
            })
            .collect()
    }

    /// The power estimate L·cos/(p_choose·p_pos·p_dir) averaged per light over `n` emitted
    /// rays (a light that is not chosen adds 0), with every sample's directions checked:
    /// (c) they lie in the emitting hemisphere, cone or direction, and distant lights start
    /// on their disk; and (a) the densities of area and environment samples are what
    /// `emission_pdf_*` report for the same ray (`mismatches` counts map samples away from
    /// the poles on a texel edge, where the round trip may find the neighbouring texel).
    fn mean_power_per_light(lights: &Lights, bounds: (Vec3, f32), n: usize) -> (Vec<f64>, usize) {
        let mut sums = vec![0.0f64; lights.count()];
        let mut mismatches = 0;
        let mut r = Rng::new(23, 7);
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-4 * a.abs().max(b.abs());
        for _ in 0..n {
            let Some(s) = lights.sample_emission(r.uniform(), r.uniform2(), r.uniform2(), bounds)
            else {
                continue;
            };
            let i = s.light as usize;
            assert_eq!(s.kind, lights.kind(i));
            assert!((s.dir.length() - 1.0).abs() < 1e-4, "{s:?}");
            assert!((s.pdf_choose - lights.choose_pdf(i)).abs() < 1e-6);
            match s.kind {
                LightKind::Area => {
                    let e = &lights.emitters[i];
                    assert!(s.n.dot(s.dir) > 0.0 && s.n.abs() == e.n.abs(), "{s:?}");
                    assert!(e.double_sided != 0 || s.n == e.n);
                    assert!(close(s.cos, s.n.dot(s.dir)));
                    let (pos, dir) = lights.emission_pdf_area(i, s.dir);
                    assert!(close(pos, s.pdf_choose * s.pdf_pos) && close(dir, s.pdf_dir));
                    // The ray leaves from the triangle.
                    assert!((s.p - e.p0).dot(e.n).abs() < 1e-5);
                }
                LightKind::Positional => {
                    let l = lights.punctual_at(i).unwrap();
                    assert_eq!((s.p, s.n), (l.position, s.dir));
                    if l.kind == PunctualKind::Spot {
                        assert!(s.dir.dot(l.direction) >= l.cos_outer - 1e-5, "{s:?}");
                    }
                }
                LightKind::Directional | LightKind::Environment => {
                    let start = bounds.0 - s.dir * bounds.1;
                    assert!((s.p - start).dot(s.dir).abs() < 1e-4);
                    assert!((s.p - start).length() <= bounds.1 * (1.0 + 1e-5));
                    assert_eq!(s.n, s.dir);
                    if s.kind == LightKind::Directional {
                        assert_eq!(s.dir, lights.punctual_at(i).unwrap().direction);
                    } else {
                        assert_eq!(s.radiance, lights.environment.radiance(-s.dir));
                        let (pos, dir) = lights.emission_pdf_environment(-s.dir, bounds.1);
                        assert!(close(pos, s.pdf_choose * s.pdf_pos));
                        // Near the poles the map's 1/sin θ amplifies the rounding of θ.
                        let sin2 = 1.0 - s.dir.y * s.dir.y;
                        if sin2 > 0.0025 && (dir - s.pdf_dir).abs() > 1e-3 * s.pdf_dir {
                            mismatches += 1;
                        }
                    }
                }
            }
            let estimate = s.radiance.luminance() * s.cos / (s.pdf_choose * s.pdf_pos * s.pdf_dir);
            sums[i] += estimate as f64 / n as f64;
        }
        (sums, mismatches)
    }

    /// (b) Every light emits its power in expectation: the power `light_powers` gives it, and
    /// for the soft spot the exact ∫ I·falloff dω (module docs), which the selection estimate
    /// overstates.
    #[test]
    fn emitted_rays_carry_each_lights_power() {
        let es = emitters();
        let pl = punctual();
        let texels = map_texels();
        let dist = build_map_distribution(16, 8, &texels).unwrap();
        let bounds = scene_sphere(Vec3::new(-1.0, -0.5, -1.0), Vec3::new(2.0, 3.0, 1.5));
        for env in [
            Environment::constant(Rgb::new(0.2, 0.3, 0.1)),
            Environment::map(16, 8, &texels, &dist, 0.5, 40.0),
        ] {
            let powers = light_powers(&es, &pl, &env, bounds.1);
            let cdf = build_cdf(&powers).unwrap();
            let lights = Lights {
                emitters: &es,
                punctual: &pl,
                environment: env,
                power_cdf: &cdf,
                materials: &[],
                textures: &[],
            };
            let n = 4_000_000;
            let (got, mismatches) = mean_power_per_light(&lights, bounds, n);
            assert!(mismatches <= n / 1000, "{mismatches} density mismatches");
            let mut want: Vec<f64> = powers.iter().map(|&p| p as f64).collect();
            let soft = &pl[2];
            let (ci, co) = (soft.cos_inner as f64, soft.cos_outer as f64);
            let exact = 2.0 * std::f64::consts::PI * ((1.0 - ci) + (ci - co) / 3.0) * 4.0;
            assert!(
                want[4] > exact * 1.05,
                "the estimate is pbrt-v4's linear one"
            );
            want[4] = exact;
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!((g / w - 1.0).abs() < 0.03, "light {k}: {g} vs {w}");
            }
        }
    }

    /// Both faces of a double-sided emitter, chosen by `u_dir.x`; one-sided emitters give no
    /// density behind them; no lights, no environment or a black point give nothing.
    #[test]
    fn faces_and_absent_lights() {
        let es = emitters();
        let cdf = build_cdf(&es.iter().map(Emitter::power).collect::<Vec<_>>()).unwrap();
        let lights = Lights::area_only(&es, &cdf);
        let bounds = (Vec3::ZERO, 3.0);
        // u_light 0.9 chooses the double-sided emitter (index 1).
        let front = lights.sample_emission(0.9, Vec2::splat(0.3), Vec2::new(0.2, 0.6), bounds);
        let back = lights.sample_emission(0.9, Vec2::splat(0.3), Vec2::new(0.7, 0.6), bounds);
        let (front, back) = (front.unwrap(), back.unwrap());
        assert_eq!((front.light, back.light), (1, 1));
        assert_eq!((front.n, back.n), (es[1].n, -es[1].n));
        assert!(front.dir.dot(es[1].n) > 0.0 && back.dir.dot(es[1].n) < 0.0);
        // 0.2 and 0.7 both rescale to 0.4: the same angle from the normal on either side.
        assert!((back.dir.dot(es[1].n) + front.dir.dot(es[1].n)).abs() < 1e-5);
        assert!((back.cos - front.cos).abs() < 1e-5 && (back.pdf_dir - front.pdf_dir).abs() < 1e-6);
        assert!((front.pdf_dir - front.cos / (2.0 * PI)).abs() < 1e-6);

        assert_eq!(lights.emission_pdf_area(0, -Vec3::Z), (0.0, 0.0));
        let (pos, dir) = lights.emission_pdf_area(0, Vec3::Z);
        assert!((pos - lights.pdf_area(0)).abs() < 1e-7 && (dir - 1.0 / PI).abs() < 1e-6);
        assert_eq!(lights.emission_pdf_area(5, Vec3::Z), (0.0, 0.0));
        assert_eq!(lights.emission_pdf_environment(Vec3::Y, 3.0), (0.0, 0.0));

        let none = Lights::area_only(&[], &[]);
        assert!(none
            .sample_emission(0.5, Vec2::ZERO, Vec2::ZERO, bounds)
            .is_none());
        let mut dark = es;
        dark[0].radiance = Rgb::ZERO;
        let lights = Lights::area_only(&dark, &cdf);
        assert!(lights
            .sample_emission(0.1, Vec2::splat(0.3), Vec2::splat(0.5), bounds)
            .is_none());
    }

    #[test]
    fn scene_sphere_holds_the_box() {
        let (lo, hi) = (Vec3::new(-1.0, 2.0, 0.0), Vec3::new(3.0, 2.5, 4.0));
        let (c, r) = scene_sphere(lo, hi);
        for k in 0..8 {
            let corner = Vec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            assert!(corner.distance(c) < r);
        }
        assert!(r < 0.51 * (hi - lo).length());
        let (c, r) = scene_sphere(Vec3::ONE, Vec3::ONE);
        assert!(c == Vec3::ONE && r > 0.0);
        assert_eq!(
            scene_sphere(Vec3::INFINITY, -Vec3::INFINITY),
            (Vec3::ZERO, 1.0)
        );
    }
}
