//! Tests of the layer lobes (sheen, translucent diffuse base, thin film) with the checks
//! every glTF lobe passes (`tests.rs`): sampling matches eval and pdf, ∫ pdf ≤ 1 and equals
//! the sampler's success rate, the albedo never exceeds one (white furnace), reciprocity.

use super::super::testutil::*;
use super::super::{Bsdf, Component, TransportMode};
use super::*;
use crate::rng::Rng;

fn with_layers(f: impl FnOnce(&mut MaterialLayers)) -> MaterialLayers {
    let mut l = MaterialLayers::default();
    f(&mut l);
    l
}

/// Materials with each layer, alone and with the other extensions.
fn layered_variants() -> Vec<GltfParams> {
    let b = Rgb::new(0.9, 0.6, 0.3);
    let sheen = with_layers(|l| {
        l.sheen_color = Rgb::new(1.0, 0.8, 0.6);
        l.sheen_roughness = 0.4;
    });
    let sheen_sharp = with_layers(|l| {
        l.sheen_color = Rgb::ONE;
        l.sheen_roughness = 0.1;
    });
    let translucent = with_layers(|l| {
        l.diffuse_transmission = 0.6;
        l.diffuse_transmission_color = Rgb::new(0.4, 0.9, 0.2);
    });
    let film = with_layers(|l| {
        l.iridescence = 1.0;
        l.iridescence_ior = 1.3;
        l.iridescence_thickness_max = 350.0;
    });
    let aniso = with_layers(|l| {
        l.anisotropy_strength = 0.8;
        l.anisotropy_direction = [0.6, 0.8];
    });
    vec![
        GltfParams {
            base: b,
            roughness: 0.3,
            layers: aniso,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            metallic: 1.0,
            roughness: 0.0,
            layers: MaterialLayers {
                anisotropy_strength: 1.0,
                ..aniso
            },
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.6,
            layers: sheen,
            ..gltf_params()
        },
        GltfParams {
            base: Rgb::ONE,
            roughness: 0.8,
            layers: sheen_sharp,
            clearcoat: 1.0,
            clearcoat_roughness: 0.2,
            transmission: 0.5,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            metallic: 1.0,
            roughness: 0.5,
            layers: sheen,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.5,
            layers: translucent,
            ..gltf_params()
        },
        GltfParams {
            base: Rgb::ONE,
            roughness: 0.3,
            layers: MaterialLayers {
                diffuse_transmission: 1.0,
                diffuse_transmission_color: Rgb::ONE,
                ..sheen
            },
            oren_nayar_sigma: 0.4,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            roughness: 0.35,
            layers: film,
            ..gltf_params()
        },
        GltfParams {
            base: b,
            metallic: 0.7,
            roughness: 0.5,
            layers: film,
            ..gltf_params()
        },
        GltfParams {
            base: Rgb::ONE,
            roughness: 0.25,
            ior: 1.8,
            layers: MaterialLayers {
                iridescence_ior: 2.0,
                iridescence_thickness_max: 600.0,
                ..film
            },
            ..gltf_params()
        },
    ]
}

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

#[test]
fn layered_materials_have_their_lobes() {
    let kinds = |p: &GltfParams| {
        let (ls, n) = lobes(p);
        ls[..n].iter().map(|(l, _)| l.kind).collect::<Vec<_>>()
    };
    let v = layered_variants();
    use GltfLobeKind::*;
    assert_eq!(kinds(&v[0]), vec![AnisotropicSpecular, Diffuse]);
    let v = &v[2..];
    assert_eq!(kinds(&v[0]), vec![Sheen, Specular, Diffuse]);
    assert_eq!(
        kinds(&v[1]),
        vec![Coat, Sheen, Specular, Diffuse, ThinTransmission]
    );
    assert_eq!(kinds(&v[3]), vec![Specular, TranslucentDiffuse]);
    let (ls, n) = lobes(&v[5]);
    assert!(ls[..n].iter().any(|(l, _)| l.film.is_some()));
    // Every lobe beneath the sheen carries its scaling, the sheen and coat do not.
    let (ls, n) = lobes(&v[1]);
    for (l, _) in &ls[..n] {
        assert_eq!(
            l.sheen.is_some(),
            !matches!(l.kind, Coat | Sheen),
            "{:?}",
            l.kind
        );
    }
}

/// Layers that are off (factor 0, black sheen) build the lobes of a material without them,
/// bit for bit, whatever their other parameters.
#[test]
fn layers_that_are_off_change_nothing() {
    let off = with_layers(|l| {
        l.sheen_roughness = 0.7;
        l.diffuse_transmission_color = Rgb::new(0.1, 0.2, 0.3);
        l.iridescence_ior = 2.0;
        l.iridescence_thickness_max = 250.0;
    });
    for p in [
        gltf_params(),
        GltfParams {
            metallic: 0.4,
            clearcoat: 0.5,
            transmission: 0.3,
            ..gltf_params()
        },
    ] {
        let (a, na) = lobes(&p);
        let (b, nb) = lobes(&GltfParams { layers: off, ..p });
        assert_eq!(na, nb);
        for ((la, wa), (lb, wb)) in a[..na].iter().zip(&b[..nb]) {
            assert_eq!(wa.to_bits(), wb.to_bits());
            assert_eq!(format!("{la:?}"), format!("{lb:?}"));
        }
    }
}

#[test]
fn layer_lobes_sample_their_eval_and_pdf() {
    for p in layered_variants() {
        for (kind, c) in lobe_components(&p) {
            for wo in test_directions_both_sides() {
                let ok = check_sample_consistency(&c, wo, 2000, 166);
                assert!(ok > 500, "{kind:?}: only {ok} samples");
            }
        }
    }
}

#[test]
fn layer_lobes_pdf_and_energy() {
    for p in layered_variants() {
        for (kind, c) in lobe_components(&p) {
            if kind == GltfLobeKind::Refraction {
                continue;
            }
            // Narrow lobes need a finer grid (as in tests.rs).
            let narrow =
                matches!(c, Component::Gltf(l) if l.class_alpha().is_some_and(|a| a < 0.1));
            let n = if narrow { 1000 } else { 400 };
            for wo in [dir(0.3, 0.2), super::flip(dir(0.8, 1.0)), dir(1.35, 2.0)] {
                let pi = check_pdf_integral(&c, wo, n, 60_000, 167);
                assert!(pi > 0.5, "{kind:?}: ∫pdf {pi}");
                check_energy(&c, wo, n, 60_000, 168, 0.02);
            }
        }
    }
}

/// The whole layered material: sampling matches the mixture, weights sum to one, and a
/// white material never reflects and transmits more than it receives.
#[test]
fn layered_materials_sample_consistently_and_conserve_energy() {
    for p in layered_variants() {
        let (ls, n) = lobes(&p);
        let mut b = Bsdf::from_gltf_lobes(&ls[..n]);
        for wo in test_directions_both_sides() {
            assert!(check_sample_consistency(&b, wo, 2000, 172) > 1000);
        }
        b.set_transport_mode(TransportMode::Importance);
        // Narrow lobes need a finer grid (as in tests.rs).
        let narrow = ls[..n]
            .iter()
            .any(|(l, _)| l.class_alpha().is_some_and(|a| a < 0.1));
        let grid = if narrow { 1000 } else { 400 };
        for wo in [dir(0.2, 0.1), dir(1.3, 1.0), super::flip(dir(0.9, 2.0))] {
            check_energy(&b, wo, grid, 60_000, 173, 0.02);
        }
        let w: f32 = b.components().map(|(_, w)| w).sum();
        assert!((w - 1.0).abs() < 1e-5);
    }
}

/// White furnace: a white material with every layer at full strength reflects (and
/// transmits) at most what it receives, at grazing and normal view.
#[test]
fn white_layered_material_stays_in_the_furnace_bound() {
    let all = with_layers(|l| {
        l.anisotropy_strength = 0.7;
        l.anisotropy_direction = [0.0, 1.0];
        l.sheen_color = Rgb::ONE;
        l.sheen_roughness = 0.3;
        l.diffuse_transmission = 0.5;
        l.diffuse_transmission_color = Rgb::ONE;
        l.iridescence = 1.0;
        l.iridescence_thickness_max = 300.0;
    });
    for rough in [0.2f32, 0.5, 1.0] {
        let p = GltfParams {
            base: Rgb::ONE,
            roughness: rough,
            layers: all,
            ..gltf_params()
        };
        let (ls, n) = lobes(&p);
        let b = Bsdf::from_gltf_lobes(&ls[..n]);
        for theta in [0.0f32, 0.7, 1.2, 1.5] {
            let e = check_energy(&b, dir(theta, 0.4), 400, 60_000, 181, 0.02);
            assert!(e.iter().all(|&v| v > 0.5), "rough {rough} θ {theta}: {e:?}");
        }
    }
}

/// The sheen and the translucent base are reciprocal (across the surface for the
/// transmission), and so is the whole material with a film.
#[test]
fn layer_lobes_are_reciprocal() {
    for p in layered_variants() {
        let (ls, n) = lobes(&p);
        if ls[..n]
            .iter()
            .any(|(l, _)| l.kind == GltfLobeKind::Refraction)
        {
            continue;
        }
        check_reciprocity(&Bsdf::from_gltf_lobes(&ls[..n]), 171);
        for (kind, c) in lobe_components(&p) {
            if kind != GltfLobeKind::TranslucentDiffuse {
                continue;
            }
            let mut r = Rng::new(169, 0);
            let mut nonzero = 0;
            for _ in 0..1000 {
                let a = crate::sampling::uniform_sphere(r.uniform2());
                let mut b = crate::sampling::uniform_sphere(r.uniform2());
                b.z = -b.z.abs() * a.z.signum();
                let (x, y) = (c.eval(a, b), c.eval(b, a));
                for (x, y) in x.to_array().into_iter().zip(y.to_array()) {
                    assert!((x - y).abs() <= 1e-4 * x.max(y) + 1e-6, "{x} vs {y}");
                }
                nonzero += (!x.is_black()) as usize;
            }
            assert!(nonzero > 500);
        }
    }
}

/// The sheen brightens grazing reflection of a dark base (the point of the layer), and its
/// scaling darkens the base at normal view by max(C) E(μ) at most.
#[test]
fn sheen_brightens_grazing_view_of_a_dark_base() {
    let dark = GltfParams {
        base: Rgb::splat(0.05),
        roughness: 0.8,
        ..gltf_params()
    };
    let velvet = GltfParams {
        layers: with_layers(|l| {
            l.sheen_color = Rgb::ONE;
            l.sheen_roughness = 0.3;
        }),
        ..dark
    };
    let albedo = |p: &GltfParams, theta: f32| {
        let (ls, n) = lobes(p);
        sampled_albedo(
            &Bsdf::from_gltf_lobes(&ls[..n]),
            dir(theta, 0.0),
            100_000,
            5,
        )
        .0[0]
    };
    assert!(albedo(&velvet, 1.4) > albedo(&dark, 1.4) + 0.05);
    assert!(albedo(&velvet, 0.0) >= albedo(&dark, 0.0) * 0.5);
}

/// The anisotropic lobe is stretched along its direction: a reflection seen along the
/// direction spreads wider there than across it, and turning the direction by 90° swaps the
/// two; strength 0 is the isotropic lobe, bit for bit.
#[test]
fn anisotropy_stretches_the_highlight_along_its_direction() {
    let lobe = |dir: [f32; 2], s: f32| {
        let p = GltfParams {
            metallic: 1.0,
            roughness: 0.3,
            layers: with_layers(|l| {
                l.anisotropy_strength = s;
                l.anisotropy_direction = dir;
            }),
            ..gltf_params()
        };
        let (ls, n) = lobes(&p);
        assert_eq!(n, 1);
        Bsdf::from_gltf_lobes(&ls[..n])
    };
    let wo = Vec3::Z;
    let off = |a: f32, b: f32| Vec3::new(a, b, 1.0).normalize();
    let along_x = lobe([1.0, 0.0], 1.0);
    let along_y = lobe([0.0, 1.0], 1.0);
    let (fx, fy) = (
        along_x.eval(wo, off(0.5, 0.0)).r,
        along_x.eval(wo, off(0.0, 0.5)).r,
    );
    assert!(fx > 3.0 * fy, "along {fx} across {fy}");
    let (gx, gy) = (
        along_y.eval(wo, off(0.5, 0.0)).r,
        along_y.eval(wo, off(0.0, 0.5)).r,
    );
    assert!((gx - fy).abs() < 1e-4 * fy && (gy - fx).abs() < 1e-4 * fx);
    let iso = Bsdf::from_gltf_lobes(
        &lobes(&GltfParams {
            metallic: 1.0,
            roughness: 0.3,
            ..gltf_params()
        })
        .0[..1],
    );
    let zero = lobe([0.3, 0.4], 0.0);
    for (a, b) in direction_pairs(500, 7) {
        assert!(same_rgb(zero.eval(a, b), iso.eval(a, b)));
    }
}
