//! The thin-lens camera (`flowlight_core::thin_lens`) in the integrators that start at the
//! camera:
//!
//! - **Focus and blur.** A small lamp on the plane in focus stays in one pixel; one at twice
//!   the distance in focus spreads into the circle of confusion c = 2R·|z − f_d|/z (scaled
//!   to the film), measured from the spot's second moment.
//! - **Pinhole limit.** As the aperture goes to 0 the image converges to the pinhole's: its
//!   distance to it falls to the noise floor of two pinhole renders; a zero aperture is the
//!   pinhole bit for bit.
//! - **Agreement.** BDPT, light tracing and VCM (eye connections through a sampled lens
//!   point), PSSMLT over MCPT and over BDPT and MMLT (the lens pair from the camera stream)
//!   and ERPT with Veach's perturbations (which keep the lens point) match MCPT under a lens
//!   on the Cornell box, per 8×8 region and in the image mean, and none moves towards the
//!   pinhole image; the perturbations keep detailed balance and the lens point on the glass
//!   caustic.
//!
//! Build the plugins first (`cargo build --workspace`).

use crate::common;

use common::{
    assert_image_mean, assert_regions_unbiased, independent_runs, quads_gltf, render,
    renderer_from, scene_config, table, toml_params, MeanRule,
};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_mcmc::measurement;
use flowlight_pathtrace::untangled;
use flowlight_scene::config::lens::{Aperture, Focus, LensKeys};
use flowlight_sdk::Stats;

/// A renderer of scene config `config` at 32×32 with `spp`, through `plugin` (its own
/// parameters dropped) or the config's integrator, with `params` and a lens of radius and
/// focus distance `lens`.
fn lens_renderer(
    config: &str,
    plugin: Option<&str>,
    spp: u32,
    params: &[(&str, toml::Value)],
    lens: Option<(f32, f32)>,
) -> Renderer {
    let mut cfg = flowlight_scene::config::load_config(&scene_config(config))
        .unwrap_or_else(|e| panic!("{e}"));
    cfg.width = 32;
    cfg.height = 32;
    if let Some(plugin) = plugin {
        cfg.integrator_plugin = plugin.to_string();
        cfg.integrator_params.clear();
    }
    if let Some((radius, focus)) = lens {
        let mut o = cfg.camera_override.clone().unwrap_or_default();
        o.lens = LensKeys {
            aperture: Some(Aperture::Radius(radius)),
            focus: Some(Focus::Distance(focus)),
        };
        cfg.camera_override = Some(o);
    }
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

/// A square lamp of half side `h` centred at (x, y, z), facing +Z.
fn lamp(x: f32, y: f32, z: f32, h: f32) -> [[f32; 3]; 4] {
    [
        [x - h, y - h, z],
        [x + h, y - h, z],
        [x + h, y + h, z],
        [x - h, y + h, z],
    ]
}

/// Luminance-weighted centroid, second central moment E[r²] (pixel centres) and the share
/// of the brightest pixel of the columns `cols` of a `w`-wide image.
fn spot(img: &[Rgb], w: usize, cols: std::ops::Range<usize>) -> (f64, f64, f64) {
    let px: Vec<(f64, f64, f64)> = img
        .iter()
        .enumerate()
        .filter(|(i, _)| cols.contains(&(i % w)))
        .map(|(i, c)| {
            (
                (i % w) as f64 + 0.5,
                (i / w) as f64 + 0.5,
                c.luminance() as f64,
            )
        })
        .collect();
    let total: f64 = px.iter().map(|p| p.2).sum();
    assert!(total > 0.0, "no light in columns {cols:?}");
    let cx = px.iter().map(|p| p.0 * p.2).sum::<f64>() / total;
    let cy = px.iter().map(|p| p.1 * p.2).sum::<f64>() / total;
    let r2 = px
        .iter()
        .map(|p| ((p.0 - cx).powi(2) + (p.1 - cy).powi(2)) * p.2)
        .sum::<f64>()
        / total;
    let brightest = px.iter().map(|p| p.2).fold(0.0, f64::max);
    (cx, r2, brightest / total)
}

/// Camera at z = 10 looking along −Z (40°, 64×64), lens radius 0.4 focused at 4. Lamp A
/// (half side 0.01) on the plane in focus at z = 6, lamp B (half side 0.1) at depth 8, z = 2.
#[test]
fn a_point_in_focus_is_sharp_and_one_out_of_focus_has_the_circle_of_confusion() {
    let (radius, focus, depth_b) = (0.4f32, 4.0f32, 8.0f32);
    let gltf = quads_gltf(
        &[
            lamp(-0.99, 0.03, 10.0 - focus, 0.01),
            lamp(1.456, 0.0, 10.0 - depth_b, 0.1),
        ],
        r#"{"emissiveFactor": [1, 1, 1]}"#,
        &[],
        "",
    );
    let body = |lens: &str| {
        format!(
            "[render]\nwidth = 64\nheight = 64\n[camera]\nposition = [0, 0, 10]\nlook_at = [0, 0, 0]\nfov_y = 40.0\n{lens}[integrator]\nplugin = \"mcpt\"\n"
        )
    };
    let lens = format!("aperture_radius = {radius}\nfocus_distance = {focus}\n");
    let img = render(&renderer_from("lens-spots", &gltf, &body(&lens), 256))
        .frame
        .image();
    // A: one pixel holds the whole spot (the lamp's image is 0.44 px wide, inside pixel 10).
    let (_, r2_a, share_a) = spot(&img, 64, 0..32);
    assert!(
        share_a > 0.999,
        "in focus: the brightest pixel holds {share_a}"
    );
    assert!(r2_a < 0.01, "in focus: E[r²] = {r2_a} px²");
    // B: the circle of confusion, from the second moment. Per axis the variances of the
    // blur disk (ρ²/4), the lamp's own pinhole image (side s: s²/12) and a pixel (1/12) add.
    let px_per_unit = 64.0 / (2.0 * focus * 20f32.to_radians().tan());
    let c_formula = 2.0 * radius * (depth_b - focus).abs() / depth_b * px_per_unit;
    let s = 0.2 * focus / depth_b * px_per_unit;
    let (cx, r2_b, _) = spot(&img, 64, 32..64);
    let rho2 = 2.0 * (r2_b - 2.0 * (s as f64).powi(2) / 12.0 - 2.0 / 12.0);
    let c_measured = 2.0 * rho2.sqrt();
    assert!(
        (c_measured / c_formula as f64 - 1.0).abs() < 0.05,
        "circle of confusion {c_measured:.3} px, thin-lens formula {c_formula:.3} px"
    );
    assert!((cx - 48.0).abs() < 0.3, "B's centre {cx}");
    // Through the pinhole both are sharp: B spreads only over its own image and the pixels.
    let pinhole = render(&renderer_from("lens-spots-pinhole", &gltf, &body(""), 64))
        .frame
        .image();
    let (_, r2_pin, _) = spot(&pinhole, 64, 32..64);
    let want = 2.0 * (s as f64).powi(2) / 12.0 + 2.0 / 12.0;
    assert!(
        (r2_pin - want).abs() < 0.25 * want,
        "pinhole: E[r²] {r2_pin} vs {want}"
    );
}

/// Mean absolute luminance difference per pixel.
fn distance(a: &[Rgb], b: &[Rgb]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.luminance() as f64 - y.luminance() as f64).abs())
        .sum::<f64>()
        / a.len() as f64
}

fn cornell(plugin: Option<&str>, spp: u32, seed: u64, lens: Option<(f32, f32)>) -> Vec<Rgb> {
    let mut s = lens_renderer("cornell-box/cornell-box.toml", plugin, spp, &[], lens);
    s.options.seed = seed;
    render(&s).frame.image()
}

#[test]
fn the_image_converges_to_the_pinhole_one_as_the_aperture_goes_to_zero() {
    let pinhole = cornell(None, 256, 2, None);
    let floor = distance(&cornell(None, 256, 1, None), &pinhole);
    let d: Vec<f64> = [0.1f32, 0.01, 1e-4]
        .iter()
        .map(|&r| distance(&cornell(None, 256, 3, Some((r, 1.3))), &pinhole))
        .collect();
    assert!(
        d[0] > 3.0 * floor,
        "R = 0.1: {} vs noise floor {floor}",
        d[0]
    );
    assert!(d[1] < d[0], "{d:?}");
    assert!(
        d[2] < 1.25 * floor,
        "R = 1e-4: {} vs noise floor {floor}",
        d[2]
    );
    // A zero aperture is the pinhole, bit for bit.
    assert_eq!(
        cornell(None, 16, 5, Some((0.0, 1.3))),
        cornell(None, 16, 5, None)
    );
}

/// Lens of the agreement tests: radius 15 cm focused at 1.3 (the back half of the box): the
/// box's front edges blur over 6 pixels.
const LENS: (f32, f32) = (0.15, 1.3);

fn cornell_lens_reference() -> &'static Vec<Rgb> {
    static REFERENCE: std::sync::OnceLock<Vec<Rgb>> = std::sync::OnceLock::new();
    REFERENCE.get_or_init(|| cornell(None, 1024, 77, Some(LENS)))
}

/// How far each of `images` moved from `reference` (the lens image) towards `pinhole`, in
/// units of the whole difference: s = Σ (img − ref)·(pin − ref) / Σ (pin − ref)², per run.
/// Regions are blind to a blur, which moves light by a few pixels; this projection is not:
/// an integrator that ignored the lens would give s ≈ 1. Returns the runs' mean and its
/// standard error.
fn towards_pinhole(images: &[Vec<Rgb>], reference: &[Rgb], pinhole: &[Rgb]) -> (f64, f64) {
    // Only the walls' pixels: the lamp's blurred edge (radiance 17), which light tracing
    // draws by the lamp's own connection, would outweigh them, and they are what the eye
    // connections of surface vertices draw. A pixel within 4 pixels of one at luminance ≥ 1
    // in the pinhole image is left out.
    let lum = |c: &Rgb| c.luminance() as f64;
    let w = 32i32;
    let near_lamp = |i: usize| {
        let (x, y) = (i as i32 % w, i as i32 / w);
        (-4..=4).any(|dy| {
            (-4..=4).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                (0..w).contains(&u)
                    && (0..w).contains(&v)
                    && lum(&pinhole[(v * w + u) as usize]) >= 1.0
            })
        })
    };
    let d: Vec<f64> = (0..pinhole.len())
        .map(|i| {
            if near_lamp(i) {
                0.0
            } else {
                lum(&pinhole[i]) - lum(&reference[i])
            }
        })
        .collect();
    let norm: f64 = d.iter().map(|x| x * x).sum();
    let s: Vec<f64> = images
        .iter()
        .map(|img| {
            img.iter()
                .zip(reference)
                .zip(&d)
                .map(|((i, r), d)| (lum(i) - lum(r)) * d)
                .sum::<f64>()
                / norm
        })
        .collect();
    let n = s.len() as f64;
    let m = s.iter().sum::<f64>() / n;
    let var = s.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

#[test]
fn bdpt_and_light_tracing_match_mcpt_under_a_thin_lens() {
    let reference = cornell_lens_reference();
    let pinhole = cornell(None, 1024, 78, None);
    let depth = [("path_depth", toml::Value::Integer(8))];
    for (plugin, spp, seed) in [("lighttrace", 16, 600), ("bdpt", 8, 500)] {
        let (images, _) = independent_runs(plugin, 12, seed, &|| {
            lens_renderer(
                "cornell-box/cornell-box.toml",
                Some(plugin),
                spp,
                &depth,
                Some(LENS),
            )
        });
        let label = format!("lens {plugin}");
        assert_regions_unbiased(&label, &images, reference);
        assert_image_mean(&label, &images, reference, MeanRule::Z(5.0));
        let (s, se) = towards_pinhole(&images, reference, &pinhole);
        assert!(
            s.abs() < 0.1 && s.abs() < 5.0 * se.max(0.004),
            "{label}: moved {s:.3} ± {se:.3} of the way to the pinhole image"
        );
    }
}

/// The primary-sample-space samplers draw the lens point from the camera stream's pair after
/// the raster position: PSSMLT over MCPT and over BDPT, short runs, against MCPT under a lens.
#[test]
fn pssmlt_matches_mcpt_under_a_thin_lens() {
    let reference = cornell_lens_reference();
    let pinhole = cornell(None, 1024, 78, None);
    for sampler in ["mcpt", "bdpt"] {
        let params = [
            ("path_depth", toml::Value::Integer(8)),
            ("bootstrap", toml::Value::Integer(256)),
            ("sampler", toml::Value::String(sampler.into())),
        ];
        let (images, _) = independent_runs(sampler, 16, 7000, &|| {
            lens_renderer(
                "cornell-box/cornell-box.toml",
                Some("pssmlt"),
                8,
                &params,
                Some(LENS),
            )
        });
        let label = format!("lens pssmlt/{sampler}");
        assert_image_mean(&label, &images, reference, MeanRule::Z(5.0));
        // 16 runs at 8 spp leave a standard error near 0.09 here, so 0.1 would sit one error
        // from failing; a renderer that ignored the lens moves about 0.84 (as MMLT's test shows).
        let (s, se) = towards_pinhole(&images, reference, &pinhole);
        assert!(
            s.abs() < 0.3 && s.abs() < 5.0 * se.max(0.004),
            "{label}: moved {s:.3} ± {se:.3} of the way to the pinhole image"
        );
    }
}

/// VCM's eye connections and its camera subpaths' vertices (merged with the photons) come
/// through the shared lens sampling: VCM under a lens against MCPT under it, as BDPT is
/// checked above.
#[test]
fn vcm_matches_mcpt_under_a_thin_lens() {
    let reference = cornell_lens_reference();
    let pinhole = cornell(None, 1024, 78, None);
    let depth = [("path_depth", toml::Value::Integer(8))];
    let (images, _) = independent_runs("vcm", 12, 800, &|| {
        lens_renderer(
            "cornell-box/cornell-box.toml",
            Some("vcm"),
            8,
            &depth,
            Some(LENS),
        )
    });
    let label = "lens vcm";
    assert_regions_unbiased(label, &images, reference);
    assert_image_mean(label, &images, reference, MeanRule::Z(5.0));
    let (s, se) = towards_pinhole(&images, reference, &pinhole);
    assert!(
        s.abs() < 0.1 && s.abs() < 5.0 * se.max(0.004),
        "{label}: moved {s:.3} ± {se:.3} of the way to the pinhole image"
    );
}

/// MMLT draws the lens point from its camera stream as PSSMLT does: short runs against MCPT
/// under a lens, as PSSMLT is checked above (at 64 spp, for the projection's noise).
#[test]
fn mmlt_matches_mcpt_under_a_thin_lens() {
    let reference = cornell_lens_reference();
    let pinhole = cornell(None, 1024, 78, None);
    let params = [
        ("path_depth", toml::Value::Integer(8)),
        ("bootstrap", toml::Value::Integer(256)),
    ];
    let (images, _) = independent_runs("mmlt", 16, 9000, &|| {
        lens_renderer(
            "cornell-box/cornell-box.toml",
            Some("mmlt"),
            64,
            &params,
            Some(LENS),
        )
    });
    let label = "lens mmlt";
    assert_image_mean(label, &images, reference, MeanRule::Z(5.0));
    // The Metropolis runs scatter in the projection (one MMLT run's s from −0.3 to 0.5 at
    // 64 spp; the mean's standard error 0.09 at 8 spp for MMLT and PSSMLT over MCPT alike,
    // 0.056 for MMLT at 64 spp), so the bound is 0.3 rather than 0.1: the same MMLT runs
    // without a lens move 0.836 ± 0.076, which it fails by far, and a correct lens passes it
    // at more than 5 standard errors.
    let (s, se) = towards_pinhole(&images, reference, &pinhole);
    assert!(
        s.abs() < 0.3 && s.abs() < 5.0 * se.max(0.004),
        "{label}: moved {s:.3} ± {se:.3} of the way to the pinhole image"
    );
}

/// `[[integrator.mutations]]` of (plugin, weight).
fn mutations(entries: &[(&str, f64)]) -> toml::Value {
    toml::Value::Array(
        entries
            .iter()
            .map(|(p, w)| {
                table(&[
                    ("plugin", toml::Value::String(p.to_string())),
                    ("weight", (*w).into()),
                ])
            })
            .collect(),
    )
}

fn perturbations() -> toml::Value {
    mutations(&[
        ("lens-perturbation", 0.4),
        ("caustic-perturbation", 0.2),
        ("multichain-perturbation", 0.2),
        ("hard-reconnection", 0.2),
    ])
}

#[test]
fn erpt_with_the_perturbations_matches_mcpt_under_a_thin_lens() {
    let params = [
        ("mutations", perturbations()),
        ("mutations_per_sample", 32.0.into()),
        ("chain_length", toml::Value::Integer(32)),
        ("film_window", toml::Value::Integer(8)),
    ];
    let (images, _) = independent_runs("lens erpt", 6, 3000, &|| {
        lens_renderer("cornell-box/erpt.toml", None, 4, &params, Some(LENS))
    });
    let reference = cornell_lens_reference();
    assert_regions_unbiased("lens erpt", &images, reference);
    assert_image_mean("lens erpt", &images, reference, MeanRule::Z(5.0));
}

/// On the glass caustic under a lens, every perturbation's proposal keeps the seed's lens
/// point, reports the ratio of its densities, and satisfies detailed balance; a path moved
/// to another lens point has density 0 under each.
#[test]
fn perturbations_keep_the_lens_point_and_detailed_balance() {
    let params = [("mutations", perturbations())];
    let s = lens_renderer(
        "glass-caustic/erpt.toml",
        None,
        1,
        &params,
        Some((0.05, 3.0)),
    );
    let set = s.instance.mutation_set();
    let moves = common::with_seed_sampler(&s, |scene, tracer, mut settings| {
        assert!(scene.camera.has_lens());
        settings.path_depth = 10;
        let mut rng = Rng::new(31, 2);
        let (mut x, mut y) = (Box::new(Path::empty()), Box::new(Path::empty()));
        let mut moves = vec![0usize; set.len()];
        for _ in 0..10000 {
            let raster = glam::Vec2::new(rng.uniform(), rng.uniform()) * 32.0;
            let sample = untangled::trace(scene, tracer, &settings, &mut rng, raster, Some(&mut x));
            if sample.value.is_black() || x.vertex_count < 3 {
                continue;
            }
            x.film_window = 8;
            let f_x = measurement(scene, &x).luminance() as f64;
            // NaN counts as no energy.
            if f_x.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            for (i, count) in moves.iter_mut().enumerate() {
                let p = set
                    .propose(i, tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))
                    .unwrap();
                if !p.is_move() {
                    continue;
                }
                let what = format!("{}: {} → {}", set.name(i), x.heckbert(), y.heckbert());
                assert_eq!(
                    x.vertices()[0].p,
                    y.vertices()[0].p,
                    "{what}: lens point moved"
                );
                let forward = set.density(i, &x, &y).unwrap();
                let reverse = set.density(i, &y, &x).unwrap();
                assert!(forward > 0.0, "{what}: T(x→y) = {forward}");
                let got = p.transition_ratio().unwrap() as f64;
                let expected = reverse / forward;
                assert!(
                    (got - expected).abs() <= 2e-3 * expected.max(got) + 1e-30,
                    "{what}: ratio {got}, densities {expected}"
                );
                let f_y = measurement(scene, &y).luminance() as f64;
                if expected > 0.0 && f_y > 0.0 {
                    let a_xy = (f_y / f_x * got).min(1.0);
                    let a_yx = (f_x / f_y / got).min(1.0);
                    let (lhs, rhs) = (f_x * forward * a_xy, f_y * reverse * a_yx);
                    assert!(
                        (lhs - rhs).abs() <= 3e-3 * lhs.max(rhs),
                        "{what}: {lhs} vs {rhs}"
                    );
                    *count += 1;
                }
                // The same proposal seen from another lens point cannot be made.
                let mut shifted = *y;
                shifted.vertices[0].p += scene.camera.right * 0.01;
                assert_eq!(set.density(i, &x, &shifted).unwrap(), 0.0, "{what}");
            }
        }
        moves
    });
    for (i, n) in moves.iter().enumerate() {
        assert!(*n >= 20, "{}: only {n} balanced moves", set.name(i));
    }
}
