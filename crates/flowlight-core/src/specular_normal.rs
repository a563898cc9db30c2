//! Bending a normal-mapped shading normal back towards the geometric normal so that the
//! mirror reflection of the viewer stays above the surface (the equivalent of Cycles'
//! `ensure_valid_specular_reflection`).
//!
//! A normal map tilts the shading normal n_s by up to 90° from the geometric normal n_g. Where
//! the viewer direction ω_o lies on the far side of the tilt, the mirror reflection
//! R = 2 (n_s·ω_o) n_s − ω_o falls *below* the geometric surface: the samplers reject it (a
//! direction on different sides of n_s and n_g would leak light through the surface), and
//! a glossy or mirror metal loses the energy of every such pixel. On a normal-mapped dome
//! (NormalTangentTest's gold cells) that is a dark ring around the dome's edge, 16–17%
//! darker than the same dome modelled as geometry.
//!
//! The fix keeps the shading normal in the plane of n_s and n_g and turns it towards n_g by
//! the least angle that lifts the reflection to a height t above the surface,
//! t = min(0.9 (ω_o·n_g), 0.01) (the reflection may always be as shallow as the incoming
//! direction itself). With z = n_g, x the unit part of n_s orthogonal to n_g, n = sin φ x +
//! cos φ z and ω_o = (I_x, I_y, I_z):
//!
//!   R·z = 2 (n·ω_o) cos φ − I_z = I_x sin 2φ + I_z cos 2φ = r cos(2φ − ψ),
//!
//! with r = √(I_x² + I_z²) and ψ = atan2(I_x, I_z). The tilts that keep R·z ≥ t form the
//! interval 2φ ∈ [ψ − acos(t/r), ψ + acos(t/r)], which holds φ = 0 (n = n_g reflects ω_o at
//! height I_z ≥ t); a tilt beyond it is brought back to its upper end,
//!
//!   φ' = (ψ + acos(t/r)) / 2,   0 < φ' < φ,
//!
//! (φ' > 0 because t ≤ 0.9 I_z = 0.9 r cos ψ gives acos(t/r) > |ψ|). A normal whose
//! reflection is high enough is returned unchanged.
//!
//! Cycles bends only its glossy closures' normals and keeps the diffuse ones; Flowlight's
//! BSDF has one shading frame for all its lobes (as for the clearcoat, see
//! [`crate::material`]), so a bent normal is the frame of every lobe of the hit. That is
//! Cycles' behaviour exactly for a metal, which has no diffuse lobe, but not for a dielectric:
//! bending a normal-mapped diffuse surface's frame changes its shading wherever the bend is
//! active (a grazing view flattens every ridge tilted away from the viewer), and on the
//! normal-mapped ground of `scenes/blender-showcase/lit.glb` that doubled the image's mean
//! luminance. So the bend is applied where the metal dominates the hit: resolved metallic
//! (factor × texture B) ≥ [`BEND_METALLIC`]. A dielectric keeps its mapped normal and loses
//! the few reflections of its specular layer (F0 ≈ 0.04) that fall below the surface, as it
//! did before. Only normal-mapped hits are considered ([`crate::mesh`]): interpolated vertex
//! normals tilt by little, and scenes without normal maps render as before, bit for bit.

use glam::Vec3;

/// The resolved metallic value from which a normal-mapped hit's normal is bent (module docs).
pub const BEND_METALLIC: f32 = 0.5;

/// Whether a normal-mapped hit of resolved metallic `metallic` gets the bent normal.
#[inline]
pub fn bends_for_metallic(metallic: f32) -> bool {
    metallic >= BEND_METALLIC
}

/// Height above the surface, as a cosine with n_g, that the reflection of `wo` about the
/// bent normal reaches: min(0.9 (ω_o·n_g), 0.01).
#[inline]
pub fn reflection_height(wo_z: f32) -> f32 {
    (0.9 * wo_z).min(0.01)
}

/// `ns` turned towards `ng` in their plane just enough that the mirror reflection of `wo`
/// about it lies at least [`reflection_height`] above the surface (module docs); `ns` itself
/// when it already does. All three are unit vectors; `wo` on either side (the normals are
/// taken to `wo`'s side for the computation and back). Never NaN: degenerate input returns
/// `ns`.
pub fn valid_specular_normal(ng: Vec3, wo: Vec3, ns: Vec3) -> Vec3 {
    let side = if wo.dot(ng) < 0.0 { -1.0 } else { 1.0 };
    let (z, n) = (ng * side, ns * side);
    let iz = wo.dot(z);
    if iz.is_nan() || iz <= 0.0 {
        return ns;
    }
    let t = reflection_height(iz);
    let nw = n.dot(wo);
    let reflected_z = 2.0 * nw * n.dot(z) - iz;
    if reflected_z >= t {
        return ns;
    }
    let Some(x) = (n - z * n.dot(z)).try_normalize() else {
        return ns;
    };
    let ix = wo.dot(x);
    let r = (ix * ix + iz * iz).sqrt();
    let psi = ix.atan2(iz);
    let phi = 0.5 * (psi + (t / r).clamp(-1.0, 1.0).acos());
    let (s, c) = phi.sin_cos();
    match (x * s + z * c).try_normalize() {
        Some(bent) => bent * side,
        None => ns,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
        n * (2.0 * n.dot(wo)) - wo
    }

    fn unit(rng: &mut Rng) -> Vec3 {
        loop {
            let v = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - Vec3::ONE;
            if v.length_squared() > 1e-3 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }

    #[test]
    fn the_reflection_about_the_bent_normal_stays_above_the_surface() {
        let mut rng = Rng::new(7, 1);
        let mut bent_count = 0;
        for _ in 0..20000 {
            let ng = unit(&mut rng);
            let mut ns = unit(&mut rng);
            if ns.dot(ng) < 0.05 {
                ns = (ns + ng * (0.05 - ns.dot(ng))).normalize();
            }
            let wo = unit(&mut rng);
            if wo.dot(ng).abs() < 1e-3 {
                continue;
            }
            let side = wo.dot(ng).signum();
            let b = valid_specular_normal(ng, wo, ns);
            assert!((b.length() - 1.0).abs() < 1e-4, "{b}");
            let h = reflect(wo, b).dot(ng * side);
            let t = reflection_height(wo.dot(ng * side));
            let before = reflect(wo, ns).dot(ng * side);
            if before >= t {
                assert_eq!(b, ns, "a valid normal is left alone");
                continue;
            }
            bent_count += 1;
            // The reflection lands at the height t (the least bend), above the surface.
            assert!((h - t).abs() < 2e-3, "height {h} vs {t}");
            assert!(h > 0.0);
            // In the plane of n_s and n_g, between them, on n_s's side of n_g.
            let plane = ns.cross(ng);
            if plane.length() > 1e-3 {
                assert!(b.dot(plane.normalize()).abs() < 1e-3);
            }
            assert!(b.dot(ng) >= ns.dot(ng) - 1e-4, "turned towards n_g");
            // The viewer stays on the same side of the bent normal as of n_g.
            assert!(b.dot(wo) * side > 0.0);
        }
        assert!(bent_count > 1000, "{bent_count}");
    }

    /// The samplers' side test (ω_i on the same side of n_g as of the shading frame's z)
    /// passes for every mirror and near-mirror sample of a gold glTF metal whose frame is the
    /// bent normal, where about the unbent tilted normal it fails for the samples that fell
    /// below the surface; and the BSDF's sample, density and value stay consistent in the
    /// bent frame (it is the BSDF's own frame).
    #[test]
    fn gold_samples_in_the_bent_frame_pass_the_side_test() {
        use crate::bsdf::Bsdf;
        use crate::geometry::Frame;
        use crate::material::Material;
        use crate::Rgb;
        let mut rng = Rng::new(11, 2);
        for roughness in [0.0f32, 0.1] {
            let m = Material {
                base_color: Rgb::new(1.0, 0.766, 0.336),
                metallic: 1.0,
                roughness,
                ..Material::default()
            };
            let bsdf = Bsdf::from_material(&m, m.base_color);
            let (mut rejected_before, mut rejected_after, mut tried) = (0, 0, 0);
            while tried < 2000 {
                let ng = Vec3::Z;
                // A steep tilt (50°–85°) and a view from the far side of it.
                let tilt = (50.0 + 35.0 * rng.uniform()).to_radians();
                let az = std::f32::consts::TAU * rng.uniform();
                let ns = Vec3::new(tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
                let view = (10.0 + 70.0 * rng.uniform()).to_radians();
                let wo = Vec3::new(-view.sin() * az.cos(), -view.sin() * az.sin(), view.cos());
                if ns.dot(wo) <= 0.0 {
                    continue;
                }
                tried += 1;
                let u = glam::Vec2::new(rng.uniform(), rng.uniform());
                for (n, rejected) in [
                    (ns, &mut rejected_before),
                    (valid_specular_normal(ng, wo, ns), &mut rejected_after),
                ] {
                    let frame = Frame::from_z(n);
                    let wo_l = frame.to_local(wo);
                    let Some(s) = bsdf.sample(wo_l, 0.5, u) else {
                        *rejected += 1;
                        continue;
                    };
                    let wi = frame.to_world(s.wi);
                    if wi.dot(ng) * s.wi.z <= 0.0 {
                        *rejected += 1;
                    } else if !s.delta {
                        let (f, pdf) = bsdf.eval_pdf(wo_l, s.wi);
                        assert!(
                            (pdf - s.pdf).abs() <= 1e-3 * pdf.max(1.0),
                            "{pdf} {}",
                            s.pdf
                        );
                        assert!(
                            (f.r - s.f.r).abs() <= 1e-3 * f.r.max(1e-3),
                            "{f:?} {:?}",
                            s.f
                        );
                    }
                }
            }
            // About the tilted normal most reflections fall below the surface.
            assert!(
                rejected_before * 2 > tried,
                "r {roughness}: {rejected_before}"
            );
            if roughness == 0.0 {
                // The mirror's reflection about the bent normal never does.
                assert_eq!(rejected_after, 0);
            } else {
                // A rough lobe centred just above the horizon loses the part of it below,
                // as it would about real geometry there (and as Cycles' does).
                assert!(
                    rejected_after * 3 < rejected_before * 2,
                    "{rejected_after} vs {rejected_before}"
                );
            }
        }
    }

    #[test]
    fn a_dome_seen_from_above_reflects_to_the_horizon_instead_of_below() {
        // A normal tilted 60° from n_g seen straight down n_g: the mirror direction would be
        // 120° from n_g, below the surface; bent, it grazes the horizon at height t.
        let ng = Vec3::Z;
        let ns = Vec3::new(60f32.to_radians().sin(), 0.0, 60f32.to_radians().cos());
        let wo = Vec3::Z;
        assert!(reflect(wo, ns).z < 0.0);
        let b = valid_specular_normal(ng, wo, ns);
        assert!((reflect(wo, b).z - 0.01).abs() < 1e-4, "{b}");
        // Just under 45°: the least bend from 60°.
        let tilt = b.z.acos().to_degrees();
        assert!(tilt > 44.0 && tilt < 45.0, "{tilt}");
        // From the back side the same, mirrored.
        let bb = valid_specular_normal(ng, -wo, ns);
        assert!((reflect(-wo, bb).z + 0.01).abs() < 1e-4, "{bb}");
    }
}
