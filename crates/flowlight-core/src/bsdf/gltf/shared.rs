//! The material-wide terms every lobe of the glTF mixture shares: the coat attenuation
//! A(μ) and the coupling of the diffuse base to the dielectric specular layer (formulas in
//! the [module documentation](super)).

use super::super::albedo::{schlick_albedo, schlick_albedo_at, schlick_albedo_pair, Roughness};
use super::{PairOutgoing, COAT_F0};
use crate::Rgb;
use glam::Vec3;

/// Material-wide data every lobe needs: the coat attenuation and the coupling of the diffuse
/// base to the dielectric specular layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfShared {
    /// Clearcoat factor c (0: no coat).
    pub coat: f32,
    /// Clearcoat GGX α_c.
    pub coat_alpha: f32,
    /// Base GGX α.
    pub alpha: f32,
    /// Max-channel dielectric Schlick f0 and f90.
    pub diel_f0: f32,
    pub diel_f90: f32,
    /// 1 / (1 − Ē_d), 0 when the dielectric layer leaves nothing to the base.
    pub diffuse_norm: f32,
}

impl GltfShared {
    /// Coat attenuation A(μ) = 1 − c E_c(μ).
    #[inline]
    pub fn coat_attenuation(&self, mu: f32) -> f32 {
        if self.coat <= 0.0 {
            return 1.0;
        }
        (1.0 - self.coat * schlick_albedo(COAT_F0, 1.0, self.coat_alpha, mu)).max(0.0)
    }

    /// A(μ_o) A(μ_i) for a coated material, the two lookups sharing their roughness
    /// coordinate ([`super::albedo::directional_pair`]); the same value as the product of two
    /// [`GltfShared::coat_attenuation`] calls, bit for bit.
    #[inline]
    pub(super) fn coat_attenuation_pair(&self, mu_o: f32, mu_i: f32) -> f32 {
        let (eo, ei) = schlick_albedo_pair(COAT_F0, 1.0, self.coat_alpha, mu_o, mu_i);
        (1.0 - self.coat * eo).max(0.0) * (1.0 - self.coat * ei).max(0.0)
    }

    /// Directional albedo E_d(μ) of the dielectric specular layer (largest channel).
    #[inline]
    pub fn dielectric_albedo(&self, mu: f32) -> f32 {
        schlick_albedo(self.diel_f0, self.diel_f90, self.alpha, mu)
    }

    /// The diffuse base's coupling (1 − E_d(μ_o)) (1 − E_d(μ_i)) / (1 − Ē_d), its two albedo
    /// lookups sharing their roughness coordinate.
    ///
    /// Without a dielectric layer (`KHR_materials_specular` factor 0: f0 = f90 = 0, as in the
    /// Lambertian Cornell box) the lookups are skipped: E_d = 0·(E₁ − E₅) + 0·E₅ is ±0 for the
    /// finite table values every non-NaN α reads (a NaN μ reads the μ = 1 column, as `min`
    /// drops NaN), so each factor (1 − E_d).max(0) is exactly 1 and the coupling is exactly
    /// 1/(1 − Ē_d), the value the lookups give, bit for bit.
    #[inline]
    pub(super) fn diffuse_coupling(&self, mu_o: f32, mu_i: f32) -> f32 {
        if self.without_layer() {
            return self.diffuse_norm;
        }
        let (eo, ei) = schlick_albedo_pair(self.diel_f0, self.diel_f90, self.alpha, mu_o, mu_i);
        (1.0 - eo).max(0.0) * (1.0 - ei).max(0.0) * self.diffuse_norm
    }

    /// Whether [`GltfShared::diffuse_coupling`] skips its lookups (no dielectric layer).
    #[inline]
    pub(super) fn without_layer(&self) -> bool {
        self.diel_f0 == 0.0 && self.diel_f90 == 0.0 && !self.alpha.is_nan()
    }

    /// The ω_o terms of [`GltfShared::diffuse_coupling`]: the factor 1 − E_d(μ_o) (1 where
    /// the coupling has no lookups) and the roughness coordinate of the lookups.
    #[inline]
    pub(super) fn outgoing_coupling(&self, mu_o: f32) -> (f32, Roughness) {
        let rough = Roughness::new(self.alpha);
        if self.without_layer() {
            return (1.0, rough);
        }
        let eo = schlick_albedo_at(self.diel_f0, self.diel_f90, rough, mu_o);
        ((1.0 - eo).max(0.0), rough)
    }

    /// [`GltfShared::diffuse_coupling`] from the ω_o terms in `at`: the same value, bit for
    /// bit, since a lookup of the pair equals the lookup alone
    /// ([`super::albedo::directional_pair`]) and the product is taken in the same order.
    #[inline]
    pub(super) fn diffuse_coupling_with(&self, at: &PairOutgoing, mu_i: f32) -> f32 {
        if self.without_layer() {
            return self.diffuse_norm;
        }
        let ei = schlick_albedo_at(self.diel_f0, self.diel_f90, at.rough, mu_i);
        at.base_o * (1.0 - ei).max(0.0) * self.diffuse_norm
    }

    /// Max-channel dielectric Schlick Fresnel at cos = `c`.
    #[inline]
    pub(super) fn diel_fresnel(&self, c: f32) -> f32 {
        self.diel_f0 + (self.diel_f90 - self.diel_f0) * w5(c)
    }
}

/// (1 − |c|)⁵.
#[inline]
pub(super) fn w5(c: f32) -> f32 {
    let m = (1.0 - c.abs().min(1.0)).max(0.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's Fresnel with colour f0 and f90.
#[inline]
pub fn schlick_f0_f90(f0: Rgb, f90: Rgb, c: f32) -> Rgb {
    let w = w5(c);
    f0 * (1.0 - w) + f90 * w
}

/// The coat attenuation A(μ_o) A(μ_i) of one (ω_o, ω_i) pair, computed by the first lobe of a
/// mixture pass that needs it and reused by the others with the same coat (c, α_c): the lobes
/// of one material all have the same, so a coated material looks its coat albedo up twice per
/// pass instead of twice per lobe. Make a new one for every pair.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CoatAttenuation {
    /// (c, α_c) bits of the value held, if any.
    key: Option<(u32, u32)>,
    value: f32,
}

impl CoatAttenuation {
    #[inline]
    pub(super) fn get(&mut self, shared: &GltfShared, wo: Vec3, wi: Vec3) -> f32 {
        let key = (shared.coat.to_bits(), shared.coat_alpha.to_bits());
        if self.key != Some(key) {
            self.value = shared.coat_attenuation_pair(wo.z, wi.z);
            self.key = Some(key);
        }
        self.value
    }
}

/// Both directions mirrored into the upper hemisphere of `wo`.
#[inline]
pub(super) fn to_upper(wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
    if wo.z < 0.0 {
        (flip(wo), flip(wi))
    } else {
        (wo, wi)
    }
}

#[inline]
pub(super) fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}
