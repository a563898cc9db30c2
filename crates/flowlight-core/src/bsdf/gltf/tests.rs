//! Tests of the glTF lobes against the formulas of the module documentation.

use super::super::testutil::*;
use super::super::{Bsdf, Component};
use super::*;
use crate::material::Material;
use crate::rng::Rng;
use std::f64::consts::PI;

/// Each lobe alone (scale 1), as a component.
fn lobe_components(p: &GltfParams) -> Vec<(GltfLobeKind, Component)> {
    let (ls, n) = lobes(p);
    ls[..n]
        .iter()
        .map(|&(mut l, _)| {
            l.scale = 1.0;
            (l.kind, Component::Gltf(l))
        })
        .collect()
}

// ---- independent reference formulas (written from the spec, not from the code) ----

/// D_GGX = α² / (π ((n·h)² (α² − 1) + 1)²).
fn d_ref(alpha: f64, nh: f64) -> f64 {
    if nh <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let k = nh * nh * (a2 - 1.0) + 1.0;
    a2 / (PI * k * k)
}

/// Height-correlated V = 0.5 / (NL √(NV²(1 − α²) + α²) + NV √(NL²(1 − α²) + α²)).
fn v_ref(alpha: f64, nl: f64, nv: f64) -> f64 {
    let a2 = alpha * alpha;
    let gv = nl * (nv * nv * (1.0 - a2) + a2).sqrt();
    let gl = nv * (nl * nl * (1.0 - a2) + a2).sqrt();
    0.5 / (gv + gl)
}

/// The spec's specular_brdf × Schlick(f0, f90), upper hemisphere.
fn spec_ref(alpha: f64, f0: f64, f90: f64, wo: [f64; 3], wi: [f64; 3]) -> f64 {
    if wo[2] <= 0.0 || wi[2] <= 0.0 {
        return 0.0;
    }
    let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
    let l = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    let h = [h[0] / l, h[1] / l, h[2] / l];
    let vh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
    let f = f0 + (f90 - f0) * (1.0 - vh.abs()).powi(5);
    f * d_ref(alpha, h[2]) * v_ref(alpha, wi[2], wo[2])
}

/// ∫ g(ω_i) μ_i dω_i over the upper hemisphere, midpoint rule in (μ_i, φ).
fn hemi(n: usize, g: impl Fn([f64; 3]) -> f64) -> f64 {
    let mut s = 0.0;
    for i in 0..n {
        let mu = (i as f64 + 0.5) / n as f64;
        let st = (1.0 - mu * mu).sqrt();
        for j in 0..2 * n {
            let phi = PI * (j as f64 + 0.5) / n as f64;
            s += g([st * phi.cos(), st * phi.sin(), mu]) * mu;
        }
    }
    s * (1.0 / n as f64) * (PI / n as f64)
}

fn wo_at(theta: f64) -> [f64; 3] {
    [theta.sin(), 0.0, theta.cos()]
}

fn v3(w: [f64; 3]) -> Vec3 {
    Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32)
}

#[test]
fn specular_lobe_is_the_spec_formula() {
    let mut r = Rng::new(60, 0);
    for (m, ior, rough) in [
        (0.0f32, 1.5f32, 0.5f32),
        (0.0, 2.2, 0.2),
        (1.0, 1.5, 0.7),
        (0.4, 1.3, 0.35),
    ] {
        let base = Rgb::new(0.9, 0.5, 0.2);
        let p = GltfParams {
            base,
            metallic: m,
            roughness: rough,
            ior,
            ..gltf_params()
        };
        let spec = lobe_components(&p)
            .into_iter()
            .find(|(k, _)| *k == GltfLobeKind::Specular)
            .unwrap()
            .1;
        let alpha = (rough * rough) as f64;
        let f0d = ((ior as f64 - 1.0) / (ior as f64 + 1.0)).powi(2);
        for _ in 0..500 {
            let mut a = crate::sampling::uniform_sphere(r.uniform2());
            let mut b = crate::sampling::uniform_sphere(r.uniform2());
            a.z = a.z.abs();
            b.z = b.z.abs();
            let wo = [a.x as f64, a.y as f64, a.z as f64];
            let wi = [b.x as f64, b.y as f64, b.z as f64];
            let got = spec.eval(a, b).to_array();
            for (k, ch) in base.to_array().into_iter().enumerate() {
                let metal = spec_ref(alpha, ch as f64, 1.0, wo, wi);
                let diel = spec_ref(alpha, f0d, 1.0, wo, wi);
                let want = (1.0 - m as f64) * diel + m as f64 * metal;
                assert!(
                    (got[k] as f64 - want).abs() <= 2e-3 * want + 1e-5,
                    "m {m} ior {ior}: {} vs {want}",
                    got[k]
                );
            }
        }
    }
}

/// The failing case of the old mixture: a rough-0.1 dielectric has a highlight.
#[test]
fn dielectric_has_a_specular_highlight() {
    let base = Rgb::splat(0.5);
    let m = Material {
        base_color: base,
        metallic: 0.0,
        roughness: 0.1,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, base);
    let wo = v3(wo_at(0.5));
    let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
    let f = b.eval(wo, mirror).g;
    let diffuse = 0.5 / std::f32::consts::PI;
    assert!(
        f > 20.0 * diffuse,
        "f at the mirror direction {f} vs ρ/π {diffuse}"
    );
    // And away from it the material is (nearly) diffuse.
    let off = v3(wo_at(-1.0));
    let g = b.eval(wo, off).g;
    assert!((g - diffuse).abs() < 0.1 * diffuse, "{g} vs {diffuse}");
}

/// The literal spec `fresnel_mix` (diffuse weighted by 1 − F(V·H)) reflects more than it
/// receives at grazing view: why the diffuse base is energy-coupled instead.
#[test]
fn spec_fresnel_mix_gains_energy_at_grazing() {
    let alpha = 0.09f64;
    let wo = wo_at(80f64.to_radians());
    let e = hemi(400, |wi| {
        let h = [wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]];
        let l = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let vh = (wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]) / l;
        let f = 0.04 + 0.96 * (1.0 - vh).powi(5);
        (1.0 - f) / PI + spec_ref(alpha, 0.04, 1.0, wo, wi)
    });
    assert!(e > 1.1, "spec fresnel_mix albedo {e}");
    let b = Bsdf::from_material(
        &Material {
            base_color: Rgb::ONE,
            roughness: 0.3,
            ..Default::default()
        },
        Rgb::ONE,
    );
    let (_, ours) = sphere_integrals(&b, v3(wo), 400, 61);
    assert!(ours[0] < 1.01, "coupled albedo {}", ours[0]);
}

/// ∫ spec_ref μ_i dω_i by a midpoint grid over the microfacet normal, mapped so that
/// D cos θ_h dω_h is uniform (tan²θ_h = α² u / (1 − u)); exact for narrow lobes too.
fn spec_albedo_ref(alpha: f64, f0: f64, f90: f64, wo: [f64; 3]) -> f64 {
    let n = 400;
    let a2 = alpha * alpha;
    let mut s = 0.0;
    for i in 0..n {
        let u = (i as f64 + 0.5) / n as f64;
        let ch = 1.0 / (1.0 + a2 * u / (1.0 - u)).sqrt();
        let sh = (1.0 - ch * ch).max(0.0).sqrt();
        for j in 0..n {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
            let h = [sh * phi.cos(), sh * phi.sin(), ch];
            let vh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
            if vh <= 0.0 {
                continue;
            }
            let wi = [
                2.0 * vh * h[0] - wo[0],
                2.0 * vh * h[1] - wo[1],
                2.0 * vh * h[2] - wo[2],
            ];
            if wi[2] <= 0.0 {
                continue;
            }
            let f = f0 + (f90 - f0) * (1.0 - vh).powi(5);
            // f D V μ_i dω_i with dω_i = 4 (ω_o·h) dω_h, divided by the grid's D cos θ_h.
            s += f * v_ref(alpha, wi[2], wo[2]) * wi[2] * 4.0 * vh / ch;
        }
    }
    s / (n * n) as f64
}

/// Independent quadrature of the documented model: a white dielectric reflects its
/// specular lobe (the spec's, integrated here) and the coupled base returns the rest, so
/// its albedo is 1 at every angle, roughness and ior; never more.
#[test]
fn white_dielectric_albedo_matches_quadrature_and_never_exceeds_one() {
    for rough in [0.0f32, 0.1, 0.3, 0.6, 1.0] {
        for ior in [1.0f32, 1.5, 2.5] {
            let p = GltfParams {
                roughness: rough,
                ior,
                ..gltf_params()
            };
            let (ls, n) = lobes(&p);
            let b = Bsdf::from_gltf_lobes(&ls[..n]);
            let spec_lobe = lobe_components(&p)
                .into_iter()
                .find(|(k, _)| *k == GltfLobeKind::Specular)
                .unwrap()
                .1;
            let alpha = (rough as f64).powi(2);
            let f0 = ((ior as f64 - 1.0) / (ior as f64 + 1.0)).powi(2);
            for theta in [0.1f64, 0.7, 1.2, 1.45] {
                let wo = wo_at(theta);
                let spec = if rough == 0.0 {
                    f0 + (1.0 - f0) * (1.0 - wo[2]).powi(5)
                } else {
                    spec_albedo_ref(alpha, f0, 1.0, wo)
                };
                let ctx = format!("r {rough} ior {ior} θ {theta}");
                // The specular lobe alone integrates to the spec's lobe.
                let (s_is, s_se) = sampled_albedo(&spec_lobe, v3(wo), 100_000, 63);
                assert!(
                    (s_is[0] - spec).abs() < 0.005 + 4.0 * s_se[0],
                    "{ctx}: specular {} vs {spec}",
                    s_is[0]
                );
                // The whole material: white, so everything comes back.
                let (is, se) = sampled_albedo(&b, v3(wo), 100_000, 64);
                assert!(
                    is[0] <= 1.0 + 0.01 + 4.0 * se[0],
                    "{ctx}: sampled {}",
                    is[0]
                );
                assert!(
                    (is[0] - 1.0).abs() < 0.015 + 4.0 * se[0],
                    "{ctx}: sampled {}",
                    is[0]
                );
                if rough == 0.0 || rough >= 0.3 {
                    // Stratified quadrature of eval (the Dirac layer is added analytically).
                    let (_, num) = sphere_integrals(&b, v3(wo), 500, 62);
                    let quad = if rough == 0.0 { num[0] + spec } else { num[0] };
                    assert!(quad <= 1.0 + 0.01, "{ctx}: quadrature {quad}");
                    assert!((quad - 1.0).abs() < 0.015, "{ctx}: quadrature {quad}");
                }
            }
        }
    }
}

/// A white metal reflects E₁(μ_o), the single-scattering GGX albedo (computed here by
/// quadrature): 0.999, 0.912 and 0.316 at roughness 0.2, 0.5, 1 and θ_o = 0.3.
#[test]
fn white_metal_loses_only_the_single_scattering_energy() {
    for (rough, known) in [(0.2f32, 0.9988), (0.5, 0.9122), (1.0, 0.3157)] {
        let p = GltfParams {
            metallic: 1.0,
            roughness: rough,
            ..gltf_params()
        };
        let (ls, n) = lobes(&p);
        assert_eq!(n, 1);
        let b = Bsdf::from_gltf_lobes(&ls[..n]);
        let wo = wo_at(0.3);
        let e1 = spec_albedo_ref((rough as f64).powi(2), 1.0, 1.0, wo);
        assert!((e1 - known).abs() < 0.003, "r {rough}: E1 {e1}");
        let (is, se) = sampled_albedo(&b, v3(wo), 100_000, 65);
        assert!(
            (is[0] - e1).abs() < 0.005 + 4.0 * se[0],
            "r {rough}: {} vs {e1}",
            is[0]
        );
        let (_, num) = sphere_integrals(&b, v3(wo), 500, 66);
        assert!((num[0] - e1).abs() < 0.01, "r {rough}: {} vs {e1}", num[0]);
    }
}

fn variants() -> Vec<GltfParams> {
    let b = Rgb::new(0.9, 0.6, 0.3);
    vec![
        GltfParams {
            base: b,
            roughness: 0.4,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            metallic: 0.5,
            roughness: 0.25,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.5,
            clearcoat: 1.0,
            clearcoat_roughness: 0.3,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.45,
            transmission: 0.7,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.45,
            transmission: 0.7,
            volumetric: true,
            ior: 1.33,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.6,
            specular: 0.7,
            specular_color: Rgb::new(2.0, 1.0, 0.5),
            ior: 1.8,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.5,
            oren_nayar_sigma: 0.5,
            ..gltf_params()
        },
    ]
}

#[test]
fn every_lobe_samples_its_eval_and_pdf() {
    for p in variants() {
        for (kind, c) in lobe_components(&p) {
            for wo in test_directions_both_sides() {
                let ok = check_sample_consistency(&c, wo, 2000, 66);
                assert!(ok > 500, "{kind:?}: only {ok} samples");
            }
        }
    }
}

#[test]
fn every_lobe_pdf_and_energy() {
    for p in variants() {
        for (kind, c) in lobe_components(&p) {
            let c = match c {
                Component::Gltf(mut l) => {
                    l.dielectric.mode = super::super::TransportMode::Importance;
                    Component::Gltf(l)
                }
                c => c,
            };
            // Narrow lobes need a finer grid (refraction at η = 1.33 compresses the lobe).
            let narrow = kind == GltfLobeKind::Refraction
                || matches!(c, Component::Gltf(l) if l.class_alpha().is_some_and(|a| a < 0.1));
            let n = if narrow { 1000 } else { 400 };
            for wo in [dir(0.3, 0.2), flip_dir(dir(0.8, 1.0)), dir(1.35, 2.0)] {
                let pi = check_pdf_integral(&c, wo, n, 60_000, 67);
                assert!(pi > 0.5, "{kind:?}: ∫pdf {pi}");
                check_energy(&c, wo, n, 60_000, 68, 0.02);
            }
        }
    }
}

/// The diffuse coupling without a dielectric layer (no lookups) is what the lookups give,
/// bit for bit, at any α (NaN included, where the lookups run) and any cosines (NaN, ±0,
/// beyond ±1); with a layer it is the lookups' formula.
#[test]
fn diffuse_coupling_equals_the_lookups() {
    let by_lookup = |sh: &GltfShared, a: f32, b: f32| {
        (1.0 - sh.dielectric_albedo(a)).max(0.0)
            * (1.0 - sh.dielectric_albedo(b)).max(0.0)
            * sh.diffuse_norm
    };
    let mut r = Rng::new(75, 0);
    let mut mus = vec![0.0f32, -0.0, 1.0, -1.0, 1.5, f32::NAN, f32::INFINITY, 1e-30];
    mus.extend((0..100).map(|_| 2.0 * r.uniform() - 1.0));
    for (f0, f90) in [(0.0f32, 0.0f32), (0.04, 1.0), (0.0, 0.5)] {
        for alpha in [0.0f32, 0.3, 1.0, 2.0, f32::INFINITY, f32::NAN] {
            let sh = GltfShared {
                coat: 0.0,
                coat_alpha: 0.0,
                alpha,
                diel_f0: f0,
                diel_f90: f90,
                diffuse_norm: 1.25,
            };
            for (k, &a) in mus.iter().enumerate() {
                let b = mus[(k * 5 + 1) % mus.len()];
                let (got, want) = (sh.diffuse_coupling(a, b), by_lookup(&sh, a, b));
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "f0 {f0} f90 {f90} α {alpha} μ {a}, {b}: {got} vs {want}"
                );
            }
        }
    }
}

/// The paired coat attenuation A(μ_o) A(μ_i) is the product of the single ones, bit for
/// bit.
#[test]
fn paired_coat_attenuation_is_the_product() {
    let mut r = Rng::new(76, 0);
    for (coat, coat_alpha) in [(1.0f32, 0.09f32), (0.5, 0.0), (0.8, 0.6)] {
        let sh = GltfShared {
            coat,
            coat_alpha,
            alpha: 0.3,
            diel_f0: 0.04,
            diel_f90: 1.0,
            diffuse_norm: 1.1,
        };
        for _ in 0..500 {
            let (a, b) = (2.0 * r.uniform() - 1.0, 2.0 * r.uniform() - 1.0);
            let single = sh.coat_attenuation(a) * sh.coat_attenuation(b);
            assert_eq!(sh.coat_attenuation_pair(a, b).to_bits(), single.to_bits());
        }
    }
}

fn flip_dir(w: Vec3) -> Vec3 {
    super::flip(w)
}

#[test]
fn reflective_lobes_are_reciprocal() {
    for p in variants() {
        for (kind, c) in lobe_components(&p) {
            if kind == GltfLobeKind::Refraction {
                continue;
            }
            if kind == GltfLobeKind::ThinTransmission {
                // f(ωo, ωi) = f(ωi, ωo) across the surface.
                let mut r = Rng::new(69, 0);
                for _ in 0..1000 {
                    let a = crate::sampling::uniform_sphere(r.uniform2());
                    let mut b = crate::sampling::uniform_sphere(r.uniform2());
                    b.z = -b.z.abs() * a.z.signum();
                    let (x, y) = (c.eval(a, b).r, c.eval(b, a).r);
                    assert!((x - y).abs() <= 1e-3 * x.max(y) + 1e-6, "{x} vs {y}");
                }
                continue;
            }
            check_reciprocity(&c, 70);
        }
        let (ls, n) = lobes(&p);
        if !ls[..n]
            .iter()
            .any(|(l, _)| l.kind == GltfLobeKind::Refraction)
        {
            check_reciprocity(&Bsdf::from_gltf_lobes(&ls[..n]), 71);
        }
    }
}

#[test]
fn whole_material_samples_consistently_and_conserves_energy() {
    for p in variants() {
        let (ls, n) = lobes(&p);
        let mut b = Bsdf::from_gltf_lobes(&ls[..n]);
        for wo in test_directions_both_sides() {
            assert!(check_sample_consistency(&b, wo, 2000, 72) > 1000);
        }
        b.set_transport_mode(super::super::TransportMode::Importance);
        for wo in [dir(0.2, 0.1), dir(1.3, 1.0), flip_dir(dir(0.9, 2.0))] {
            check_energy(&b, wo, 400, 60_000, 73, 0.02);
        }
        // Weights sum to one; albedo estimates are in [0, 1].
        let w: f32 = b.components().map(|(_, w)| w).sum();
        assert!((w - 1.0).abs() < 1e-5);
        assert!(b
            .components()
            .all(|(c, _)| (0.0..=1.0).contains(&c.albedo())));
    }
}

#[test]
fn roughness_zero_makes_dirac_layers() {
    let p = GltfParams {
        base: Rgb::splat(0.5),
        roughness: 0.0,
        clearcoat: 1.0,
        transmission: 0.5,
        ..gltf_params()
    };
    let (ls, n) = lobes(&p);
    let kinds: Vec<_> = ls[..n]
        .iter()
        .map(|(l, _)| (l.kind, l.is_delta()))
        .collect();
    assert_eq!(
        kinds,
        vec![
            (GltfLobeKind::Coat, true),
            (GltfLobeKind::Specular, true),
            (GltfLobeKind::Diffuse, false),
            (GltfLobeKind::ThinTransmission, true)
        ]
    );
    // Throughput of the mixture's samples: E[f cos/pdf] = coat + A²(F_S + ρ(1 − F_d)·…).
    let b = Bsdf::from_gltf_lobes(&ls[..n]);
    let wo = v3(wo_at(0.6));
    let mut r = Rng::new(74, 0);
    let mut thin = 0;
    for _ in 0..5000 {
        let s = b.sample(wo, r.uniform(), r.uniform2()).unwrap();
        if s.node == NodeType::SpecularTransmission {
            thin += 1;
            assert!(
                (s.wi + wo).length() < 1e-5,
                "thin transmission goes straight through"
            );
        }
    }
    assert!(thin > 100);
}
