//! Veach's perturbation kernels (Veach 1997 §11.4.3–11.4.5; thesis §5.4): the jump
//! distributions of the lens, caustic and multi-chain perturbations.
//!
//! **Lens jump** ([`LensJump`]): the raster position moves by a distance r in a uniformly
//! random direction φ, with r exponentially (log-uniformly) distributed between r₁ and r₂:
//!
//! ```text
//! r = r₂ · (r₁/r₂)^U,   U uniform in [0, 1)    ⇒   p(r) = 1 / (r · ln(r₂/r₁)),  r₁ ≤ r ≤ r₂
//! ```
//!
//! so that every scale between r₁ and r₂ gets the same share of the jumps. Per unit raster
//! area (the film measure of the target function, [`crate::measure`]) the density is
//!
//! ```text
//! T₀(u → u') = p(r) / (2π r) = 1 / (2π r² ln(r₂/r₁)),   r = |u' − u| ∈ [r₁, r₂], u' on the film
//! ```
//!
//! and 0 otherwise. It depends on |u' − u| alone, so it is symmetric: T₀(u'→u)/T₀(u→u') = 1.
//! Veach's defaults are r₁ = 0.1 pixel and r₂ = √(0.05 · W · H / π) (a disk of 5 % of the
//! image area). **Film window**: the chains' film window K (`film_window`,
//! [`crate::migration`]) bounds how far a chain moves per step, and ERPT's work units keep a
//! flange of 2K pixels for the deposits of their chains; so the effective outer radius is
//! r₂' = min(r₂, K/2), the largest disk inside the K×K window. When r₂' ≤ r₁ every proposal
//! is a domain miss; with K = 0 the raster position never moves (as for migration).
//!
//! **Exponential cone** ([`ExpCone`]): a direction ω' at angle θ from an axis ω, with θ
//! log-uniform between θ₁ and θ₂ and a uniform azimuth — and, unlike Veach's, a uniform
//! *core* inside θ₁ instead of a hole, so that the density has no edge at θ₁:
//!
//! ```text
//! p(ω') = g(θ) / Z,   g(θ) = 1/(θ sin θ) for θ₁ ≤ θ ≤ θ₂,  1/(θ₁ sin θ₁) for θ < θ₁,
//! Z = 2π (ln(θ₂/θ₁) + (1 − cos θ₁)/(θ₁ sin θ₁))
//! ```
//!
//! (the core, sampled uniformly in solid angle, takes (1 − cos θ₁)/(θ₁ sin θ₁) / (Z/2π) ≈
//! 1/(1 + 2 ln(θ₂/θ₁)) of the moves: 6.7 % with Veach's angles). The densities are evaluated
//! from stored vertex positions, whose directions differ from the sampled ones by rounding
//! and the ray-origin offset (about 10⁻⁶ over a short segment): at a hard edge at θ₁ = 10⁻⁴
//! such a proposal could get density 0, an impossible move that was made. With the core, the
//! density is continuous and the rounding only perturbs it slightly. Again a function of the
//! angle alone (symmetric); Veach's defaults for the caustic and multi-chain perturbations are
//! θ₁ = 10⁻⁴ and θ₂ = 0.1 radians. The angle is computed as atan2(|ω × ω'|, ω·ω') in f64,
//! which resolves angles of 10⁻⁴ (acos of an f32 dot product does not).

use flowlight_core::geometry::Frame;
use flowlight_core::rng::Rng;
use glam::{DVec3, Vec2, Vec3};
use std::f64::consts::PI;

/// The lens perturbation's raster jump (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LensJump {
    /// Smallest jump, pixels.
    pub r1: f32,
    /// Largest jump, pixels (before the film window's bound).
    pub r2: f32,
}

impl LensJump {
    /// Veach's sizes for a `width` × `height` film: r₁ = 0.1, r₂ = √(0.05·W·H/π).
    pub fn veach(width: u32, height: u32) -> LensJump {
        LensJump {
            r1: 0.1,
            r2: (0.05 * width as f64 * height as f64 / PI).sqrt() as f32,
        }
    }

    /// Veach's sizes with the plugin parameters [`crate::params::R1`] and
    /// [`crate::params::R2`] (0: Veach's r₂) applied, as the lens and multi-chain
    /// perturbations declare them; a bad value is a one-line error naming the parameter.
    pub fn from_params(
        params: &flowlight_sdk::Params,
        width: u32,
        height: u32,
    ) -> Result<LensJump, String> {
        let mut jump = LensJump::veach(width, height);
        let r1 = crate::params::R1.get(params)?;
        let r2 = crate::params::R2.get(params)?;
        if !(r2 == 0.0 || r2 > r1) {
            return Err(format!(
                "parameter 'r2' must be 0 (Veach's default) or greater than r1 = {r1}, got {r2}"
            ));
        }
        jump.r1 = r1 as f32;
        if r2 > 0.0 {
            jump.r2 = r2 as f32;
        }
        Ok(jump)
    }

    /// The outer radius inside the film window K: min(r₂, K/2).
    pub fn outer(&self, k: u32) -> f32 {
        self.r2.min(k as f32 * 0.5)
    }

    /// A jumped raster position, or `None` (a domain miss) off the film or when the window
    /// leaves no room for a jump of at least r₁.
    pub fn sample(
        &self,
        raster: Vec2,
        k: u32,
        width: u32,
        height: u32,
        rng: &mut Rng,
    ) -> Option<Vec2> {
        if k == 0 {
            return Some(raster);
        }
        let r2 = self.outer(k);
        if r2 <= self.r1 {
            return None;
        }
        let r = r2 * (self.r1 / r2).powf(rng.uniform());
        let phi = 2.0 * std::f32::consts::PI * rng.uniform();
        let p = raster + Vec2::new(phi.cos(), phi.sin()) * r;
        on_film(p, width, height).then_some(p)
    }

    /// Density per unit raster area of jumping from `from` to `to` (module docs).
    pub fn density(&self, from: Vec2, to: Vec2, k: u32, width: u32, height: u32) -> f64 {
        if k == 0 {
            return if from == to { 1.0 } else { 0.0 };
        }
        let r2 = self.outer(k) as f64;
        let r1 = self.r1 as f64;
        let r = (to.as_dvec2() - from.as_dvec2()).length();
        // The sampled radius and the one the positions give differ by f32 rounding.
        let slack = 1e-5 * r2;
        if r2 <= r1 || !on_film(to, width, height) || r < r1 - slack || r > r2 + slack || r <= 0.0 {
            return 0.0;
        }
        1.0 / (2.0 * PI * r * r * (r2 / r1).ln())
    }
}

/// Whether `p` is on the `width` × `height` film.
fn on_film(p: Vec2, width: u32, height: u32) -> bool {
    p.x >= 0.0 && p.y >= 0.0 && p.x < width as f32 && p.y < height as f32
}

/// Directions in an exponentially distributed cone around an axis (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExpCone {
    /// Smallest angle of the log-uniform part, radians (below it: the uniform core).
    pub theta1: f32,
    /// Largest angle, radians.
    pub theta2: f32,
}

impl ExpCone {
    /// Veach's angles: θ₁ = 10⁻⁴, θ₂ = 0.1 radians.
    pub const VEACH: ExpCone = ExpCone {
        theta1: 1e-4,
        theta2: 0.1,
    };

    /// Checks 0 < θ₁ < θ₂ ≤ π/2 (names the parameters in the error).
    pub fn new(theta1: f64, theta2: f64) -> Result<ExpCone, String> {
        if !(theta1 > 0.0 && theta1 < theta2 && theta2 <= std::f64::consts::FRAC_PI_2) {
            return Err(format!(
                "parameters 'theta1' and 'theta2' must satisfy 0 < theta1 < theta2 <= pi/2 radians, got {theta1} and {theta2}"
            ));
        }
        Ok(ExpCone {
            theta1: theta1 as f32,
            theta2: theta2 as f32,
        })
    }

    fn angles(&self) -> (f64, f64) {
        (self.theta1 as f64, self.theta2 as f64)
    }

    /// Solid angle of the core θ < θ₁ weighted by g = 1/(θ₁ sin θ₁), over 2π.
    fn core_mass(&self) -> f64 {
        let (t1, _) = self.angles();
        (1.0 - t1.cos()) / (t1 * t1.sin())
    }

    /// Normalisation Z = ∫ g dω = 2π (ln(θ₂/θ₁) + (1 − cos θ₁)/(θ₁ sin θ₁)).
    fn norm(&self) -> f64 {
        let (t1, t2) = self.angles();
        2.0 * PI * ((t2 / t1).ln() + self.core_mass())
    }

    /// A direction around the unit `axis`.
    pub fn sample(&self, axis: Vec3, rng: &mut Rng) -> Vec3 {
        let (t1, t2) = self.angles();
        let p_core = 2.0 * PI * self.core_mass() / self.norm();
        let theta = if (rng.uniform() as f64) < p_core {
            // Uniform in solid angle inside θ₁: cos θ = 1 − u (1 − cos θ₁), written with
            // half-angle sines to keep its precision.
            let u = rng.uniform() as f64;
            2.0 * (u * (1.0 - t1.cos()) * 0.5).sqrt().asin()
        } else {
            t2 * (t1 / t2).powf(rng.uniform() as f64)
        };
        let phi = 2.0 * PI * rng.uniform() as f64;
        let (s, c) = theta.sin_cos();
        let local = DVec3::new(s * phi.cos(), s * phi.sin(), c);
        let f = Frame::from_z(axis);
        let (x, y, z) = (f.x.as_dvec3(), f.y.as_dvec3(), f.z.as_dvec3());
        (x * local.x + y * local.y + z * local.z)
            .normalize()
            .as_vec3()
    }

    /// Solid-angle density of `w` around `axis` (both unit vectors): g(θ)/Z with
    /// g = 1/(θ sin θ) on [θ₁, θ₂] and 1/(θ₁ sin θ₁) below θ₁ (module docs).
    pub fn pdf(&self, axis: Vec3, w: Vec3) -> f64 {
        self.pdf_angle(angle(axis, w))
    }

    /// [`ExpCone::pdf`] of the angle θ.
    pub fn pdf_angle(&self, theta: f64) -> f64 {
        let (t1, t2) = self.angles();
        // The sampled largest angle may come back a rounding error larger.
        if theta > t2 * (1.0 + 1e-4) || theta.is_nan() {
            return 0.0;
        }
        let t = theta.max(t1);
        1.0 / (t * t.sin() * self.norm())
    }
}

/// Angle between two directions, accurate for small angles.
pub fn angle(a: Vec3, b: Vec3) -> f64 {
    let (a, b): (DVec3, DVec3) = (a.as_dvec3().normalize(), b.as_dvec3().normalize());
    a.cross(b).length().atan2(a.dot(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lens_jumps_are_log_uniform_in_radius_and_their_density_integrates_to_one() {
        let jump = LensJump { r1: 0.1, r2: 16.0 };
        let mut rng = Rng::new(5, 2);
        let start = Vec2::new(64.0, 64.0);
        // Log-uniform: each of four equal ranges of ln r gets a quarter of the jumps.
        let (lo, hi) = (0.1f64.ln(), 8.0f64.ln()); // K = 16: r₂' = 8
        let mut bins = [0usize; 4];
        let n = 40_000;
        for _ in 0..n {
            let p = jump.sample(start, 16, 128, 128, &mut rng).unwrap();
            let r = (p - start).length() as f64;
            let b = ((r.ln() - lo) / (hi - lo) * 4.0).floor().clamp(0.0, 3.0) as usize;
            bins[b] += 1;
            let d = jump.density(start, p, 16, 128, 128);
            assert!(
                (d * 2.0 * PI * r * r * (80.0f64).ln() - 1.0).abs() < 1e-3,
                "{d}"
            );
            assert_eq!(d, jump.density(p, start, 16, 128, 128), "symmetric");
        }
        for b in bins {
            assert!((b as f64 / (n as f64 / 4.0) - 1.0).abs() < 0.05, "{bins:?}");
        }
        // ∫ T₀ dA over the annulus = 1 (midpoint rule in ln r).
        let m = 2000;
        let integral: f64 = (0..m)
            .map(|i| {
                let lr = lo + (hi - lo) * (i as f64 + 0.5) / m as f64;
                let r = lr.exp();
                let to = start + Vec2::new(r as f32, 0.0);
                jump.density(start, to, 16, 128, 128) * 2.0 * PI * r * r * (hi - lo) / m as f64
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
        assert_eq!(
            jump.density(start, start + Vec2::new(9.0, 0.0), 16, 128, 128),
            0.0
        );
        assert_eq!(
            jump.density(start, start + Vec2::new(0.05, 0.0), 16, 128, 128),
            0.0
        );
    }

    #[test]
    fn cone_angles_are_log_uniform_above_theta1_and_the_density_is_what_is_sampled() {
        let cone = ExpCone::VEACH;
        let axis = Vec3::new(0.3, -0.5, 0.8).normalize();
        let mut rng = Rng::new(9, 4);
        let (lo, hi) = (1e-4f64.ln(), 0.1f64.ln());
        let mut bins = [0usize; 4];
        let (n, mut core) = (40_000, 0usize);
        let mut inv = 0.0;
        for _ in 0..n {
            let w = cone.sample(axis, &mut rng);
            let t = angle(axis, w);
            let p = cone.pdf(axis, w);
            assert!(p > 0.0, "{t}");
            inv += 1.0 / p;
            if t < 1e-4 {
                core += 1;
                continue;
            }
            let b = ((t.ln() - lo) / (hi - lo) * 4.0).floor().clamp(0.0, 3.0) as usize;
            bins[b] += 1;
        }
        // The core's share, 1/(1 + 2 ln 1000) to first order; the rest log-uniform.
        let share = core as f64 / n as f64;
        assert!(
            (share / (1.0 / (1.0 + 2.0 * 1000f64.ln())) - 1.0).abs() < 0.06,
            "{share}"
        );
        let rest = (n - core) as f64 / 4.0;
        for b in bins {
            assert!((b as f64 / rest - 1.0).abs() < 0.05, "{bins:?}");
        }
        // E[1/p(ω)] over the samples is the solid angle of the support, 2π(1 − cos θ₂):
        // the density is the one the sampler draws from.
        let support = 2.0 * PI * (1.0 - 0.1f64.cos());
        assert!(
            (inv / n as f64 / support - 1.0).abs() < 0.05,
            "{inv} vs {support}"
        );
        // Continuous at θ₁, 0 beyond θ₂.
        let (a, b) = (cone.pdf_angle(0.99e-4), cone.pdf_angle(1.01e-4));
        assert!((a / b - 1.0).abs() < 0.03, "{a} {b}");
        assert_eq!(cone.pdf_angle(0.2), 0.0);
        assert!(ExpCone::new(0.1, 0.01).is_err());
    }
}
