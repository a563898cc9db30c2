//! RGB spectrum with the thesis' split into total energy and fractional distribution (§3.4).

use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign};

/// Linear RGB radiance or reflectance (Rec.709 primaries).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rgb {
    pub r: f32,
    pub g: f32,
    pub b: f32,
}

impl Rgb {
    pub const ZERO: Rgb = Rgb::splat(0.0);
    pub const ONE: Rgb = Rgb::splat(1.0);

    #[inline]
    pub const fn new(r: f32, g: f32, b: f32) -> Self {
        Rgb { r, g, b }
    }
    #[inline]
    pub const fn splat(v: f32) -> Self {
        Rgb { r: v, g: v, b: v }
    }
    /// Rec.709 luminance (Y of CIE XYZ).
    #[inline]
    pub fn luminance(self) -> f32 {
        0.2126 * self.r + 0.7152 * self.g + 0.0722 * self.b
    }
    /// Total energy e_t = sum over the discrete spectrum (thesis §3.4).
    #[inline]
    pub fn total_energy(self) -> f32 {
        self.r + self.g + self.b
    }
    /// Fractional energy distribution ρ with Σρ = 1 and ρ·e_t = self (thesis §3.4).
    /// Returns `None` for a spectrum with no energy.
    #[inline]
    pub fn fractional_distribution(self) -> Option<Rgb> {
        let e = self.total_energy();
        (e > 0.0 && e.is_finite()).then(|| self / e)
    }
    #[inline]
    pub fn max_component(self) -> f32 {
        self.r.max(self.g).max(self.b)
    }
    #[inline]
    pub fn is_black(self) -> bool {
        self.r == 0.0 && self.g == 0.0 && self.b == 0.0
    }
    /// True when every channel is finite (no NaN, no infinity).
    #[inline]
    pub fn is_finite(self) -> bool {
        self.r.is_finite() && self.g.is_finite() && self.b.is_finite()
    }
    /// True when every channel is finite and non-negative: a valid radiance sample.
    #[inline]
    pub fn is_valid_radiance(self) -> bool {
        self.is_finite() && self.r >= 0.0 && self.g >= 0.0 && self.b >= 0.0
    }
    #[inline]
    pub fn to_array(self) -> [f32; 3] {
        [self.r, self.g, self.b]
    }
    #[inline]
    pub fn from_array(a: [f32; 3]) -> Self {
        Rgb::new(a[0], a[1], a[2])
    }
}

impl Add for Rgb {
    type Output = Rgb;
    #[inline]
    fn add(self, o: Rgb) -> Rgb {
        Rgb::new(self.r + o.r, self.g + o.g, self.b + o.b)
    }
}
impl AddAssign for Rgb {
    #[inline]
    fn add_assign(&mut self, o: Rgb) {
        *self = *self + o;
    }
}
impl Mul for Rgb {
    type Output = Rgb;
    #[inline]
    fn mul(self, o: Rgb) -> Rgb {
        Rgb::new(self.r * o.r, self.g * o.g, self.b * o.b)
    }
}
impl MulAssign for Rgb {
    #[inline]
    fn mul_assign(&mut self, o: Rgb) {
        *self = *self * o;
    }
}
impl Mul<f32> for Rgb {
    type Output = Rgb;
    #[inline]
    fn mul(self, s: f32) -> Rgb {
        Rgb::new(self.r * s, self.g * s, self.b * s)
    }
}
impl MulAssign<f32> for Rgb {
    #[inline]
    fn mul_assign(&mut self, s: f32) {
        *self = *self * s;
    }
}
impl DivAssign<f32> for Rgb {
    #[inline]
    fn div_assign(&mut self, s: f32) {
        *self = *self / s;
    }
}
impl Div<f32> for Rgb {
    type Output = Rgb;
    #[inline]
    fn div(self, s: f32) -> Rgb {
        self * (1.0 / s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractional_distribution_recombines() {
        let c = Rgb::new(0.2, 3.0, 0.7);
        let rho = c.fractional_distribution().unwrap();
        assert!((rho.total_energy() - 1.0).abs() < 1e-6);
        let back = rho * c.total_energy();
        assert!((back.g - 3.0).abs() < 1e-5);
        assert!(Rgb::ZERO.fractional_distribution().is_none());
    }

    #[test]
    fn luminance_of_white_is_one() {
        assert!((Rgb::ONE.luminance() - 1.0).abs() < 1e-6);
        assert!(!Rgb::new(f32::NAN, 0.0, 0.0).is_valid_radiance());
        assert!(!Rgb::new(-1.0, 0.0, 0.0).is_valid_radiance());
    }
}
