//! The environment: radiance arriving from infinitely far away, constant or from an
//! equirectangular (latitude–longitude) map.
//!
//! Map coordinates (+Y up). A texel row v ∈ [0, 1] (top row first) is the polar angle
//! θ = π·v from +Y; a column u ∈ [0, 1] is the azimuth φ = 2π·u, with the local direction
//!
//! ```text
//! d = (sin θ cos φ, cos θ, sin θ sin φ)
//! ```
//!
//! so the left edge of the image looks along +X, a quarter across along +Z, the middle along −X.
//! `rotation_degrees` turns the map about +Y: world = R_y(rotation) · d.
//!
//! Importance sampling (pbrt-v4 §12.5, Mitsuba's `envmap`): a piecewise-constant 2-D density
//! over (u, v) with f(x, y) = luminance(texel) · sin θ_y (θ_y at the row's centre), sampled by
//! a marginal CDF over rows and a conditional CDF per row. With F = Σ f / (W·H),
//!
//! ```text
//! p_uv(u, v) = f(x, y) / F,        p_ω(ω) = p_uv / (2π² sin θ)
//! ```
//!
//! (dω = 2π² sin θ du dv). Rows or maps without energy fall back to uniform columns; a map
//! that is black everywhere is no light at all. A constant environment is sampled uniformly
//! on the sphere, p_ω = 1/4π. The radiance of a map at a direction is its nearest texel times
//! `strength` (piecewise constant, like the density, so the estimator's ratio is smooth).
//!
//! Power (for light selection): Φ = π r² ∫ L dω over the sphere, r the scene's
//! bounding-sphere radius: the power that crosses a disc of the scene's size.

use crate::sampling::{sample_cdf, uniform_sphere};
use crate::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Which environment a scene has.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EnvironmentKind {
    None = 0,
    Constant = 1,
    Map = 2,
}

/// The environment as the plugins see it. The map and its CDFs are owned by the host and
/// valid while the scene lives.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Environment {
    pub kind: EnvironmentKind,
    /// Constant radiance (colour × strength), or the map's multiplier (strength) for a map.
    pub color: Rgb,
    /// cos and sin of the rotation about +Y.
    pub rot_cos: f32,
    pub rot_sin: f32,
    pub width: u32,
    pub height: u32,
    /// `width × height` linear RGB texels, top row first.
    pub texels: *const Rgb,
    /// `height` entries: CDF over rows.
    pub marginal_cdf: *const f32,
    /// `width × height` entries: per row, the CDF over its columns.
    pub conditional_cdf: *const f32,
    /// F = Σ f / (W·H), the normaliser of p_uv.
    pub func_mean: f32,
    /// ∫ L dω (luminance), for the power estimate.
    pub integral: f32,
}

// SAFETY: the environment is immutable during a render; the host keeps its buffers alive.
unsafe impl Send for Environment {}
unsafe impl Sync for Environment {}

impl Default for Environment {
    fn default() -> Self {
        Environment::none()
    }
}

/// The importance-sampling tables of a map (see the module docs), built once by the loader.
#[derive(Clone, Debug, PartialEq)]
pub struct MapDistribution {
    pub marginal_cdf: Vec<f32>,
    pub conditional_cdf: Vec<f32>,
    pub func_mean: f32,
    /// ∫ L dω of the map's luminance (strength 1).
    pub integral: f32,
}

/// sin θ at the centre of row `y` of `height`.
#[inline]
fn row_sin(y: usize, height: usize) -> f32 {
    (PI * (y as f32 + 0.5) / height as f32).sin()
}

/// Builds the 2-D distribution of a `width × height` map. `None` when it has no energy (or a
/// texel is negative or not finite).
pub fn build_map_distribution(width: u32, height: u32, texels: &[Rgb]) -> Option<MapDistribution> {
    let (w, h) = (width as usize, height as usize);
    if w == 0 || h == 0 || texels.len() != w * h {
        return None;
    }
    let mut conditional = Vec::with_capacity(w * h);
    let mut row_sums = Vec::with_capacity(h);
    let mut integral = 0.0f64;
    for y in 0..h {
        let s = row_sin(y, h) as f64;
        let mut acc = 0.0f64;
        let start = conditional.len();
        for x in 0..w {
            let l = texels[y * w + x].luminance() as f64;
            if !(l >= 0.0 && l.is_finite()) {
                return None;
            }
            acc += l * s;
            conditional.push(acc);
        }
        if acc > 0.0 {
            for c in &mut conditional[start..] {
                *c /= acc;
            }
        } else {
            for (x, c) in conditional[start..].iter_mut().enumerate() {
                *c = (x + 1) as f64 / w as f64;
            }
        }
        conditional[start + w - 1] = 1.0;
        row_sums.push(acc);
        integral += acc;
    }
    if integral <= 0.0 {
        return None;
    }
    let mut marginal = Vec::with_capacity(h);
    let mut acc = 0.0f64;
    for s in &row_sums {
        acc += s;
        marginal.push((acc / integral) as f32);
    }
    marginal[h - 1] = 1.0;
    let func_mean = integral / (w * h) as f64;
    Some(MapDistribution {
        marginal_cdf: marginal,
        conditional_cdf: conditional.into_iter().map(|c| c as f32).collect(),
        func_mean: func_mean as f32,
        // ∫ L dω = Σ L sin θ · (2π/W)(π/H) = 2π² F.
        integral: (2.0 * (PI as f64) * (PI as f64) * func_mean) as f32,
    })
}

/// A sampled direction towards the environment.
#[derive(Clone, Copy, Debug)]
pub struct EnvironmentSample {
    /// Unit world direction towards the environment.
    pub dir: Vec3,
    pub radiance: Rgb,
    /// Solid-angle density.
    pub pdf: f32,
}

impl Environment {
    pub const fn none() -> Environment {
        Environment {
            kind: EnvironmentKind::None,
            color: Rgb::ZERO,
            rot_cos: 1.0,
            rot_sin: 0.0,
            width: 0,
            height: 0,
            texels: std::ptr::null(),
            marginal_cdf: std::ptr::null(),
            conditional_cdf: std::ptr::null(),
            func_mean: 0.0,
            integral: 0.0,
        }
    }

    /// A constant sky of radiance `radiance`.
    pub fn constant(radiance: Rgb) -> Environment {
        Environment {
            kind: EnvironmentKind::Constant,
            color: radiance,
            integral: 4.0 * PI * radiance.luminance(),
            ..Environment::none()
        }
    }

    /// A map view over `texels` and its distribution; both must outlive the environment.
    pub fn map(
        width: u32,
        height: u32,
        texels: &[Rgb],
        dist: &MapDistribution,
        strength: f32,
        rotation_degrees: f32,
    ) -> Environment {
        let r = rotation_degrees.to_radians();
        Environment {
            kind: EnvironmentKind::Map,
            color: Rgb::splat(strength),
            rot_cos: r.cos(),
            rot_sin: r.sin(),
            width,
            height,
            texels: texels.as_ptr(),
            marginal_cdf: dist.marginal_cdf.as_ptr(),
            conditional_cdf: dist.conditional_cdf.as_ptr(),
            func_mean: dist.func_mean,
            integral: dist.integral * strength,
        }
    }

    #[inline]
    pub fn is_present(&self) -> bool {
        self.kind != EnvironmentKind::None
    }

    /// Power estimate π r² ∫ L dω (module docs).
    pub fn power(&self, scene_radius: f32) -> f32 {
        if !self.is_present() {
            return 0.0;
        }
        PI * scene_radius * scene_radius * self.integral
    }

    /// World direction to map-local direction (inverse rotation about +Y).
    #[inline]
    fn world_to_map(&self, d: Vec3) -> Vec3 {
        Vec3::new(
            self.rot_cos * d.x - self.rot_sin * d.z,
            d.y,
            self.rot_sin * d.x + self.rot_cos * d.z,
        )
    }

    #[inline]
    fn map_to_world(&self, d: Vec3) -> Vec3 {
        Vec3::new(
            self.rot_cos * d.x + self.rot_sin * d.z,
            d.y,
            -self.rot_sin * d.x + self.rot_cos * d.z,
        )
    }

    /// Map coordinates (u, v) ∈ [0, 1)² of a local direction.
    #[inline]
    pub fn local_to_uv(d: Vec3) -> Vec2 {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let mut phi = d.z.atan2(d.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        Vec2::new(phi / (2.0 * PI), theta / PI)
    }

    /// The local direction of map coordinates (u, v).
    #[inline]
    pub fn uv_to_local(uv: Vec2) -> Vec3 {
        let theta = PI * uv.y;
        let phi = 2.0 * PI * uv.x;
        let s = theta.sin();
        Vec3::new(s * phi.cos(), theta.cos(), s * phi.sin())
    }

    #[inline]
    fn texel_index(&self, uv: Vec2) -> (usize, usize) {
        let (w, h) = (self.width as usize, self.height as usize);
        let x = ((uv.x * w as f32) as usize).min(w - 1);
        let y = ((uv.y * h as f32) as usize).min(h - 1);
        (x, y)
    }

    #[inline]
    fn texel(&self, x: usize, y: usize) -> Rgb {
        // SAFETY: x < width, y < height; the host keeps `width × height` texels alive.
        unsafe { *self.texels.add(y * self.width as usize + x) }
    }

    #[inline]
    fn map_ready(&self) -> bool {
        self.width > 0
            && self.height > 0
            && !self.texels.is_null()
            && !self.marginal_cdf.is_null()
            && !self.conditional_cdf.is_null()
    }

    /// Radiance arriving from world direction `dir` (unit, pointing away from the scene).
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        match self.kind {
            EnvironmentKind::None => Rgb::ZERO,
            EnvironmentKind::Constant => self.color,
            EnvironmentKind::Map => {
                if !self.map_ready() {
                    return Rgb::ZERO;
                }
                let (x, y) = self.texel_index(Self::local_to_uv(self.world_to_map(dir)));
                self.texel(x, y) * self.color
            }
        }
    }

    /// Solid-angle density with which [`Environment::sample`] picks world direction `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self.kind {
            EnvironmentKind::None => 0.0,
            EnvironmentKind::Constant => 1.0 / (4.0 * PI),
            EnvironmentKind::Map => {
                if !self.map_ready() || self.func_mean <= 0.0 {
                    return 0.0;
                }
                let uv = Self::local_to_uv(self.world_to_map(dir));
                let sin_theta = (PI * uv.y).sin();
                if sin_theta <= 0.0 {
                    return 0.0;
                }
                let (x, y) = self.texel_index(uv);
                let f = self.texel(x, y).luminance() * row_sin(y, self.height as usize);
                f / self.func_mean / (2.0 * PI * PI * sin_theta)
            }
        }
    }

    /// Samples a direction towards the environment.
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        match self.kind {
            EnvironmentKind::None => None,
            EnvironmentKind::Constant => Some(EnvironmentSample {
                dir: uniform_sphere(u),
                radiance: self.color,
                pdf: 1.0 / (4.0 * PI),
            }),
            EnvironmentKind::Map => {
                if !self.map_ready() {
                    return None;
                }
                let (w, h) = (self.width as usize, self.height as usize);
                // SAFETY: the host keeps `height` and `width × height` CDF entries alive.
                let marginal = unsafe { std::slice::from_raw_parts(self.marginal_cdf, h) };
                let (y, py) = sample_cdf(marginal, u.y);
                if py <= 0.0 {
                    return None;
                }
                let lo = if y == 0 { 0.0 } else { marginal[y - 1] };
                let dv = ((u.y - lo) / py).clamp(0.0, 0.999_999);
                // SAFETY: row y's CDF lies at y·w … y·w + w − 1.
                let row = unsafe { std::slice::from_raw_parts(self.conditional_cdf.add(y * w), w) };
                let (x, px) = sample_cdf(row, u.x);
                if px <= 0.0 {
                    return None;
                }
                let lo = if x == 0 { 0.0 } else { row[x - 1] };
                let du = ((u.x - lo) / px).clamp(0.0, 0.999_999);
                let uv = Vec2::new((x as f32 + du) / w as f32, (y as f32 + dv) / h as f32);
                let dir = self.map_to_world(Self::uv_to_local(uv));
                // Density and radiance of the texel drawn (a round trip through `dir` could
                // land in the neighbouring texel at an edge).
                let sin_theta = (PI * uv.y).sin();
                let texel = self.texel(x, y);
                let f = texel.luminance() * row_sin(y, h);
                let pdf = f / self.func_mean / (2.0 * PI * PI * sin_theta);
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                Some(EnvironmentSample {
                    dir,
                    radiance: texel * self.color,
                    pdf,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A 16×8 map: a bright spot, a dim gradient and one black row.
    fn test_map() -> (u32, u32, Vec<Rgb>) {
        let (w, h) = (16u32, 8u32);
        let mut t = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = if y == 5 {
                    0.0
                } else if (x, y) == (3, 2) {
                    40.0
                } else {
                    0.1 + 0.05 * x as f32
                };
                t.push(Rgb::new(v, 0.5 * v, 2.0 * v));
            }
        }
        (w, h, t)
    }

    #[test]
    fn directions_and_uv_round_trip() {
        for &(u, v) in &[(0.1f32, 0.3f32), (0.6, 0.7), (0.95, 0.05), (0.25, 0.5)] {
            let uv = Environment::local_to_uv(Environment::uv_to_local(Vec2::new(u, v)));
            assert!(
                (uv.x - u).abs() < 1e-4 && (uv.y - v).abs() < 1e-4,
                "{u},{v}: {uv}"
            );
        }
        // Documented orientation: u = 0 → +X, u = 1/4 → +Z, v = 0 → +Y.
        assert!(Environment::uv_to_local(Vec2::new(0.0, 0.5)).distance(Vec3::X) < 1e-5);
        assert!(Environment::uv_to_local(Vec2::new(0.25, 0.5)).distance(Vec3::Z) < 1e-5);
        assert!(Environment::uv_to_local(Vec2::new(0.3, 0.0)).distance(Vec3::Y) < 1e-5);
    }

    #[test]
    fn map_pdf_integrates_to_one_and_matches_the_sampled_histogram() {
        let (w, h, t) = test_map();
        let dist = build_map_distribution(w, h, &t).unwrap();
        let env = Environment::map(w, h, &t, &dist, 1.0, 30.0);
        // ∫ p dω over the sphere by a fine midpoint rule in (θ, φ).
        let (nt, np) = (400, 800);
        let mut total = 0.0f64;
        for i in 0..nt {
            let theta = PI * (i as f32 + 0.5) / nt as f32;
            for j in 0..np {
                let phi = 2.0 * PI * (j as f32 + 0.5) / np as f32;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                let dw = (PI / nt as f32) * (2.0 * PI / np as f32) * theta.sin();
                total += (env.pdf(d) * dw) as f64;
            }
        }
        assert!((total - 1.0).abs() < 2e-3, "∫p dω = {total}");

        // Histogram over texels (in map-local coordinates): sampled share vs ∫ p over the texel.
        let mut counts = vec![0u32; (w * h) as usize];
        let mut r = Rng::new(11, 3);
        let n = 400_000;
        for _ in 0..n {
            let s = env.sample(r.uniform2()).unwrap();
            let uv = Environment::local_to_uv(env.world_to_map(s.dir));
            let (x, y) = env.texel_index(uv);
            // Away from texel edges, sampling and evaluation agree.
            let frac = uv * Vec2::new(w as f32, h as f32);
            let inner = (frac - frac.floor()).min_element() > 1e-3
                && (frac.ceil() - frac).min_element() > 1e-3
                && (PI * uv.y).sin() > 0.05;
            if inner {
                assert!(
                    (s.pdf - env.pdf(s.dir)).abs() <= 1e-2 * s.pdf,
                    "{} {} {uv} {x} {y}",
                    s.pdf,
                    env.pdf(s.dir)
                );
                assert_eq!(s.radiance, env.radiance(s.dir));
            }
            counts[y * w as usize + x] += 1;
        }
        let f_sum: f32 = (0..h as usize)
            .flat_map(|y| (0..w as usize).map(move |x| (x, y)))
            .map(|(x, y)| t[y * w as usize + x].luminance() * row_sin(y, h as usize))
            .sum();
        for y in 0..h as usize {
            for x in 0..w as usize {
                let expected = t[y * w as usize + x].luminance() * row_sin(y, h as usize) / f_sum;
                let got = counts[y * w as usize + x] as f32 / n as f32;
                let sigma = (expected * (1.0 - expected) / n as f32).sqrt();
                assert!(
                    (got - expected).abs() <= 5.0 * sigma + 1e-6,
                    "texel ({x},{y}): {got} vs {expected}"
                );
            }
        }
        // The black row is never sampled.
        assert!((0..w as usize).all(|x| counts[5 * w as usize + x] == 0));
    }

    #[test]
    fn black_map_is_no_light_and_constant_integrates() {
        let t = vec![Rgb::ZERO; 8];
        assert!(build_map_distribution(4, 2, &t).is_none());
        let c = Environment::constant(Rgb::splat(2.0));
        assert!((c.integral - 8.0 * PI).abs() < 1e-4);
        assert_eq!(c.radiance(Vec3::X), Rgb::splat(2.0));
        // A uniform map has ∫ L dω = 4π L up to the row discretisation of sin θ.
        let t = vec![Rgb::splat(1.0); 64 * 32];
        let d = build_map_distribution(64, 32, &t).unwrap();
        assert!(
            (d.integral / (4.0 * PI) - 1.0).abs() < 2e-3,
            "{}",
            d.integral
        );
    }
}
