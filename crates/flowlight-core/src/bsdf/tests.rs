//! Tests of the BSDF mixture: every component against its formula, sampling against
//! evaluation, and the glTF mixture against its parts.

use super::testutil::*;
use super::*;
use crate::rng::Rng;
use crate::sampling::{jittered_moments, ONE_MINUS_EPSILON};

fn weights(b: &Bsdf) -> Vec<f32> {
    b.components().map(|(_, w)| w).collect()
}

/// The mixture with every dielectric switched to importance transport (R + T = 1), so
/// energy bounds hold from inside too.
fn without_radiance_scaling(mut b: Bsdf) -> Bsdf {
    b.set_transport_mode(TransportMode::Importance);
    b
}

fn kinds(b: &Bsdf) -> Vec<GltfLobeKind> {
    b.components()
        .map(|(c, _)| match c {
            Component::Gltf(l) => l.kind,
            c => panic!("not a glTF lobe: {c:?}"),
        })
        .collect()
}

#[test]
fn from_material_builds_the_gltf_mixture() {
    use GltfLobeKind::*;
    let base = Rgb::new(0.8, 0.5, 0.2);
    // The default material: a rough dielectric, specular layer over a diffuse base.
    let b = Bsdf::from_material(&Material::default(), base);
    assert_eq!(kinds(&b), vec![Specular, Diffuse]);
    assert!((weights(&b).iter().sum::<f32>() - 1.0).abs() < 1e-6);

    let m = Material {
        metallic: 0.5,
        transmission: 0.2,
        roughness: 0.5,
        clearcoat: 0.5,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, base);
    assert_eq!(kinds(&b), vec![Coat, Specular, Diffuse, ThinTransmission]);
    assert!((weights(&b).iter().sum::<f32>() - 1.0).abs() < 1e-6);
    assert!(weights(&b).iter().all(|&w| w > 0.0));
    // The specular layer's F0 mixes the dielectric's 0.04 and the metal's base colour.
    let Component::Gltf(s) = b.component(1) else {
        unreachable!()
    };
    assert!((s.alpha - 0.25).abs() < 1e-6);
    assert!((s.f0.r - (0.5 * 0.04 + 0.5 * 0.8)).abs() < 1e-6 && (s.f90.r - 1.0).abs() < 1e-6);
    // Volumetric transmission refracts.
    let b = Bsdf::from_material(
        &Material {
            thickness: 1.0,
            ..m
        },
        base,
    );
    assert_eq!(kinds(&b), vec![Coat, Specular, Diffuse, Refraction]);
    let Component::Gltf(r) = b.component(3) else {
        unreachable!()
    };
    assert!(r.dielectric.eta == 1.5 && r.dielectric.tint == base);

    // A smooth metal is one Dirac mirror.
    let m = Material {
        metallic: 1.0,
        roughness: 0.0,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, base);
    assert_eq!(kinds(&b), vec![Specular]);
    assert!(b.is_delta() && !b.has_non_delta());
    assert_eq!(b.component(0).class(), NodeClass::Alpha);

    // Full glass: only the refracting interface (and the metal's share of reflection).
    let m = Material {
        transmission: 1.0,
        thickness: 1.0,
        roughness: 0.1,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, base);
    // (A dielectric's whole reflection belongs to the interface: no specular layer.)
    assert_eq!(kinds(&b), vec![Refraction]);
    assert!(!b.is_delta() && b.component(0).class() == NodeClass::Alpha);

    // Oren–Nayar base under a smooth layer.
    let m = Material {
        diffuse_model: DiffuseModel::OrenNayar,
        oren_nayar_sigma: 0.5,
        metallic: 0.25,
        roughness: 0.0,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, base);
    assert_eq!(kinds(&b), vec![Specular, Diffuse]);
    assert!(b.has_non_delta() && !b.is_delta());
    assert!(b.component(0).is_delta() && b.component(1).class() == NodeClass::Beta);
    assert!(b.albedo() > 0.0 && b.albedo() <= 1.0);

    // Nothing to scatter: a black base, no specular, no metal.
    let m = Material {
        specular: 0.0,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, Rgb::ZERO);
    assert_eq!(b.components().count(), 1);
    assert!(b.eval(Vec3::Z, Vec3::Z).is_black());
}

#[test]
fn node_types_match_sampled_nodes() {
    let comps = [
        Component::Lambert(Lambert { albedo: Rgb::ONE }),
        Component::OrenNayar(OrenNayar::new(Rgb::ONE, 0.5)),
        Component::Conductor(Conductor {
            f0: Rgb::ONE,
            alpha: 0.3,
        }),
        Component::Conductor(Conductor {
            f0: Rgb::ONE,
            alpha: 0.0,
        }),
        Component::Dielectric(Dielectric::new(Rgb::ONE, 1.5, 0.3)),
        Component::Dielectric(Dielectric::new(Rgb::ONE, 1.5, 0.0)),
    ]
    .into_iter()
    .chain(
        [
            Material {
                transmission: 0.5,
                clearcoat: 1.0,
                clearcoat_roughness: 0.3,
                ..Default::default()
            },
            Material {
                transmission: 0.5,
                roughness: 0.0,
                ..Default::default()
            },
            Material {
                transmission: 0.5,
                thickness: 1.0,
                roughness: 0.4,
                ..Default::default()
            },
        ]
        .into_iter()
        .flat_map(|m| {
            let b = Bsdf::from_material(&m, Rgb::ONE);
            b.components().map(|(c, _)| c).collect::<Vec<_>>()
        }),
    );
    let mut r = Rng::new(52, 0);
    for c in comps {
        for wo in test_directions_both_sides() {
            for _ in 0..200 {
                if let Some(s) = c.sample_with(wo, r.uniform(), r.uniform2()) {
                    assert_eq!(c.node_type(wo, s.wi), s.node, "{c:?}");
                }
            }
        }
    }
}

#[test]
fn component_selection_follows_weights() {
    let m = Material {
        metallic: 0.5,
        transmission: 0.2,
        ..Default::default()
    };
    let b = Bsdf::from_material(&m, Rgb::ONE);
    let mut r = Rng::new(41, 0);
    let mut counts = [0usize; MAX_COMPONENTS];
    for _ in 0..30_000 {
        counts[b.choose_component(r.uniform()).0] += 1;
    }
    assert_eq!(weights(&b).len(), 3);
    for (c, w) in counts.iter().zip(weights(&b)) {
        assert!((*c as f32 / 30_000.0 - w).abs() < 0.01);
    }
}

#[test]
fn lambert_sampling_matches_eval_and_pdf() {
    let c = Component::Lambert(Lambert {
        albedo: Rgb::new(0.7, 0.2, 0.9),
    });
    for wo in test_directions_both_sides() {
        assert_eq!(check_sample_consistency(&c, wo, 2000, 42), 2000);
    }
}

#[test]
fn lambert_pdf_and_energy() {
    let a = Rgb::new(0.7, 0.2, 1.0);
    let c = Component::Lambert(Lambert { albedo: a });
    for wo in [dir(0.3, 0.1), flip(dir(1.3, 2.0))] {
        let (p, num) = sphere_integrals(&c, wo, 400, 43);
        assert!((p - 1.0).abs() < 0.01, "∫pdf = {p}");
        let is = check_energy(&c, wo, 400, 100_000, 44, 0.01);
        for k in 0..3 {
            let ak = a.to_array()[k] as f64;
            assert!(
                (num[k] - ak).abs() < 0.01 * ak,
                "numerical {} vs {ak}",
                num[k]
            );
            assert!((is[k] - ak).abs() < 0.01 * ak, "sampled {} vs {ak}", is[k]);
        }
    }
    check_reciprocity(&c, 45);
}

fn mixtures() -> Vec<Material> {
    vec![
        Material {
            metallic: 0.5,
            roughness: 0.6,
            ..Default::default()
        },
        Material {
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.8,
            metallic: 0.3,
            transmission: 0.3,
            roughness: 0.45,
            ..Default::default()
        },
        Material {
            transmission: 0.6,
            metallic: 0.5,
            roughness: 0.7,
            ior: 1.33,
            ..Default::default()
        },
    ]
}

#[test]
fn mixture_sampling_matches_eval_and_pdf() {
    for m in mixtures() {
        let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
        for wo in test_directions_both_sides() {
            let ok = check_sample_consistency(&b, wo, 3000, 46);
            assert!(ok > 1500);
        }
    }
}

#[test]
fn mixture_pdf_and_energy() {
    for m in mixtures() {
        let b = without_radiance_scaling(Bsdf::from_material(&m, Rgb::ONE));
        for wo in [dir(0.3, 0.2), flip(dir(0.7, 1.0)), dir(1.35, 2.0)] {
            let p = check_pdf_integral(&b, wo, 400, 100_000, 47);
            assert!(p > 0.8, "∫pdf = {p}");
            check_energy(&b, wo, 400, 100_000, 48, 0.02);
        }
    }
}

#[test]
fn mixture_reflection_is_reciprocal() {
    let m = Material {
        metallic: 0.4,
        transmission: 0.3,
        roughness: 0.5,
        ..Default::default()
    };
    check_reciprocity(&Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3)), 49);
    let m = Material {
        diffuse_model: DiffuseModel::OrenNayar,
        oren_nayar_sigma: 1.0,
        ..mixtures()[0]
    };
    check_reciprocity(&Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3)), 50);
}

/// Every component type alone, with the parameters that switch its branches: smooth
/// (Dirac), narrow and rough GGX, both transport modes, η = 1, and every glTF lobe kind.
fn every_component() -> Vec<Component> {
    let tint = Rgb::new(0.9, 0.6, 0.3);
    let mut cs = vec![
        Component::Lambert(Lambert { albedo: tint }),
        Component::OrenNayar(OrenNayar::new(tint, 0.0)),
        Component::OrenNayar(OrenNayar::new(tint, 0.7)),
    ];
    for alpha in [0.0, 0.01, 0.3, 1.0] {
        cs.push(Component::Conductor(Conductor { f0: tint, alpha }));
        for (eta, mode) in [
            (1.5, TransportMode::Radiance),
            (1.33, TransportMode::Importance),
            (1.0, TransportMode::Radiance),
        ] {
            cs.push(Component::Dielectric(Dielectric {
                mode,
                ..Dielectric::new(tint, eta, alpha)
            }));
        }
    }
    for b in every_gltf_mixture() {
        cs.extend(b.components().map(|(c, _)| c));
    }
    cs
}

/// The glTF material's switches, alone and together: metal, rough and smooth layers,
/// clearcoat (rough and Dirac), thin and volumetric transmission (rough and smooth),
/// Oren–Nayar, KHR_materials_specular (coloured, and 0), η = 1; both transport modes.
fn every_gltf_mixture() -> Vec<Bsdf> {
    let d = Material::default();
    // KHR_materials_specular, coloured, and an unusual η.
    let coloured = Material {
        roughness: 0.6,
        specular: 0.7,
        specular_color: Rgb::new(2.0, 1.0, 0.5),
        ior: 1.8,
        ..d
    };
    let materials = [
        d,
        Material {
            roughness: 0.5,
            ..d
        },
        Material {
            metallic: 0.5,
            roughness: 0.6,
            ..d
        },
        Material {
            metallic: 1.0,
            roughness: 0.4,
            ..d
        },
        Material {
            metallic: 1.0,
            roughness: 0.0,
            ..d
        },
        Material {
            metallic: 0.25,
            roughness: 0.0,
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.5,
            ..d
        },
        Material {
            roughness: 0.5,
            clearcoat: 1.0,
            clearcoat_roughness: 0.3,
            ..d
        },
        Material {
            roughness: 0.4,
            clearcoat: 0.7,
            clearcoat_roughness: 0.0,
            ..d
        },
        Material {
            roughness: 0.45,
            transmission: 0.6,
            ..d
        },
        Material {
            roughness: 0.0,
            transmission: 0.5,
            clearcoat: 1.0,
            ..d
        },
        Material {
            roughness: 0.45,
            transmission: 0.7,
            thickness: 1.0,
            ior: 1.33,
            ..d
        },
        Material {
            roughness: 0.1,
            transmission: 1.0,
            thickness: 1.0,
            ..d
        },
        Material {
            roughness: 0.0,
            transmission: 0.5,
            thickness: 1.0,
            ..d
        },
        Material {
            metallic: 0.5,
            transmission: 0.2,
            roughness: 0.5,
            clearcoat: 0.5,
            clearcoat_roughness: 0.2,
            ..d
        },
        Material {
            metallic: 0.3,
            transmission: 0.4,
            thickness: 1.0,
            roughness: 0.3,
            clearcoat: 0.8,
            clearcoat_roughness: 0.5,
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.8,
            ..d
        },
        coloured,
        Material {
            roughness: 0.3,
            ior: 1.0,
            ..d
        },
        // α = 0.0025: a narrow lobe, but not a Dirac one.
        Material {
            roughness: 0.05,
            metallic: 0.7,
            ..d
        },
        Material {
            diffuse_model: DiffuseModel::OrenNayar,
            oren_nayar_sigma: 0.5,
            ..coloured
        },
        // No dielectric layer (the Lambertian Cornell box): a lone diffuse lobe.
        Material { specular: 0.0, ..d },
    ];
    let mut out = Vec::new();
    for m in materials {
        let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
        out.push(b);
        out.push(without_radiance_scaling(b));
    }
    out
}

/// Every mixture: the glTF ones, each component alone with weight 1, and hand-built
/// mixtures of the standalone models (rough and Dirac).
fn every_mixture() -> Vec<Bsdf> {
    let mut out = every_gltf_mixture();
    out.extend(every_component().into_iter().map(Bsdf::single));
    let tint = Rgb::new(0.9, 0.6, 0.3);
    for alpha in [0.0, 0.3] {
        let mut b = Bsdf::single(Component::OrenNayar(OrenNayar::new(tint, 0.4)));
        b.components[0] = Some((b.component(0), 0.3));
        b.components[1] = Some((Component::Conductor(Conductor { f0: tint, alpha }), 0.2));
        b.components[2] = Some((
            Component::Dielectric(Dielectric::new(tint, 1.5, alpha)),
            0.4,
        ));
        b.components[3] = Some((Component::Lambert(Lambert { albedo: tint }), 0.1));
        b.count = 4;
        // The summary (albedo, Dirac, pair, reflection only) of the mixture as built.
        out.push(b.summarise());
    }
    out
}

/// `eval_pdf` is `(eval, pdf)` bit for bit, for every component type and every mixture,
/// at random pairs on both sides, pairs inside narrow lobes, degenerate pairs, and each
/// model's own samples (where its value is surely non-zero).
#[test]
fn eval_pdf_equals_eval_and_pdf_bit_for_bit() {
    let pairs = direction_pairs(3000, 80);
    let mut r = Rng::new(81, 0);
    let mut nonzero = (0usize, 0usize);
    let mut check =
        |name: &str, m: &dyn Fn(Vec3, Vec3) -> ((Rgb, f32), Rgb, f32), pairs: &[(Vec3, Vec3)]| {
            for &(wo, wi) in pairs {
                let ((f, p), ef, ep) = m(wo, wi);
                assert!(
                    same_rgb(f, ef) && same_float(p, ep),
                    "{name} at wo {wo:?} wi {wi:?}: eval_pdf ({f:?}, {p}) vs ({ef:?}, {ep})"
                );
                nonzero.0 += !f.is_black() as usize;
                nonzero.1 += (p != 0.0) as usize;
            }
        };
    // 50 of a model's own samples at each test direction, drawn by `sample(wo, uc, u)`.
    let mut own_pairs = |sample: &dyn Fn(Vec3, f32, Vec2) -> Option<BsdfSample>| {
        let mut v = Vec::new();
        for wo in test_directions_both_sides() {
            for _ in 0..50 {
                if let Some(s) = sample(wo, r.uniform(), r.uniform2()) {
                    v.push((wo, s.wi));
                }
            }
        }
        v
    };
    for c in every_component() {
        let own = own_pairs(&|wo, uc, u| c.sample_with(wo, uc, u));
        let m = |wo, wi| (c.eval_pdf(wo, wi), c.eval(wo, wi), c.pdf(wo, wi));
        check(&format!("{c:?}"), &m, &pairs);
        check(&format!("{c:?} (own samples)"), &m, &own);
    }
    for b in every_mixture() {
        let own = own_pairs(&|wo, uc, u| b.sample(wo, uc, u));
        let m = |wo, wi| (b.eval_pdf(wo, wi), b.eval(wo, wi), b.pdf(wo, wi));
        check(&format!("{b:?}"), &m, &pairs);
        check(&format!("{b:?} (own samples)"), &m, &own);
    }
    // The comparisons saw real values, not only the zeros of the early exits.
    assert!(nonzero.0 > 100_000 && nonzero.1 > 100_000, "{nonzero:?}");
}

/// A glTF material whose only lobe is a plain diffuse base (specular factor 0, no coat,
/// no transmission, σ = 0) is built as one Lambert component, and it gives what the glTF
/// lobe gives, bit for bit: values, densities, samples, albedo. A specular layer, a coat,
/// transmission or σ > 0 keep the glTF mixture.
#[test]
fn a_plain_gltf_diffuse_base_is_a_lambert_component_with_the_same_values() {
    let plain = GltfParams {
        base: Rgb::new(0.9, 0.6, 0.3),
        specular: 0.0,
        ..gltf_params()
    };
    let (lobes, n) = gltf::lobes(&plain);
    assert_eq!(n, 1);
    let lambert = Bsdf::from_gltf_lobes(&lobes[..n]);
    assert!(matches!(lambert.component(0), Component::Lambert(_)));
    assert_eq!(lambert.components().count(), 1);
    let glt = Bsdf::single(Component::Gltf(lobes[0].0));
    assert!(same_float(lambert.albedo(), glt.albedo()));
    for (wo, wi) in direction_pairs(3000, 91) {
        let ((f, p), (gf, gp)) = (lambert.eval_pdf(wo, wi), glt.eval_pdf(wo, wi));
        assert!(same_rgb(f, gf) && same_float(p, gp), "{wo:?} {wi:?}");
        assert!(same_rgb(lambert.eval(wo, wi), glt.eval(wo, wi)));
        assert!(same_float(lambert.pdf(wo, wi), glt.pdf(wo, wi)));
    }
    let mut r = Rng::new(92, 0);
    let mut sampled = 0;
    for wo in test_directions_both_sides() {
        for _ in 0..300 {
            let (uc, u) = (r.uniform(), r.uniform2());
            match (lambert.sample(wo, uc, u), glt.sample(wo, uc, u)) {
                (Some(a), Some(b)) => {
                    assert_eq!(a.wi, b.wi);
                    assert!(same_rgb(a.f, b.f) && same_float(a.pdf, b.pdf));
                    assert_eq!((a.node, a.delta, a.eta), (b.node, b.delta, b.eta));
                    sampled += 1;
                }
                (None, None) => {}
                (a, b) => panic!("{wo:?}: {a:?} against {b:?}"),
            }
        }
    }
    assert!(sampled > 1000, "{sampled}");
    for other in [
        GltfParams {
            specular: 0.5,
            ..plain
        },
        GltfParams {
            oren_nayar_sigma: 0.3,
            ..plain
        },
        GltfParams {
            clearcoat: 0.5,
            ..plain
        },
        GltfParams {
            transmission: 0.5,
            ..plain
        },
    ] {
        let (lobes, n) = gltf::lobes(&other);
        let b = Bsdf::from_gltf_lobes(&lobes[..n]);
        assert!(
            b.components().all(|(c, _)| matches!(c, Component::Gltf(_))),
            "{other:?}"
        );
    }
}

/// The summary a mixture keeps (albedo, whether a light can be connected) is the walk
/// over its components, for every mixture (single components included), in both
/// transport modes.
#[test]
fn summary_is_the_walk_over_the_components() {
    let mut deltas = 0;
    for mut b in every_mixture() {
        for mode in [TransportMode::Importance, TransportMode::Radiance] {
            b.set_transport_mode(mode);
            let albedo = b
                .components()
                .map(|(c, w)| c.albedo() * w)
                .sum::<f32>()
                .clamp(0.0, 1.0);
            let non_delta = b.components().any(|(c, _)| !c.is_delta());
            assert!(same_float(b.albedo(), albedo), "{b:?}");
            assert_eq!(b.has_non_delta(), non_delta, "{b:?}");
            assert_eq!(b.is_delta(), !non_delta, "{b:?}");
            deltas += b.is_delta() as usize;
        }
    }
    assert!(deltas > 0, "some all-Dirac mixture was checked");
}

/// Directions so close to the surface that wo.z · wi.z underflows to zero, and one in it.
const GRAZING: [Vec3; 3] = [
    Vec3::new(1.0, 0.0, 1e-30),
    Vec3::new(0.0, -1.0, -1e-30),
    Vec3::new(1.0, 0.0, 0.0),
];

/// The pair's first number chooses the lobe and, rescaled, samples it: a pixel's 64
/// jittered pairs (8 × 8 strata) estimate a glossy-on-diffuse pair's albedo with about
/// 1.7 times less variance than with a separate, randomly paired choice number (emulated by
/// mapping the pair into the chosen lobe's interval). Fails if the lobe choice stops
/// using the pair.
#[test]
fn a_mixture_keeps_the_pairs_strata_on_each_lobe() {
    let b = every_gltf_mixture()
        .into_iter()
        .filter(|b| b.opaque_pair().is_some())
        .max_by(|a, b| {
            a.components[0]
                .unwrap()
                .1
                .total_cmp(&b.components[0].unwrap().1)
        })
        .unwrap();
    let (w_spec, w_diffuse) = (b.components[0].unwrap().1, b.components[1].unwrap().1);
    assert!(w_spec > 0.2, "{w_spec}");
    let wo = Vec3::new(0.6, 0.0, 0.8);
    let weight =
        |s: Option<BsdfSample>| s.map_or(0.0, |s| (s.f.luminance() * s.wi.z.abs() / s.pdf) as f64);
    let [pair, separate] = jittered_moments(&mut Rng::new(21, 4), 1000, 8, |u, r| {
        let separate = if r.uniform() < w_spec {
            Vec2::new(u.x * w_spec, u.y)
        } else {
            Vec2::new(w_spec + u.x * w_diffuse, u.y)
        };
        [
            weight(b.sample(wo, 0.5, u)),
            weight(b.sample(wo, 0.5, separate)),
        ]
    });
    assert!(
        (pair.0 / separate.0 - 1.0).abs() < 0.02,
        "{pair:?} {separate:?}"
    );
    assert!(
        pair.1 * 1.4 < separate.1,
        "mean and variance: {pair:?} (one pair) against {separate:?} (separate choice)"
    );
}

/// The direction numbers of draw `k` of a loop: near 1 for the first two (cos θ_i close to
/// 0 at the hemisphere's rim), random after.
fn rim_or_random(k: usize, r: &mut Rng) -> Vec2 {
    match k {
        0 => Vec2::new(ONE_MINUS_EPSILON, 0.3),
        1 => Vec2::new(1.0 - 1e-7, 0.7),
        _ => r.uniform2(),
    }
}

/// Asserts that two ways of sampling gave one sample bit for bit (direction, value,
/// density, kind) or both refused; true where they drew one.
fn same_sample(a: Option<BsdfSample>, b: Option<BsdfSample>, context: impl Fn() -> String) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => {
            assert!(
                a.wi == b.wi
                    && same_rgb(a.f, b.f)
                    && same_float(a.pdf, b.pdf)
                    && (a.node, a.delta, a.eta) == (b.node, b.delta, b.eta),
                "{}: {a:?} vs {b:?}",
                context()
            );
            true
        }
        (None, None) => false,
        (a, b) => panic!("{}: {a:?} vs {b:?}", context()),
    }
}

/// A lone Lambert component samples and evaluates without the mixture walk, and gives
/// what the walk gives bit for bit: the walk is taken by the same Lambert beside a second, black
/// component of weight 0 (which adds +0 to the value and the density), also at
/// directions so close to the surface that wo.z · wi.z underflows to zero (refused by
/// both).
#[test]
fn a_lone_lambert_samples_as_the_mixture_walk_does() {
    let lambert = Lambert {
        albedo: Rgb::new(0.9, 0.5, 0.2),
    };
    let lone = Bsdf::single(Component::Lambert(lambert));
    assert!(lone.lone_lambert().is_some());
    let mut components = [None; MAX_COMPONENTS];
    components[0] = Some((Component::Lambert(lambert), 1.0));
    components[1] = Some((Component::Lambert(Lambert { albedo: Rgb::ZERO }), 0.0));
    let walk = Bsdf {
        components,
        count: 2,
        albedo: 0.0,
        non_delta: false,
        opaque_pair: false,
        reflects_only: false,
    }
    .summarise();
    assert!(walk.lone_lambert().is_none());
    let mut r = Rng::new(93, 0);
    let (mut sampled, mut refused) = (0, 0);
    for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
        for k in 0..300 {
            let u = rim_or_random(k, &mut r);
            let uc = r.uniform();
            let (a, b) = (lone.sample(wo, uc, u), walk.sample(wo, uc, u));
            match same_sample(a, b, || format!("lone against walk at {wo:?} {u:?}")) {
                true => sampled += 1,
                false => refused += 1,
            }
        }
    }
    assert!(
        sampled > 1000 && refused > 0,
        "{sampled} sampled, {refused} refused"
    );
    for (wo, wi) in direction_pairs(3000, 94) {
        let ((f, p), (wf, wp)) = (lone.eval_pdf(wo, wi), walk.eval_pdf(wo, wi));
        assert!(same_rgb(f, wf) && same_float(p, wp), "{wo:?} {wi:?}");
    }
}

/// A metallic-roughness material without coat or transmission (roughness > 0) is an
/// opaque pair, sampled and evaluated without the walk, and the pair gives what the walk
/// gives bit for bit: directions, values, densities, kinds and refusals, at random
/// numbers, at numbers on the lobe boundary and the hemisphere's rim, and at directions
/// so close to the surface that wo.z · wi.z underflows. A Dirac specular layer, a coat or
/// transmission keep the walk.
#[test]
fn an_opaque_pair_samples_and_evaluates_as_the_walk_does() {
    // Every opaque pair among the glTF mixtures: rough and narrow, dielectric and metal,
    // coloured specular, Oren–Nayar base, both transport modes.
    let pairs: Vec<Bsdf> = every_gltf_mixture()
        .into_iter()
        .filter(|b| b.opaque_pair().is_some())
        .collect();
    assert!(pairs.len() >= 12, "{} pairs", pairs.len());
    let mut r = Rng::new(95, 0);
    let (mut sampled, mut refused, mut specular) = (0, 0, 0);
    for b in pairs {
        let spec_weight = b.components[0].unwrap().1;
        for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
            for k in 0..400 {
                let mut u = rim_or_random(k, &mut r);
                // The lobe choice's boundary, on both sides.
                match k {
                    2 => u.x = spec_weight,
                    3 => u.x = f32::from_bits(spec_weight.to_bits() - 1),
                    _ => {}
                }
                let uc = r.uniform();
                let (a, w) = (b.sample(wo, uc, u), b.sample_by_walk(wo, uc, u));
                specular += a.is_some_and(|a| a.node == NodeType::GlossyReflection) as usize;
                match same_sample(a, w, || {
                    format!("pair against walk, {b:?} {wo:?} {uc} {u:?}")
                }) {
                    true => sampled += 1,
                    false => refused += 1,
                }
            }
        }
        for (wo, wi) in direction_pairs(3000, 96) {
            let ((f, p), (wf, wp)) = (b.eval_pdf(wo, wi), b.eval_pdf_by_walk(wo, wi));
            assert!(same_rgb(f, wf) && same_float(p, wp), "{b:?} {wo:?} {wi:?}");
        }
    }
    assert!(
        sampled > 10_000 && specular > 1000 && refused > 0,
        "{sampled} sampled ({specular} specular), {refused} refused"
    );
    let d = Material::default();
    for m in [
        Material {
            roughness: 0.0,
            ..d
        },
        Material {
            clearcoat: 0.5,
            ..d
        },
        Material {
            transmission: 0.5,
            ..d
        },
        Material { metallic: 1.0, ..d },
    ] {
        let b = Bsdf::from_material(&m, Rgb::new(0.9, 0.6, 0.3));
        assert!(b.opaque_pair().is_none(), "{m:?}");
    }
}

/// A BSDF at one ω_o ([`Bsdf::at`]) samples and evaluates as the BSDF itself does at
/// that ω_o, bit for bit, for every glTF mixture (opaque pairs, whose ω_o terms it
/// computes once, and the rest); so does one rebuilt from its terms ([`Bsdf::at_with`]),
/// and one given terms of another kind of BSDF, which it ignores.
#[test]
fn a_bsdf_at_one_direction_gives_what_its_calls_give() {
    let mixtures = every_gltf_mixture();
    let pairs = mixtures
        .iter()
        .filter(|b| b.opaque_pair().is_some())
        .count();
    assert!(
        pairs >= 12 && mixtures.len() > pairs,
        "{pairs} of {}",
        mixtures.len()
    );
    let pair_terms = mixtures
        .iter()
        .find(|b| b.opaque_pair().is_some())
        .unwrap()
        .at(dir(0.4, 0.3))
        .terms();
    let mut r = Rng::new(98, 0);
    let mut sampled = 0;
    for b in &mixtures {
        for wo in test_directions_both_sides().into_iter().chain(GRAZING) {
            let at = b.at(wo);
            assert_eq!(at.terms().0.is_some(), b.opaque_pair().is_some());
            let kept = b.at_with(wo, at.terms());
            // Terms of a pair given to another kind, none given to a pair: recomputed.
            let other = b.at_with(
                wo,
                if at.terms().0.is_some() {
                    OutgoingTerms::default()
                } else {
                    pair_terms
                },
            );
            for k in 0..40 {
                let u = rim_or_random(k, &mut r);
                let uc = r.uniform();
                let want = b.sample(wo, uc, u);
                for got in [at.sample(uc, u), kept.sample(uc, u), other.sample(uc, u)] {
                    sampled += same_sample(got, want, || format!("{b:?} {wo:?} {u:?}")) as usize;
                }
            }
        }
        for (wo, wi) in direction_pairs(500, 99) {
            let (f, p) = b.eval_pdf(wo, wi);
            let (af, ap) = b.at(wo).eval_pdf(wi);
            assert!(same_rgb(af, f) && same_float(ap, p), "{b:?} {wo:?} {wi:?}");
            assert!(same_rgb(b.at(wo).eval(wi), b.eval(wo, wi)));
            assert_eq!(b.at(wo).is_zero_between(wi), b.is_zero_between(wo, wi));
        }
    }
    assert!(sampled > 10_000, "{sampled} sampled");
}

/// Where `is_zero_between` says so, every mixture is zero (value, density and their
/// one-pass form): at random pairs on both sides, pairs with a zero cosine (±0) and
/// grazing pairs. It says so for a fair share of the pairs of the reflection-only
/// mixtures, never for a mixture that transmits, and never with a NaN cosine.
#[test]
fn a_bsdf_is_zero_where_is_zero_between_says_so() {
    let mut pairs = direction_pairs(3000, 97);
    for z in [0.0, -0.0, 1e-30, -1e-30] {
        for w in [dir(0.6, 1.1), flip(dir(1.2, 2.0))] {
            pairs.push((Vec3::new(0.8, 0.6, z), w));
            pairs.push((w, Vec3::new(0.6, -0.8, z)));
        }
    }
    let nan = Vec3::new(0.0, 0.0, f32::NAN);
    let (mut reflecting, mut transmitting) = (0, 0);
    for b in every_mixture() {
        let transmits = b.components().any(|(c, _)| {
            matches!(c, Component::Dielectric(_))
                || matches!(c, Component::Gltf(l) if matches!(
                    l.kind,
                    GltfLobeKind::ThinTransmission | GltfLobeKind::Refraction
                ))
        });
        let mut zero = 0;
        for &(wo, wi) in &pairs {
            if !b.is_zero_between(wo, wi) {
                continue;
            }
            zero += 1;
            let (f, p) = b.eval_pdf(wo, wi);
            assert!(
                f.is_black() && p == 0.0 && b.eval(wo, wi).is_black() && b.pdf(wo, wi) == 0.0,
                "{b:?} at {wo:?} {wi:?}: ({f:?}, {p})"
            );
        }
        assert!(!b.is_zero_between(nan, dir(0.6, 1.1)));
        assert!(!b.is_zero_between(dir(0.6, 1.1), nan));
        if transmits {
            assert_eq!(zero, 0, "{b:?} transmits");
            transmitting += 1;
        } else {
            assert!(zero > 1000, "{b:?}: {zero} pairs");
            reflecting += 1;
        }
    }
    assert!(
        reflecting > 10 && transmitting > 5,
        "{reflecting} {transmitting}"
    );
}

/// A non-Dirac sample of a mixture carries `eval` and `pdf` at its direction bit for bit,
/// although `sample` reuses the chosen component's own value (and diffuse density).
#[test]
fn mixture_samples_carry_eval_and_pdf_bit_for_bit() {
    let mut r = Rng::new(82, 0);
    let mut smooth = 0;
    for b in every_mixture() {
        for wo in test_directions_both_sides() {
            for _ in 0..300 {
                let Some(s) = b.sample(wo, r.uniform(), r.uniform2()) else {
                    continue;
                };
                if s.delta {
                    continue;
                }
                smooth += 1;
                let (f, p) = (b.eval(wo, s.wi), b.pdf(wo, s.wi));
                assert!(
                    same_rgb(s.f, f) && same_float(s.pdf, p),
                    "{b:?} wo {wo:?} wi {:?}: sampled ({:?}, {}) vs ({f:?}, {p})",
                    s.wi,
                    s.f,
                    s.pdf
                );
            }
        }
    }
    assert!(smooth > 50_000, "{smooth}");
}

/// Mixtures with Dirac lobes: a Dirac sample's throughput is the lobe's value over its
/// selection probability, continuous samples see only the continuous part, and the
/// expected throughput is the material's albedo.
#[test]
fn mixture_with_dirac_lobes() {
    let base = Rgb::new(0.9, 0.6, 0.3);
    let mirror = Material {
        metallic: 0.5,
        roughness: 0.0,
        ..Default::default()
    };
    let glass = Material {
        transmission: 0.5,
        thickness: 1.0,
        roughness: 0.0,
        ..Default::default()
    };
    for m in [mirror, glass] {
        let b = without_radiance_scaling(Bsdf::from_material(&m, base));
        assert!(b.has_non_delta() && !b.is_delta());
        for wo in [dir(0.4, 0.5), flip(dir(1.0, 2.0))] {
            let mut r = Rng::new(51, 0);
            let n = 200_000;
            let mut sum = Rgb::ZERO;
            let mut dirac = Rgb::ZERO;
            for _ in 0..n {
                let s = b.sample(wo, r.uniform(), r.uniform2()).unwrap();
                let t = s.f * (s.wi.z.abs() / s.pdf);
                sum += t;
                if s.delta {
                    dirac += t;
                    if s.node == NodeType::SpecularReflection {
                        assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-5);
                    } else {
                        assert_eq!(s.node, NodeType::SpecularTransmission);
                    }
                } else {
                    assert_eq!(s.node, NodeType::DiffuseReflection);
                }
            }
            // The Dirac part: the specular layer's Schlick reflectance, plus for glass the
            // interface's reflection and tinted refraction with their weight.
            let layer = b
                .components()
                .find(|(c, _)| matches!(c, Component::Gltf(l) if l.kind == GltfLobeKind::Specular))
                .map(|(c, _)| match c {
                    Component::Gltf(l) => gltf::schlick_f0_f90(l.f0, l.f90, wo.z),
                    _ => unreachable!(),
                })
                .unwrap();
            let expected_dirac = if m.metallic > 0.0 {
                layer
            } else {
                let fr = fresnel_dielectric(wo.z, 1.5);
                layer + (Rgb::splat(fr) + base * (1.0 - fr)) * 0.5
            };
            let mean = dirac / n as f32;
            for (x, y) in mean.to_array().into_iter().zip(expected_dirac.to_array()) {
                assert!(
                    (x - y).abs() < 0.01,
                    "Dirac throughput {mean:?} vs {expected_dirac:?}"
                );
            }
            // The diffuse base integrates to ρ(1 − m)(1 − t)(1 − E_d(μ_o)).
            let e_d = gltf::GltfShared {
                coat: 0.0,
                coat_alpha: 0.0,
                alpha: 0.0,
                diel_f0: 0.04,
                diel_f90: 1.0,
                diffuse_norm: 0.0,
            }
            .dielectric_albedo(wo.z);
            let expected = expected_dirac + base * (0.5 * (1.0 - e_d));
            let mean = sum / n as f32;
            for (x, y) in mean.to_array().into_iter().zip(expected.to_array()) {
                assert!(
                    (x - y).abs() < 0.01,
                    "mean throughput {mean:?} vs {expected:?}"
                );
            }
        }
    }
}
