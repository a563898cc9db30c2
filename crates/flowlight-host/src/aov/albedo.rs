//! The albedo AOV: the reflectance of a glTF material seen from one direction, as a denoiser
//! takes it (Open Image Denoise wants "the reflectance", the colour a surface gives to white
//! light from everywhere, not the base colour alone).
//!
//! For the material of `flowlight_core::bsdf::gltf` (ρ base colour, m metallic, t
//! transmission, α = roughness², s / C specular factor / colour, η ior, c / α_c clearcoat)
//! at μ = |cos θ_o| against the shading normal, with E₁, E₅ the GGX tables of
//! `flowlight_core::bsdf::albedo`:
//!
//! ```text
//! f0_d = min(((η − 1)/(η + 1))² C, 1) s,   f90_d = s,   t_v = t if volumetric else 0
//! f0_S = (1 − m)(1 − t_v) f0_d + m ρ,   f90_S = (1 − m)(1 − t_v) f90_d + m
//! E_S  = f0_S (E₁ − E₅) + f90_S E₅                           specular layer (per channel)
//! E_d  = max(f0_d) (E₁ − E₅) + f90_d E₅                      dielectric layer, as coupled
//! A_base = E_S + (1 − m)(1 − t) ρ (1 − E_d) + (1 − m) t ρ T,  T = 1 volumetric, 1 − E_d thin
//! A = c E_c(μ) + (1 − c E_c(μ)) (1 − c Ē_c) A_base,   E_c = 0.04 (E₁ − E₅) + E₅ at α_c
//! ```
//!
//! This is the directional albedo ∫ f |cos θ_i| dω_i of the BSDF itself where the model makes
//! it exact (the specular layer and the energy-coupled diffuse base: the module docs of
//! `gltf` show the diffuse term integrates to (1 − m)(1 − t) ρ (1 − E_d(μ_o))), and the
//! transmission's tint ρ where light leaves through the other side (counted whole, as the
//! colour seen through it). A plain diffuse material (specular 0, as the Cornell box's
//! walls) has A = ρ exactly. Single scattering, clamped to [0, 1] per channel.

use flowlight_core::bsdf::albedo::{directional, schlick_average};
use flowlight_core::bsdf::gltf::{f0_from_ior, COAT_F0};
use flowlight_core::material::Material;
use flowlight_core::Rgb;

/// [`reflectance`] for a material whose textures are resolved (`base` the textured base
/// colour), seen at `mu` = |cos θ_o|.
pub fn reflectance(m: &Material, base: Rgb, mu: f32) -> Rgb {
    let unit = |x: f32| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let rho = Rgb::new(unit(base.r), unit(base.g), unit(base.b));
    let metal = unit(m.metallic);
    let alpha = unit(m.roughness).powi(2);
    let t = unit(m.transmission);
    let s = unit(m.specular);
    let ior = if m.ior.is_finite() && m.ior >= 0.0 {
        m.ior
    } else {
        1.5
    };
    let tint = |x: f32| if x.is_finite() { x.max(0.0) } else { 1.0 };
    let c = m.specular_color;
    let f0_d = Rgb::new(
        (tint(c.r) * f0_from_ior(ior)).min(1.0),
        (tint(c.g) * f0_from_ior(ior)).min(1.0),
        (tint(c.b) * f0_from_ior(ior)).min(1.0),
    ) * s;
    let volumetric = m.thickness > 0.0 && t > 0.0;
    let t_v = if volumetric { t } else { 0.0 };
    let dielectric = (1.0 - metal) * (1.0 - t_v);
    let f0_s = f0_d * dielectric + rho * metal;
    let f90_s = s * dielectric + metal;
    let mu = if mu.is_finite() {
        mu.abs().min(1.0)
    } else {
        1.0
    };
    let (e1, e5) = directional(alpha, mu);
    let specular = f0_s * (e1 - e5) + Rgb::splat(f90_s * e5);
    let e_d = (f0_d.max_component() * (e1 - e5) + s * e5).clamp(0.0, 1.0);
    let diffuse = rho * ((1.0 - metal) * (1.0 - t) * (1.0 - e_d));
    let through = if volumetric { 1.0 } else { 1.0 - e_d };
    let transmission = rho * ((1.0 - metal) * t * through);
    let layer = specular + diffuse + transmission;
    let coat = unit(m.clearcoat);
    let total = if coat > 0.0 {
        let coat_alpha = unit(m.clearcoat_roughness).powi(2);
        let (c1, c5) = directional(coat_alpha, mu);
        let e_c = coat * (COAT_F0 * (c1 - c5) + c5);
        // The base is attenuated on the way in, A(μ_o), and out, A(μ_i) averaged over the
        // cosine-weighted hemisphere (exact for a diffuse base).
        let out = 1.0 - coat * schlick_average(COAT_F0, 1.0, coat_alpha);
        Rgb::splat(e_c) + layer * ((1.0 - e_c) * out)
    } else {
        layer
    };
    Rgb::new(unit(total.r), unit(total.g), unit(total.b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::bsdf::Bsdf;
    use flowlight_core::rng::Rng;
    use glam::Vec3;

    /// ∫ f |cos θ_i| dω_i of the material's BSDF at `wo` by BSDF sampling (n samples).
    fn estimate(m: &Material, wo: Vec3, n: usize) -> Rgb {
        let bsdf = Bsdf::from_material(m, m.base_color);
        let mut rng = Rng::new(11, 3);
        let mut sum = Rgb::ZERO;
        for _ in 0..n {
            if let Some(s) = bsdf.sample(wo, rng.uniform(), rng.uniform2()) {
                let w = s.f * (s.wi.z.abs() / s.pdf);
                // Undo the radiance scaling of a refraction (1/η'²): the albedo counts the
                // light that leaves, not the radiance squeezed into the glass.
                sum += w * (s.eta * s.eta);
            }
        }
        sum * (1.0 / n as f32)
    }

    /// The reflectance is the BSDF's own directional albedo (by Monte Carlo, within its noise)
    /// for diffuse, glossy dielectric, rough metal and coated materials, and exactly the base
    /// colour for a plain diffuse one.
    #[test]
    fn reflectance_is_the_bsdfs_directional_albedo() {
        let base = Rgb::new(0.7, 0.4, 0.2);
        let plain = Material {
            base_color: base,
            specular: 0.0,
            ..Material::default()
        };
        assert_eq!(reflectance(&plain, base, 0.3), base);
        let cases = [
            Material {
                base_color: base,
                roughness: 0.4,
                ..Material::default()
            },
            Material {
                base_color: base,
                metallic: 1.0,
                roughness: 0.5,
                ..Material::default()
            },
            Material {
                base_color: base,
                roughness: 0.6,
                clearcoat: 0.8,
                clearcoat_roughness: 0.3,
                ..Material::default()
            },
        ];
        for m in cases {
            for mu in [0.9f32, 0.5, 0.2] {
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let mc = estimate(&m, wo, 200_000);
                let a = reflectance(&m, m.base_color, mu);
                for (x, y) in [(a.r, mc.r), (a.g, mc.g), (a.b, mc.b)] {
                    assert!((x - y).abs() < 0.02, "{m:?} μ {mu}: {a:?} vs MC {mc:?}");
                }
            }
        }
    }
}
