//! Thin-film interference of `KHR_materials_iridescence`: the Fresnel term of a dielectric
//! film (index η₂, thickness d in nm) between the outside (η₁ = 1) and the base, in RGB, after
//! Belcour & Barla 2017 ("A Practical Extension to Microfacet Theory for the Modeling of
//! Varying Iridescence") as the extension's sample implementation evaluates it.
//!
//! With c₁ = ω_o·h the cosine at the film, c₂ = √(1 − (η₁/η₂)² (1 − c₁²)) inside it (Snell),
//! Schlick reflectances R₁₂ = F(R₀(η₂, η₁), c₁) at the top and R₂₃ = F(R₀(η₃, η₂), c₂) at
//! the base (η₃ per channel from the base's F0, η₃ = (1 + √F0)/(1 − √F0)), T₁₂₁ = 1 − R₁₂,
//! phase shifts φ₂₁ = π − φ₁₂ (φ₁₂ = π where η₂ < η₁) and φ₂₃ = π where η₃ < η₂, and the optical
//! path difference OPD = 2 η₂ d c₂, the Airy sum of the film's multiple reflections is
//!
//!   I = R₁₂ + R_s + Σ_{m=1,2} C_m S_m,    R_s = T₁₂₁² R₂₃ / (1 − R₁₂R₂₃),
//!   C_m = (R_s − T₁₂₁) (√(R₁₂R₂₃))^m,    S_m = 2 V(m · OPD, m · (φ₂₁ + φ₂₃)),
//!
//! where V(OPD, shift) is the Fourier transform of the CIE XYZ matching functions (Gaussian
//! fits of the paper) at the phase 2π OPD, taken to linear Rec. 709 RGB; negative results
//! (out of gamut) are clamped to 0. Total internal reflection in the film gives 1.
//!
//! The material's specular Fresnel becomes mix(F_Schlick, I, iridescence) for its
//! dielectric part (base F0 = the dielectric f0) and its metal part (base F0 = base colour),
//! evaluated at ω_o·h like the Schlick term, so the lobe stays reciprocal. A film of
//! thickness 0 is no film: the base's Schlick Fresnel (the sample implementation blends
//! η₂ → η₁ over the first 0.03 nm, kept here, but its Airy sum with Schlick's R₁₂ = (1 − c)⁵
//! at η₂ = η₁ still differs from the bare base by up to 0.03).

use crate::Rgb;
use std::f32::consts::PI;

/// The thin film over a glTF specular lobe (factor 0: none, the lobe's Schlick Fresnel).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ThinFilm {
    /// iridescenceFactor in [0, 1].
    pub factor: f32,
    /// Film index of refraction η₂.
    pub ior: f32,
    /// Film thickness d in nanometres.
    pub thickness: f32,
    /// Weight and base F0 of the dielectric part ((1 − m)(1 − t_v) and f0_d).
    pub diel_weight: f32,
    pub diel_f0: Rgb,
    /// Weight and base F0 of the metal part (m and the base colour).
    pub metal_weight: f32,
    pub metal_f0: Rgb,
}

impl ThinFilm {
    #[inline]
    pub fn is_some(&self) -> bool {
        self.factor > 0.0
    }

    /// mix(`schlick`, I, factor) with I the film's reflectance over the two bases, weighted.
    #[inline]
    pub fn fresnel(&self, schlick: Rgb, c: f32) -> Rgb {
        let mut film = Rgb::ZERO;
        if self.diel_weight > 0.0 {
            film +=
                iridescence_fresnel(self.ior, self.thickness, self.diel_f0, c) * self.diel_weight;
        }
        if self.metal_weight > 0.0 {
            film +=
                iridescence_fresnel(self.ior, self.thickness, self.metal_f0, c) * self.metal_weight;
        }
        schlick * (1.0 - self.factor) + film * self.factor
    }

    /// An f0 for the Schlick albedo tables that bounds the film's dielectric reflectance from
    /// above at the cosines sampled (F_Schlick(f0', c) ≥ I(c)), for the energy coupling of
    /// the diffuse base: the base receives what the film leaves, not what Schlick leaves.
    pub fn coupling_f0(&self, f0: f32) -> f32 {
        let mut out = f0;
        for k in 0..16 {
            let c = 1.0 - k as f32 / 20.0;
            let w = (1.0 - c).powi(5);
            let i = iridescence_fresnel(self.ior, self.thickness, self.diel_f0, c).max_component();
            out = out.max(((i - w) / (1.0 - w)).clamp(0.0, 1.0));
        }
        f0 + (out - f0) * self.factor
    }
}

/// Schlick's Fresnel of a scalar f0 at cosine `c`.
#[inline]
fn schlick(f0: f32, c: f32) -> f32 {
    let m = (1.0 - c.abs().min(1.0)).max(0.0);
    let m2 = m * m;
    f0 + (1.0 - f0) * m2 * m2 * m
}

/// ((η_t − η_i)/(η_t + η_i))².
#[inline]
fn ior_to_f0(t: f32, i: f32) -> f32 {
    let r = (t - i) / (t + i);
    r * r
}

/// XYZ (Rec. 709 white) to linear Rec. 709 RGB, row-major.
const XYZ_TO_RGB: [[f32; 3]; 3] = [
    [3.240_454_2, -1.537_138_5, -0.498_531_4],
    [-0.969_266, 1.876_010_8, 0.041_556],
    [0.055_643_4, -0.204_025_9, 1.057_225_2],
];

/// V(OPD, shift): the XYZ matching functions' Fourier transform at phase 2π·OPD (OPD in nm),
/// one shift per channel, in linear RGB (Belcour & Barla 2017, their Gaussian fits).
fn sensitivity(opd: f32, shift: [f32; 3]) -> [f32; 3] {
    let phase = 2.0 * PI as f64 * opd as f64 * 1.0e-9;
    const VAL: [f64; 3] = [5.4856e-13, 4.4201e-13, 5.2481e-13];
    const POS: [f64; 3] = [1.6810e+06, 1.7953e+06, 2.2084e+06];
    const VAR: [f64; 3] = [4.3278e+09, 9.3046e+09, 6.6121e+09];
    let tau = 2.0 * std::f64::consts::PI;
    let mut xyz = [0.0f64; 3];
    for k in 0..3 {
        xyz[k] = VAL[k]
            * (tau * VAR[k]).sqrt()
            * (POS[k] * phase + shift[k] as f64).cos()
            * (-phase * phase * VAR[k]).exp();
    }
    xyz[0] += 9.7470e-14
        * (tau * 4.5282e+09f64).sqrt()
        * (2.2399e+06 * phase + shift[0] as f64).cos()
        * (-4.5282e+09 * phase * phase).exp();
    let xyz = xyz.map(|v| (v / 1.0685e-7) as f32);
    XYZ_TO_RGB.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2])
}

/// The film's RGB reflectance I (module docs) for film index `eta2`, thickness `d` nm,
/// base reflectance `base_f0` and cosine `c1` at the film.
pub fn iridescence_fresnel(eta2: f32, d: f32, base_f0: Rgb, c1: f32) -> Rgb {
    let outside = 1.0f32;
    let c1 = c1.abs().min(1.0);
    if d.is_nan() || d <= 0.0 {
        // No film: the bare base (the Airy sum's Schlick terms do not vanish at d = 0).
        return Rgb::from_array(base_f0.to_array().map(|f| schlick(f.clamp(0.0, 1.0), c1)));
    }
    // η₂ → η₁ as d → 0 (smoothstep over 0..0.03 nm, as the sample implementation).
    let t = (d / 0.03).clamp(0.0, 1.0);
    let eta2 = outside + (eta2 - outside) * t * t * (3.0 - 2.0 * t);
    let sin2 = (outside / eta2).powi(2) * (1.0 - c1 * c1);
    let cos2_sq = 1.0 - sin2;
    if cos2_sq < 0.0 || !eta2.is_finite() {
        return Rgb::ONE;
    }
    let c2 = cos2_sq.sqrt();
    let r12 = schlick(ior_to_f0(eta2, outside), c1);
    let t121 = 1.0 - r12;
    let phi12 = if eta2 < outside { PI } else { 0.0 };
    let phi21 = PI - phi12;
    let opd = 2.0 * eta2 * d * c2;
    let f0 = base_f0.to_array().map(|x| x.clamp(0.0, 0.9999));
    let mut r23 = [0.0f32; 3];
    let mut phi = [0.0f32; 3];
    for k in 0..3 {
        let s = f0[k].sqrt();
        let eta3 = (1.0 + s) / (1.0 - s);
        r23[k] = schlick(ior_to_f0(eta3, eta2), c2);
        phi[k] = phi21 + if eta3 < eta2 { PI } else { 0.0 };
    }
    let mut out = [0.0f32; 3];
    let mut cm = [0.0f32; 3];
    let mut r123 = [0.0f32; 3];
    for k in 0..3 {
        let r = (r12 * r23[k]).clamp(1e-5, 0.9999);
        r123[k] = r.sqrt();
        let rs = t121 * t121 * r23[k] / (1.0 - r);
        out[k] = r12 + rs;
        cm[k] = rs - t121;
    }
    for m in 1..=2 {
        let mf = m as f32;
        let s = sensitivity(mf * opd, phi.map(|p| mf * p));
        for k in 0..3 {
            cm[k] *= r123[k];
            out[k] += cm[k] * 2.0 * s[k];
        }
    }
    let [r, g, b] = out.map(|v| {
        if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        }
    });
    Rgb::new(r, g, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A film of thickness 0 is no film: the reflectance is the base's Schlick Fresnel.
    #[test]
    fn zero_thickness_is_the_bare_base() {
        for c in [1.0f32, 0.7, 0.3, 0.05] {
            let i = iridescence_fresnel(1.3, 0.0, Rgb::splat(0.04), c);
            let s = schlick(0.04, c);
            for v in i.to_array() {
                assert_eq!(v, s, "c {c}");
            }
        }
    }

    /// The film colours the reflection (channels differ at 300 nm), tends to 1 at grazing
    /// incidence and stays in [0, 1].
    #[test]
    fn film_colours_the_reflection() {
        let i = iridescence_fresnel(1.3, 300.0, Rgb::splat(0.04), 1.0);
        let a = i.to_array();
        let spread =
            a.iter().cloned().fold(0.0f32, f32::max) - a.iter().cloned().fold(1.0f32, f32::min);
        assert!(spread > 0.01, "{i:?}");
        let g = iridescence_fresnel(1.3, 300.0, Rgb::splat(0.04), 0.001);
        assert!(g.to_array().iter().all(|&v| v > 0.9), "{g:?}");
        for d in [0.0f32, 50.0, 200.0, 400.0, 1200.0] {
            for c in [0.0f32, 0.2, 0.6, 1.0] {
                let i = iridescence_fresnel(1.5, d, Rgb::new(0.9, 0.5, 0.02), c);
                assert!(i.to_array().iter().all(|v| (0.0..=1.0).contains(v)));
            }
        }
    }
}
