//! The scene's lights and their sampling: emissive triangles ([`Emitter`]), the punctual
//! lights of `KHR_lights_punctual` ([`punctual`]) and the environment ([`environment`]);
//! the rays they emit, for light subpaths, in [`emission`].
//!
//! Light selection. Every light has an index in one list: the area emitters first, then the
//! punctual lights, then the environment when there is one. Next-event estimation chooses a
//! light from one CDF over their powers Φ (in the renderer's radiometric units):
//!
//! ```text
//! area emitter      Φ = π · A · L̄ · (1 or 2 faces)       L̄ = mean emitted luminance
//! point light       Φ = 4π · I
//! spot light        Φ = 2π (1 − (cos θ_inner + cos θ_outer)/2) · I
//! directional       Φ = π r² · E                           r = scene bounding-sphere radius
//! environment       Φ = π r² · ∫ L dω
//! ```
//!
//! Emitted radiance of a triangle is [`Material::emission_at`] at the point's two texture
//! coordinate sets (interpolated from the emitter's stored vertex uvs), so an emissive texture
//! is honoured where the light is sampled and where it is hit alike. L̄ is that radiance
//! averaged over the triangle (by the loader, with stratified samples); a triangle whose
//! average is zero is not a light.
//!
//! Delta lights (point, spot, directional) have no density a BSDF sample could reach: their
//! connections carry weight 1 and the "density" an estimator divides by is the selection
//! probability alone ([`Incident::delta`]).

pub mod emission;
pub mod environment;
pub mod punctual;

pub use emission::{scene_sphere, EmissionSample};
pub use environment::{Environment, EnvironmentKind};
pub use punctual::{PunctualKind, PunctualLight};

use crate::geometry::barycentric_error;
use crate::material::{Material, Texture};
use crate::sampling::{sample_cdf, sample_cdf_remapped, uniform_triangle};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// One emissive triangle. The scene's emitter table lists every triangle whose emission,
/// integrated over it, is non-zero.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitter {
    pub p0: Vec3,
    pub p1: Vec3,
    pub p2: Vec3,
    /// Unit geometric normal (counter-clockwise winding is the front).
    pub n: Vec3,
    pub area: f32,
    /// Mean emitted radiance over the triangle (texture included): what its power is from.
    pub radiance: Rgb,
    /// 1 when both faces emit.
    pub double_sided: u32,
    /// Global triangle index (what a ray hit reports).
    pub prim: u32,
    /// Index of the triangle's material in the scene's material table.
    pub material: u32,
    /// Texture coordinates of the three vertices, set 0 (TEXCOORD_0) …
    pub uv0: [Vec2; 3],
    /// … and set 1 (TEXCOORD_1).
    pub uv1: [Vec2; 3],
    /// Linear RGB of `COLOR_0` at the three vertices, multiplied into the emission when
    /// `vertex_colored` is 1. Only an unlit material's emission takes them (its colour is
    /// base colour × `COLOR_0`, `KHR_materials_unlit`); glTF's `emissiveFactor` and
    /// `emissiveTexture` are not multiplied by vertex colours, so other emitters hold 1s and 0.
    pub color: [Rgb; 3],
    /// 1 when the emission is multiplied by `color`.
    pub vertex_colored: u32,
}

impl Emitter {
    /// Whether direction `w` (pointing away from the emitter) leaves an emitting face.
    #[inline]
    pub fn faces(&self, w: Vec3) -> bool {
        self.double_sided != 0 || self.n.dot(w) > 0.0
    }

    /// Barycentrics of a point `p` on the triangle (clamped onto it).
    #[inline]
    pub fn barycentrics(&self, p: Vec3) -> [f32; 3] {
        let e1 = self.p1 - self.p0;
        let e2 = self.p2 - self.p0;
        let v = p - self.p0;
        let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (d20, d21) = (v.dot(e1), v.dot(e2));
        let denom = d00 * d11 - d01 * d01;
        if !(denom > 0.0 && denom.is_finite()) {
            return [1.0 / 3.0; 3];
        }
        let b1 = ((d11 * d20 - d01 * d21) / denom).clamp(0.0, 1.0);
        let b2 = ((d00 * d21 - d01 * d20) / denom).clamp(0.0, 1.0 - b1);
        [1.0 - b1 - b2, b1, b2]
    }

    /// Both texture coordinate sets at barycentrics `b`.
    #[inline]
    pub fn uv_at(&self, b: [f32; 3]) -> [Vec2; 2] {
        let i = |t: &[Vec2; 3]| t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
        [i(&self.uv0), i(&self.uv1)]
    }

    /// Emitted radiance at barycentrics `b`, towards nothing in particular: the material's
    /// emission there, or the stored mean when the material table does not have it.
    #[inline]
    pub fn emission_at(&self, b: [f32; 3], materials: &[Material], textures: &[Texture]) -> Rgb {
        self.emission_at_with(|| b, materials, textures)
    }

    /// [`Emitter::emission_at`] with the barycentrics computed only where they matter: a
    /// material without an emissive texture or vertex colours emits its factor everywhere
    /// (what [`Material::emission_at`] returns for it), so neither the point's barycentrics
    /// nor its texture coordinates are computed for it.
    #[inline]
    pub fn emission_at_with(
        &self,
        b: impl FnOnce() -> [f32; 3],
        materials: &[Material],
        textures: &[Texture],
    ) -> Rgb {
        let Some(m) = materials.get(self.material as usize) else {
            return self.radiance;
        };
        if !m.emissive_texture.is_some() && self.vertex_colored == 0 {
            return m.emission;
        }
        let b = b();
        let emission = if m.emissive_texture.is_some() {
            m.emission_at(self.uv_at(b), textures)
        } else {
            m.emission
        };
        emission * self.color_at(b)
    }

    /// The vertex colour at barycentrics `b` (1s for an emitter without vertex colours).
    #[inline]
    pub fn color_at(&self, b: [f32; 3]) -> Rgb {
        if self.vertex_colored == 0 {
            return Rgb::ONE;
        }
        self.color[0] * b[0] + self.color[1] * b[1] + self.color[2] * b[2]
    }

    /// Power Φ = π · area · mean luminance · faces. Lights are chosen in proportion.
    pub fn power(&self) -> f32 {
        let faces = if self.double_sided != 0 { 2.0 } else { 1.0 };
        PI * self.area * self.radiance.luminance() * faces
    }
}

/// What kind of light a light index is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    Area,
    /// A point or spot light: a Dirac in position.
    Positional,
    /// A directional light: a Dirac in direction.
    Directional,
    Environment,
}

impl LightKind {
    #[inline]
    pub fn is_delta(self) -> bool {
        matches!(self, LightKind::Positional | LightKind::Directional)
    }
    /// Lights at infinity: shadow rays to them are unbounded.
    #[inline]
    pub fn is_distant(self) -> bool {
        matches!(self, LightKind::Directional | LightKind::Environment)
    }
}

/// A point (or direction) sampled on the lights.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Index in the unified light list (module docs).
    pub light: u32,
    pub kind: LightKind,
    /// Position on an area or positional light (unused for distant lights).
    pub p: Vec3,
    pub p_error: Vec3,
    /// Surface normal of an area light; for distant lights the unit direction towards them.
    pub n: Vec3,
    /// Barycentrics on an area light.
    pub bary: [f32; 3],
    /// Area light: area density (selection included). Environment: solid-angle density
    /// (selection included). Delta lights: the selection probability.
    pub pdf: f32,
    /// Environment: the radiance arriving along the sampled direction.
    pub radiance: Rgb,
}

/// Where a shadow ray must go.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShadowTarget {
    Point {
        p: Vec3,
        p_error: Vec3,
        n: Vec3,
    },
    /// Unbounded along the direction (distant lights).
    Infinity,
}

/// A light sample seen from a reference point (before the visibility test).
#[derive(Clone, Copy, Debug)]
pub struct Incident {
    /// Unit world direction from the reference point towards the light.
    pub wi: Vec3,
    /// Area or environment: radiance arriving along −wi. Positional: I(−wi)/d². Directional:
    /// the irradiance at normal incidence.
    pub radiance: Rgb,
    /// Area: |cos θ_light|/d²; positional: 1/d²; distant: 1.
    pub geometry: f32,
    /// What an estimator divides by: solid-angle density for area and environment lights;
    /// the selection probability for delta lights.
    pub pdf: f32,
    /// True for delta lights: no MIS against BSDF sampling.
    pub delta: bool,
    pub target: ShadowTarget,
}

/// The scene's lights and their selection CDF.
#[derive(Clone, Copy, Debug)]
pub struct Lights<'a> {
    pub emitters: &'a [Emitter],
    pub punctual: &'a [PunctualLight],
    pub environment: Environment,
    /// CDF over the powers of all lights, in the order of the module docs.
    pub power_cdf: &'a [f32],
    /// The material and texture tables emission is evaluated from.
    pub materials: &'a [Material],
    pub textures: &'a [Texture],
}

/// Powers of all lights in the unified order (module docs); `scene_radius` sizes the
/// distant ones.
pub fn light_powers(
    emitters: &[Emitter],
    punctual: &[PunctualLight],
    environment: &Environment,
    scene_radius: f32,
) -> Vec<f32> {
    let mut p: Vec<f32> = emitters.iter().map(Emitter::power).collect();
    p.extend(punctual.iter().map(|l| l.power(scene_radius)));
    if environment.is_present() {
        p.push(environment.power(scene_radius));
    }
    p
}

impl<'a> Lights<'a> {
    /// Lights over area emitters only (no punctual lights, no environment).
    pub fn area_only(emitters: &'a [Emitter], power_cdf: &'a [f32]) -> Lights<'a> {
        Lights {
            emitters,
            punctual: &[],
            environment: Environment::none(),
            power_cdf,
            materials: &[],
            textures: &[],
        }
    }

    /// Number of lights in the unified list.
    #[inline]
    pub fn count(&self) -> usize {
        self.emitters.len() + self.punctual.len() + usize::from(self.environment.is_present())
    }

    pub fn is_empty(&self) -> bool {
        self.count() == 0 || self.power_cdf.len() != self.count()
    }

    /// Kind of light index `i`.
    #[inline]
    pub fn kind(&self, i: usize) -> LightKind {
        let (na, np) = (self.emitters.len(), self.punctual.len());
        if i < na {
            LightKind::Area
        } else if i < na + np {
            if self.punctual[i - na].is_distant() {
                LightKind::Directional
            } else {
                LightKind::Positional
            }
        } else {
            LightKind::Environment
        }
    }

    /// The punctual light at unified index `i`, if it is one.
    #[inline]
    pub fn punctual_at(&self, i: usize) -> Option<&'a PunctualLight> {
        i.checked_sub(self.emitters.len())
            .and_then(|j| self.punctual.get(j))
    }

    /// Unified index of the environment, when there is one.
    #[inline]
    pub fn environment_index(&self) -> Option<usize> {
        self.environment
            .is_present()
            .then(|| self.emitters.len() + self.punctual.len())
    }

    /// Probability that light `i` is chosen.
    #[inline]
    pub fn choose_pdf(&self, i: usize) -> f32 {
        if self.is_empty() || i >= self.power_cdf.len() {
            return 0.0;
        }
        let lo = if i == 0 { 0.0 } else { self.power_cdf[i - 1] };
        self.power_cdf[i] - lo
    }

    /// Chooses a light by power and a point (or direction) on it, both from one pair `u`:
    /// `u.x` chooses the light and, rescaled into the chosen light's share of [0, 1)
    /// ([`sample_cdf_remapped`]), is the point's first number. With a pixel's stratified
    /// pairs a lamp made of several triangles (a glTF quad is two) gets them stratified on
    /// each of its triangles, where [`Lights::sample`]'s separately drawn, randomly paired
    /// choice scatters them: what the path tracers use.
    #[inline(always)]
    pub fn sample_from_pair(&self, u: Vec2) -> Option<LightSample> {
        if self.is_empty() {
            return None;
        }
        let (i, p_choose, ux) = sample_cdf_remapped(self.power_cdf, u.x);
        self.sample_light(i, p_choose, Vec2::new(ux, u.y))
    }

    /// Chooses a light by power with `u_light` and a point (or direction) on it with `u`.
    /// With independent numbers it is as good as [`Lights::sample_from_pair`]; with
    /// stratified ones prefer that.
    #[inline]
    pub fn sample(&self, u_light: f32, u: Vec2) -> Option<LightSample> {
        if self.is_empty() {
            return None;
        }
        let (i, p_choose) = sample_cdf(self.power_cdf, u_light);
        self.sample_light(i, p_choose, u)
    }

    /// A point (or direction) on light `i`, chosen with probability `p_choose`, from `u`.
    #[inline(always)]
    fn sample_light(&self, i: usize, p_choose: f32, u: Vec2) -> Option<LightSample> {
        if p_choose <= 0.0 {
            return None;
        }
        let kind = self.kind(i);
        let none = LightSample {
            light: i as u32,
            kind,
            p: Vec3::ZERO,
            p_error: Vec3::ZERO,
            n: Vec3::Z,
            bary: [0.0; 3],
            pdf: p_choose,
            radiance: Rgb::ZERO,
        };
        match kind {
            LightKind::Area => {
                let e = &self.emitters[i];
                if e.area <= 0.0 {
                    return None;
                }
                let b = uniform_triangle(u);
                Some(LightSample {
                    p: e.p0 * b[0] + e.p1 * b[1] + e.p2 * b[2],
                    p_error: barycentric_error(b, e.p0, e.p1, e.p2),
                    n: e.n,
                    bary: b,
                    pdf: p_choose / e.area,
                    ..none
                })
            }
            LightKind::Positional => Some(LightSample {
                p: self.punctual_at(i)?.position,
                ..none
            }),
            LightKind::Directional => Some(LightSample {
                n: -self.punctual_at(i)?.direction,
                ..none
            }),
            LightKind::Environment => {
                let s = self.environment.sample(u)?;
                Some(LightSample {
                    n: s.dir,
                    pdf: p_choose * s.pdf,
                    radiance: s.radiance,
                    ..none
                })
            }
        }
    }

    /// The light sample `ls` as seen from `p_ref`. `None` when it carries no light there
    /// (back face, outside a spot's cone, grazing, coincident).
    ///
    /// Always inlined: as a call it returned its `Option<Incident>` through the stack, after
    /// a square root and two divisions, and was 4.7% of a Cornell box render's samples.
    #[inline(always)]
    pub fn incident(&self, ls: &LightSample, p_ref: Vec3) -> Option<Incident> {
        let i = ls.light as usize;
        match ls.kind {
            LightKind::Area | LightKind::Positional => {
                let d = ls.p - p_ref;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0 && dist2.is_finite()) {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let target = ShadowTarget::Point {
                    p: ls.p,
                    p_error: ls.p_error,
                    n: ls.n,
                };
                if ls.kind == LightKind::Area {
                    let e = self.emitters.get(i)?;
                    let cos_light = ls.n.dot(-wi).abs();
                    if cos_light <= 0.0 || ls.pdf <= 0.0 || !e.faces(-wi) {
                        return None;
                    }
                    let radiance = e.emission_at(ls.bary, self.materials, self.textures);
                    // The density from the area density and dist²/cos directly, not through
                    // `geometry`: two divisions side by side instead of one after the other.
                    Some(Incident {
                        wi,
                        radiance,
                        geometry: cos_light / dist2,
                        pdf: ls.pdf * dist2 / cos_light,
                        delta: false,
                        target,
                    })
                } else {
                    let l = self.punctual_at(i)?;
                    let intensity = l.intensity_towards(-wi);
                    if intensity.is_black() {
                        return None;
                    }
                    Some(Incident {
                        wi,
                        radiance: intensity / dist2,
                        geometry: 1.0 / dist2,
                        pdf: ls.pdf,
                        delta: true,
                        target: ShadowTarget::Point {
                            p: ls.p,
                            p_error: ls.p_error,
                            n: -wi,
                        },
                    })
                }
            }
            LightKind::Directional => {
                let l = self.punctual_at(i)?;
                Some(Incident {
                    wi: ls.n,
                    radiance: l.intensity,
                    geometry: 1.0,
                    pdf: ls.pdf,
                    delta: true,
                    target: ShadowTarget::Infinity,
                })
            }
            LightKind::Environment => Some(Incident {
                wi: ls.n,
                radiance: ls.radiance,
                geometry: 1.0,
                pdf: ls.pdf,
                delta: false,
                target: ShadowTarget::Infinity,
            }),
        }
    }

    /// Radiance emitted by area emitter `i` at point `p` towards `w` (pointing away from it).
    #[inline]
    pub fn emitted(&self, i: usize, p: Vec3, w: Vec3) -> Rgb {
        match self.emitters.get(i) {
            Some(e) if e.faces(w) => {
                e.emission_at_with(|| e.barycentrics(p), self.materials, self.textures)
            }
            _ => Rgb::ZERO,
        }
    }

    /// Area density with which [`Lights::sample`] picks a point on area emitter `i`.
    #[inline]
    pub fn pdf_area(&self, i: usize) -> f32 {
        if i >= self.emitters.len() {
            return 0.0;
        }
        let area = self.emitters[i].area;
        if area > 0.0 {
            self.choose_pdf(i) / area
        } else {
            0.0
        }
    }

    /// Radiance of the environment along world direction `dir` (zero without one).
    #[inline]
    pub fn environment_radiance(&self, dir: Vec3) -> Rgb {
        self.environment.radiance(dir)
    }

    /// Solid-angle density with which [`Lights::sample`] picks direction `dir` on the
    /// environment (selection included).
    #[inline]
    pub fn pdf_environment(&self, dir: Vec3) -> f32 {
        match self.environment_index() {
            Some(i) => self.choose_pdf(i) * self.environment.pdf(dir),
            None => 0.0,
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
    use crate::sampling::{build_cdf, jittered_moments};

    fn tri(s: f32, l: f32) -> Emitter {
        Emitter {
            p0: Vec3::ZERO,
            p1: Vec3::X * s,
            p2: Vec3::Y * s,
            n: Vec3::Z,
            area: 0.5 * s * s,
            radiance: Rgb::splat(l),
            double_sided: 0,
            prim: 0,
            material: u32::MAX,
            uv0: [Vec2::ZERO, Vec2::X, Vec2::Y],
            uv1: [Vec2::ZERO; 3],
            color: [Rgb::ONE; 3],
            vertex_colored: 0,
        }
    }

    /// A unit-square lamp as its two triangles, as a glTF quad is.
    fn quad_lamp() -> [Emitter; 2] {
        let mut a = tri(1.0, 1.0);
        a.p0 = Vec3::X;
        a.p1 = Vec3::ONE.with_z(0.0);
        a.p2 = Vec3::Y;
        [tri(1.0, 1.0), a]
    }

    /// The choice and the point come from one pair: `u.x` below the first light's share
    /// chooses it, and the point is the triangle map of `u.x` rescaled by that share.
    #[test]
    fn the_pairs_first_number_chooses_the_light_and_then_places_the_point() {
        let es = quad_lamp();
        let cdf = build_cdf(&es.iter().map(|e| e.power()).collect::<Vec<_>>()).unwrap();
        assert_eq!(cdf, [0.5, 1.0]);
        let lights = Lights::area_only(&es, &cdf);
        for (u, light, rescaled) in [
            (Vec2::new(0.1, 0.7), 0, Vec2::new(0.2, 0.7)),
            (Vec2::new(0.8, 0.3), 1, Vec2::new(0.6, 0.3)),
        ] {
            let s = lights.sample_from_pair(u).unwrap();
            let e = &es[light];
            let b = uniform_triangle(rescaled);
            let p = e.p0 * b[0] + e.p1 * b[1] + e.p2 * b[2];
            assert_eq!(s.light, light as u32);
            assert!((s.p - p).length() < 1e-6, "{:?} {:?}", s.p, p);
            assert_eq!(s.pdf, 0.5 / e.area);
        }
    }

    /// What one pair buys: the irradiance of a quad lamp at a point in front of it,
    /// estimated from a pixel's 64 jittered pairs (8 × 8 strata), varies about four times less
    /// with [`Lights::sample_from_pair`] than with [`Lights::sample`]'s separate choice
    /// number. So this fails if the pair's choice stops keeping its strata.
    #[test]
    fn a_lamp_of_two_triangles_keeps_the_pairs_stratification() {
        let es = quad_lamp();
        let cdf = build_cdf(&es.iter().map(|e| e.power()).collect::<Vec<_>>()).unwrap();
        let lights = Lights::area_only(&es, &cdf);
        // In front of the lamp (its normal is +z), facing it.
        let p_ref = Vec3::new(0.3, 0.6, 0.2);
        let irradiance = |s: Option<LightSample>| {
            let inc = lights.incident(&s.unwrap(), p_ref).unwrap();
            (inc.radiance.r * (-inc.wi.z).max(0.0) / inc.pdf) as f64
        };
        let [pair, separate] = jittered_moments(&mut Rng::new(11, 3), 400, 8, |u, r| {
            [
                irradiance(lights.sample_from_pair(u)),
                irradiance(lights.sample(r.uniform(), u)),
            ]
        });
        assert!(
            (pair.0 / separate.0 - 1.0).abs() < 0.03,
            "{pair:?} {separate:?}"
        );
        assert!(
            pair.1 * 2.5 < separate.1,
            "mean and variance: {pair:?} (one pair) against {separate:?} (separate choice)"
        );
    }

    #[test]
    fn lights_are_chosen_by_power_and_pdf_matches() {
        let es = [tri(1.0, 1.0), tri(2.0, 1.0)];
        let cdf = build_cdf(&es.iter().map(|e| e.power()).collect::<Vec<_>>()).unwrap();
        let lights = Lights::area_only(&es, &cdf);
        let mut r = Rng::new(5, 0);
        let mut second = 0;
        for _ in 0..10_000 {
            let s = lights.sample(r.uniform(), r.uniform2()).unwrap();
            assert!((s.pdf - lights.pdf_area(s.light as usize)).abs() < 1e-6);
            second += s.light as usize;
        }
        // Powers 0.5π and 2π: the big one is chosen 80% of the time.
        assert!((second as f32 / 10_000.0 - 0.8).abs() < 0.02);
        assert_eq!(
            lights.emitted(0, Vec3::new(0.2, 0.2, 0.0), -Vec3::Z),
            Rgb::ZERO
        );
        assert_eq!(
            lights.emitted(0, Vec3::new(0.2, 0.2, 0.0), Vec3::Z),
            Rgb::ONE
        );
    }

    #[test]
    fn emission_follows_the_material_at_interpolated_uvs() {
        let mut e = tri(1.0, 1.0);
        e.material = 0;
        let b = e.barycentrics(Vec3::new(0.25, 0.5, 0.0));
        assert!((b[1] - 0.25).abs() < 1e-6 && (b[2] - 0.5).abs() < 1e-6);
        let uv = e.uv_at(b);
        assert!((uv[0] - Vec2::new(0.25, 0.5)).length() < 1e-6);
        let m = Material {
            emission: Rgb::new(1.0, 2.0, 3.0),
            ..Default::default()
        };
        assert_eq!(e.emission_at(b, &[m], &[]), Rgb::new(1.0, 2.0, 3.0));
    }

    /// What a hit on an emitter sees: the material's emission at the point's texture
    /// coordinates where it has an emissive texture (here black on the left half of the
    /// triangle's u range, white on the right), its factor everywhere where it has none, and
    /// the stored mean where the material table lacks it.
    #[test]
    fn emitted_radiance_reads_the_emissive_texture_only_where_there_is_one() {
        use crate::material::{Filter, TexelFormat, TextureRef, Wrap};
        let mut e = tri(1.0, 1.0);
        e.material = 0;
        e.radiance = Rgb::splat(7.0);
        let texels = [0u8, 255];
        let t = Texture {
            width: 2,
            height: 1,
            channels: 1,
            format: TexelFormat::U8,
            wrap_s: Wrap::ClampToEdge,
            wrap_t: Wrap::ClampToEdge,
            filter: Filter::Nearest,
            texels: texels.as_ptr(),
        };
        let textured = Material {
            emission: Rgb::splat(4.0),
            emissive_texture: TextureRef::new(0, 0),
            ..Default::default()
        };
        let plain = Material {
            emission: Rgb::splat(4.0),
            ..Default::default()
        };
        let (left, right) = (Vec3::new(0.1, 0.2, 0.0), Vec3::new(0.7, 0.1, 0.0));
        for (materials, want_left, want_right) in [
            (vec![textured], Rgb::ZERO, Rgb::splat(4.0)),
            (vec![plain], Rgb::splat(4.0), Rgb::splat(4.0)),
            (vec![], Rgb::splat(7.0), Rgb::splat(7.0)),
        ] {
            let lights = Lights {
                emitters: std::slice::from_ref(&e),
                punctual: &[],
                environment: Environment::none(),
                power_cdf: &[1.0],
                materials: &materials,
                textures: std::slice::from_ref(&t),
            };
            assert_eq!(lights.emitted(0, left, Vec3::Z), want_left);
            assert_eq!(lights.emitted(0, right, Vec3::Z), want_right);
            let b = e.barycentrics(right);
            assert_eq!(e.emission_at(b, &materials, &[t]), want_right);
        }
    }

    #[test]
    fn mixed_lights_share_one_cdf_and_delta_lights_use_the_choice_probability() {
        let es = [tri(1.0, 2.0)];
        let pl = [
            PunctualLight::point(Vec3::new(0.0, 0.0, 2.0), Rgb::splat(3.0)),
            PunctualLight::directional(-Vec3::Z, Rgb::splat(0.5)),
        ];
        let env = Environment::constant(Rgb::splat(0.25));
        let powers = light_powers(&es, &pl, &env, 1.0);
        assert_eq!(powers.len(), 4);
        let cdf = build_cdf(&powers).unwrap();
        let lights = Lights {
            emitters: &es,
            punctual: &pl,
            environment: env,
            power_cdf: &cdf,
            materials: &[],
            textures: &[],
        };
        assert_eq!(lights.kind(0), LightKind::Area);
        assert_eq!(lights.kind(1), LightKind::Positional);
        assert_eq!(lights.kind(2), LightKind::Directional);
        assert_eq!(lights.kind(3), LightKind::Environment);
        let total: f32 = powers.iter().sum();
        let mut r = Rng::new(9, 1);
        let mut counts = [0u32; 4];
        let n = 40_000;
        for _ in 0..n {
            let s = lights.sample(r.uniform(), r.uniform2()).unwrap();
            counts[s.light as usize] += 1;
            let p_ref = Vec3::new(0.1, 0.1, -1.0);
            if let Some(inc) = lights.incident(&s, p_ref) {
                match s.kind {
                    LightKind::Positional => {
                        // I / d² with d = 3, divided by the choice probability only.
                        let d2 = (Vec3::new(0.0, 0.0, 2.0) - p_ref).length_squared();
                        assert!((inc.radiance.r - 3.0 / d2).abs() < 1e-5);
                        assert!((inc.pdf - powers[1] / total).abs() < 1e-5 && inc.delta);
                    }
                    LightKind::Directional => {
                        assert_eq!(inc.wi, Vec3::Z);
                        assert_eq!(inc.target, ShadowTarget::Infinity);
                        assert!((inc.pdf - powers[2] / total).abs() < 1e-5);
                    }
                    LightKind::Environment => {
                        let want = powers[3] / total / (4.0 * PI);
                        assert!((inc.pdf - want).abs() < 1e-5);
                        assert!((lights.pdf_environment(inc.wi) - want).abs() < 1e-5);
                    }
                    LightKind::Area => {
                        // Seen from below the front face (normal +Z): no light.
                        unreachable!("the area light faces away from p_ref");
                    }
                }
            }
        }
        for (k, c) in counts.iter().enumerate() {
            let want = powers[k] / total;
            assert!((*c as f32 / n as f32 - want).abs() < 0.01, "{k}: {c}");
        }
    }
}
