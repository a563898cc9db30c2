//! Beer–Lambert absorption inside volumetric glTF materials (`KHR_materials_volume`).
//!
//! A material with thickness > 0 bounds a closed mesh whose inside is a homogeneous absorbing
//! medium. The extension gives the colour c that white light has after a distance d
//! (`attenuationColor`, `attenuationDistance`); the absorption coefficient per channel is
//!
//!   σ_a = −ln(c) / d,   so a segment of length s inside transmits T(s) = exp(−σ_a s) = c^(s/d)
//!
//! (KHR_materials_volume, "Attenuation"; pbrt-v4 §11.2). There is no scattering inside.
//!
//! **Which segments are inside.** The mesh's geometric normals are oriented by winding
//! (counter-clockwise = front = outside, as glTF requires for closed volumes). A path segment
//! that leaves a surface point of a volumetric material through its *back* face (direction d
//! with n_g·d < 0: refracted inwards, or reflected internally) runs inside that material's
//! volume until the next hit. Nested volumes and objects immersed in a volume are not
//! tracked: a segment that leaves a non-volumetric surface is never attenuated.

use crate::material::Material;
use crate::Rgb;
use glam::Vec3;

/// Absorption coefficient σ_a per channel (per world unit) of `m`'s volume; `None` when `m`
/// is thin-walled or does not absorb.
#[inline]
pub fn absorption(m: &Material) -> Option<Rgb> {
    let d = m.attenuation_distance;
    let positive = |x: f32| x > 0.0; // false for NaN too
    if !positive(m.thickness) || !positive(d) || d.is_infinite() {
        return None;
    }
    let sigma = |c: f32| {
        if c >= 1.0 || c.is_nan() {
            0.0
        } else if c <= 0.0 {
            f32::INFINITY
        } else {
            -c.ln() / d
        }
    };
    let c = m.attenuation_color;
    let s = Rgb::new(sigma(c.r), sigma(c.g), sigma(c.b));
    (!s.is_black()).then_some(s)
}

/// exp(−σ s) per channel.
#[inline]
pub fn transmittance(sigma: Rgb, distance: f32) -> Rgb {
    let t = |s: f32| {
        if s == 0.0 {
            1.0
        } else {
            (-s * distance.max(0.0)).exp()
        }
    };
    Rgb::new(t(sigma.r), t(sigma.g), t(sigma.b))
}

/// Transmittance of the segment that leaves a surface of material `m` (geometric normal `ng`,
/// winding-oriented) in world direction `dir` and travels `distance` to the next vertex: the
/// Beer–Lambert factor when the segment runs inside `m`'s volume, else 1.
#[inline]
pub fn segment_transmittance(m: &Material, ng: Vec3, dir: Vec3, distance: f32) -> Rgb {
    if ng.dot(dir) >= 0.0 {
        return Rgb::ONE;
    }
    match absorption(m) {
        Some(sigma) => transmittance(sigma, distance),
        None => Rgb::ONE,
    }
}

/// Absorption coefficient of the volume that a ray leaving a surface of material `m`
/// (winding-oriented geometric normal `ng`) in world direction `dir` runs through: `Some(σ_a)`
/// when it goes into an absorbing volume. Path tracers keep it with the ray and apply
/// [`transmittance`] with the hit distance.
#[inline]
pub fn entered(m: &Material, ng: Vec3, dir: Vec3) -> Option<Rgb> {
    if ng.dot(dir) >= 0.0 {
        return None;
    }
    absorption(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn water() -> Material {
        Material {
            transmission: 1.0,
            thickness: 1.0,
            attenuation_color: Rgb::new(0.5, 0.8, 1.0),
            attenuation_distance: 2.0,
            ..Default::default()
        }
    }

    #[test]
    fn attenuation_colour_is_reached_at_the_attenuation_distance() {
        let m = water();
        let t = segment_transmittance(&m, Vec3::Z, -Vec3::Z, 2.0);
        assert!((t.r - 0.5).abs() < 1e-6 && (t.g - 0.8).abs() < 1e-6 && t.b == 1.0);
        // Beer–Lambert: twice the distance squares the transmittance.
        let t4 = segment_transmittance(&m, Vec3::Z, -Vec3::Z, 4.0);
        assert!((t4.r - 0.25).abs() < 1e-6 && (t4.g - 0.64).abs() < 1e-6);
        // σ = −ln(c)/d.
        let s = absorption(&m).unwrap();
        assert!((s.r - std::f32::consts::LN_2 / 2.0).abs() < 1e-6);
    }

    #[test]
    fn only_segments_inside_a_volume_are_attenuated() {
        let m = water();
        // Leaving through the front face: outside.
        assert_eq!(segment_transmittance(&m, Vec3::Z, Vec3::Z, 5.0), Rgb::ONE);
        assert!(entered(&m, Vec3::Z, Vec3::Z).is_none());
        let sigma = entered(&m, Vec3::Z, -Vec3::Z).unwrap();
        assert_eq!(
            transmittance(sigma, 2.0),
            segment_transmittance(&m, Vec3::Z, -Vec3::Z, 2.0)
        );
        // Thin-walled or no distance: no absorption.
        let thin = Material {
            thickness: 0.0,
            ..water()
        };
        assert_eq!(
            segment_transmittance(&thin, Vec3::Z, -Vec3::Z, 5.0),
            Rgb::ONE
        );
        let clear = Material {
            attenuation_distance: f32::INFINITY,
            ..water()
        };
        assert!(absorption(&clear).is_none());
        assert!(absorption(&Material::default()).is_none());
    }
}
