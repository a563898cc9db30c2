//! Analytic checks of every light type through the whole renderer (synthetic glTF scenes, both
//! MCPT variants), and ERPT against MCPT under a point light (ERPT under lights at infinity:
//! `tests/integration/erpt.rs`).
//!
//! The surface is a Lambert floor (albedo ½, KHR_materials_specular factor 0: the spec's purely
//! diffuse material) seen from above. Direct lighting by a delta light is noise-free (one light, one
//! connection), so those images are compared per pixel against the analytic radiance
//! averaged over each pixel's footprint:
//!
//! - point light of intensity I cd: L = ρ/π · (I/683) cos θ / r² (683 lm/W: glTF's photometric
//!   units to radiometric);
//! - spot light: the same times the spec's cone fall-off (computed here independently);
//! - directional light of illuminance E lx at incidence θ: L = ρ/π · (E/683) cos θ;
//! - constant environment of radiance L_env over the open floor: L = ρ · L_env (and L_env
//!   where the camera sees the sky).

use crate::common;

use common::{mean_and_stderr, quads_gltf, render, renderer_from, FLOOR, LAMBERT};
use flowlight_core::Rgb;
use flowlight_host::renderer::Renderer;
use glam::{Vec2, Vec3};

const ALBEDO: f64 = 0.5;
/// glTF's photometric units (cd, lx) per radiometric unit (W/sr, W/m²): the loader divides by it.
const LUMENS_PER_WATT: f64 = 683.0;

/// A wall at z = −1 facing +Z.
const WALL: [[f32; 3]; 4] = [
    [-10.0, 0.0, -1.0],
    [10.0, 0.0, -1.0],
    [10.0, 10.0, -1.0],
    [-10.0, 10.0, -1.0],
];

/// Config text looking down at the floor from (0.3, 4, 0.2).
fn config(variant: &str, depth: u32, tail: &str) -> String {
    format!(
        r#"[render]
width = 24
height = 24
seed = 3
intersector = "bvh"
[camera]
position = [0.3, 4.0, 0.2]
look_at = [0.3, 0.0, 0.2]
up = [0.0, 0.0, -1.0]
fov_y = 50.0
[integrator]
plugin = "mcpt"
variant = "{variant}"
path_depth = {depth}
{tail}"#
    )
}

/// Per pixel, the mean of `radiance(p)` over an 8×8 grid of the pixel's footprint on the
/// floor y = 0 (0 where the ray misses it).
fn expected_image(s: &Renderer, radiance: impl Fn(Vec3) -> f64) -> Vec<f64> {
    let cam = s.camera;
    let mut out = Vec::new();
    for y in 0..cam.height {
        for x in 0..cam.width {
            let mut sum = 0.0;
            for i in 0..8 {
                for j in 0..8 {
                    let r = Vec2::new(
                        x as f32 + (i as f32 + 0.5) / 8.0,
                        y as f32 + (j as f32 + 0.5) / 8.0,
                    );
                    let ray = cam.generate_ray(r);
                    if ray.dir.y < 0.0 {
                        let t = -ray.origin.y / ray.dir.y;
                        sum += radiance(ray.at(t));
                    }
                }
            }
            out.push(sum / 64.0);
        }
    }
    out
}

/// Renders `s` and compares each pixel's red channel with `expected` (relative `tol` where
/// the expected value is above 10% of the maximum, absolute elsewhere) and the image means.
fn compare(label: &str, s: &Renderer, expected: &[f64], tol: f64) {
    let out = render(s);
    assert_eq!(out.stats.invalid_deposits, 0, "{label}: invalid samples");
    let img = out.frame.image();
    let max = expected.iter().cloned().fold(0.0, f64::max);
    if std::env::var("LIGHTS_DEBUG").is_ok() {
        for y in 0..24 {
            let row: Vec<String> = (0..24)
                .map(|x| {
                    format!(
                        "{:4.2}",
                        img[y * 24 + x].r as f64 / expected[y * 24 + x].max(1e-9)
                    )
                })
                .collect();
            eprintln!("{}", row.join(" "));
        }
    }
    assert!(max > 0.0, "{label}: the analytic image is black");
    for (k, (c, e)) in img.iter().zip(expected).enumerate() {
        let got = c.r as f64;
        let err = (got - e).abs();
        // Relative where the image is bright, absolute (relative to a tenth of the maximum)
        // in its dim tails, where the pixel-footprint jitter of steep fall-offs dominates.
        let ok = err <= tol * e.max(0.1 * max);
        assert!(ok, "{label}: pixel {k}: rendered {got:.6}, analytic {e:.6}");
    }
    let mean = img.iter().map(|c| c.r as f64).sum::<f64>() / img.len() as f64;
    let want = expected.iter().sum::<f64>() / expected.len() as f64;
    assert!(
        (mean / want - 1.0).abs() < tol / 3.0,
        "{label}: image mean {mean:.6}, analytic {want:.6}"
    );
}

fn light_node(light: usize, translation: [f32; 3], rotation: [f32; 4]) -> String {
    format!(
        r#"{{"translation": {translation:?}, "rotation": {rotation:?}, "extensions": {{"KHR_lights_punctual": {{"light": {light}}}}}}}"#
    )
}

/// Quaternion (x, y, z, w) turning −Z towards −Y and then tilting it by `tilt` degrees
/// towards −Z: a rotation about +X by −(90° − tilt).
fn down_tilted(tilt: f32) -> [f32; 4] {
    let a = -(90.0 - tilt).to_radians();
    [(a / 2.0).sin(), 0.0, 0.0, (a / 2.0).cos()]
}

#[test]
fn point_light_over_a_lambert_plane_gives_i_cos_over_r2() {
    let light = Vec3::new(0.2, 2.0, -0.1);
    let intensity = 10.0;
    let gltf = quads_gltf(
        &[FLOOR],
        LAMBERT,
        &[light_node(0, light.to_array(), [0.0, 0.0, 0.0, 1.0])],
        r#"[{"type": "point", "intensity": 10.0, "color": [1.0, 1.0, 1.0], "range": 100.0}]"#,
    );
    for variant in ["entangled", "untangled"] {
        let s = renderer_from(
            &format!("point-{variant}"),
            &gltf,
            &config(variant, 1, ""),
            64,
        );
        let expected = expected_image(&s, |p| {
            let d = (light - p).as_dvec3();
            let r2 = d.length_squared();
            let cos = d.y / r2.sqrt();
            ALBEDO / std::f64::consts::PI * (intensity / LUMENS_PER_WATT) * cos / r2
        });
        compare(&format!("point/{variant}"), &s, &expected, 0.02);
    }
}

#[test]
fn directional_light_gives_lux_cos_theta() {
    let lux = 3.0;
    let tilt: f64 = 30.0;
    let gltf = quads_gltf(
        &[FLOOR],
        LAMBERT,
        &[light_node(0, [5.0, 7.0, 1.0], down_tilted(tilt as f32))],
        r#"[{"type": "directional", "intensity": 3.0, "color": [1.0, 0.5, 0.25]}]"#,
    );
    for variant in ["entangled", "untangled"] {
        let s = renderer_from(&format!("dir-{variant}"), &gltf, &config(variant, 1, ""), 8);
        let want =
            ALBEDO / std::f64::consts::PI * (lux / LUMENS_PER_WATT) * tilt.to_radians().cos();
        let expected = expected_image(&s, |_| want);
        compare(&format!("directional/{variant}"), &s, &expected, 0.01);
        // The colour scales each channel.
        let img = render(&s).frame.image();
        let c = img[img.len() / 2];
        assert!(
            (c.g / c.r - 0.5).abs() < 1e-3 && (c.b / c.r - 0.25).abs() < 1e-3,
            "{c:?}"
        );
    }
}

#[test]
fn spot_light_falls_off_between_its_cones() {
    let light = Vec3::new(0.3, 2.0, 0.2);
    let (inner, outer) = (10f64.to_radians(), 25f64.to_radians());
    let intensity = 20.0;
    let gltf = quads_gltf(
        &[FLOOR],
        LAMBERT,
        &[light_node(0, light.to_array(), down_tilted(0.0))],
        &format!(
            r#"[{{"type": "spot", "intensity": {intensity}, "spot": {{"innerConeAngle": {inner}, "outerConeAngle": {outer}}}}}]"#
        ),
    );
    for variant in ["entangled", "untangled"] {
        let s = renderer_from(
            &format!("spot-{variant}"),
            &gltf,
            &config(variant, 1, ""),
            256,
        );
        let expected = expected_image(&s, |p| {
            let d = (light - p).as_dvec3();
            let r2 = d.length_squared();
            let cos = d.y / r2.sqrt();
            // Angle from the spot axis (straight down) is the incidence angle here.
            let t = ((cos - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0);
            ALBEDO / std::f64::consts::PI * (intensity / LUMENS_PER_WATT) * t * t * cos / r2
        });
        // Inside the inner cone, outside the outer one, and in between, the image has pixels.
        let max = expected.iter().cloned().fold(0.0, f64::max);
        assert!(expected.contains(&0.0));
        assert!(expected.iter().any(|&e| e > 0.1 * max && e < 0.6 * max));
        // Inside a pixel the cone edge changes the irradiance by up to ~25%: 256 jittered
        // samples leave up to ~8% of noise in pixels on the cone edges (the falloff curve
        // itself is checked exactly in flowlight-core; a linear instead of a squared ramp
        // would be off by 100% mid-cone).
        compare(&format!("spot/{variant}"), &s, &expected, 0.1);
    }
}

#[test]
fn constant_environment_over_an_open_plane_gives_albedo_times_sky() {
    let gltf = quads_gltf(&[FLOOR], LAMBERT, &[], "");
    let sky = 2.0;
    for (variant, depth, spp) in [
        ("entangled", 1, 64),
        ("entangled", 3, 512),
        ("untangled", 2, 1024),
    ] {
        let s = renderer_from(
            &format!("env-{variant}-{depth}"),
            &gltf,
            &config(
                variant,
                depth,
                "[environment]\ncolor = [1.0, 1.0, 1.0]\nstrength = 2.0\n",
            ),
            spp,
        );
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0);
        let img = out.frame.image();
        let (mean, se) = mean_and_stderr(&img, |c| c.g);
        let want = ALBEDO * sky;
        assert!(
            (mean / want - 1.0).abs() < 0.01 && se / want < 0.0033,
            "{variant}/{depth}: mean {mean:.5} ± {se:.5}, want {want}"
        );
    }
    // Looking up, the camera sees the sky itself.
    let up = config("entangled", 1, "[environment]\ncolor = [0.5, 1.0, 2.0]\n")
        .replace("look_at = [0.3, 0.0, 0.2]", "look_at = [0.3, 8.0, 0.2]");
    let s = renderer_from("env-up", &gltf, &up, 2);
    let img = render(&s).frame.image();
    assert!(img.iter().all(|c| *c == Rgb::new(0.5, 1.0, 2.0)));
}

#[test]
fn a_scene_without_light_renders_with_one_warning() {
    let gltf = quads_gltf(&[FLOOR], LAMBERT, &[], "");
    let s = renderer_from("no-light", &gltf, &config("entangled", 2, ""), 2);
    let img = render(&s).frame.image();
    assert!(img.iter().all(|c| c.is_black()));
    // The command line says so, once, and still succeeds.
    let dir = common::scratch("no-light-cli");
    std::fs::write(dir.join("scene.gltf"), &gltf).unwrap();
    let cfg = dir.join("scene.toml");
    std::fs::write(
        &cfg,
        format!("scene = \"scene.gltf\"\n{}", config("entangled", 1, "")),
    )
    .unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["render", cfg.to_str().unwrap(), "--spp", "1", "-q"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert_eq!(stderr.matches("has no light").count(), 1, "{stderr}");
    // With a light, no such line.
    std::fs::write(
        &cfg,
        format!(
            "scene = \"scene.gltf\"\n{}",
            config("entangled", 1, "[environment]\ncolor = [1.0, 1.0, 1.0]\n")
        ),
    )
    .unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["render", cfg.to_str().unwrap(), "--spp", "1", "-q"])
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&o.stderr).contains("has no light"));
}

#[test]
fn erpt_agrees_with_mcpt_under_a_point_light() {
    // Floor and wall: direct light and one-bounce indirect light from a point light.
    let gltf = quads_gltf(
        &[FLOOR, WALL],
        LAMBERT,
        &[light_node(0, [0.3, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0])],
        r#"[{"type": "point", "intensity": 4.0}]"#,
    );
    let head = r#"[render]
width = 32
height = 32
seed = 5
tile_size = 16
intersector = "bvh"
[camera]
position = [0.0, 2.0, 3.0]
look_at = [0.0, 0.5, -1.0]
fov_y = 60.0
"#;
    let mcpt =
        format!("{head}[integrator]\nplugin = \"mcpt\"\nvariant = \"entangled\"\npath_depth = 3\n");
    let reference = render(&renderer_from("erpt-ref", &gltf, &mcpt, 512))
        .frame
        .image();
    let ref_mean = reference.iter().map(|c| c.luminance() as f64).sum::<f64>() / 1024.0;
    let erpt = format!(
        r#"{head}[integrator]
plugin = "erpt"
path_depth = 3
mutations_per_sample = 32
chain_length = 32
film_window = 8
[[integrator.mutations]]
plugin = "hard-reconnection"
weight = 0.4
[[integrator.mutations]]
plugin = "blow"
weight = 0.3
[[integrator.mutations]]
plugin = "drill"
width = "wide"
weight = 0.3
"#
    );
    let mut means = Vec::new();
    for run in 0..4 {
        let mut s = renderer_from(&format!("erpt-{run}"), &gltf, &erpt, 4);
        s.options.seed = 100 + run;
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0);
        let img = out.frame.image();
        means.push(img.iter().map(|c| c.luminance() as f64).sum::<f64>() / 1024.0);
    }
    let m = means.iter().sum::<f64>() / means.len() as f64;
    assert!(
        (m / ref_mean - 1.0).abs() < 0.03,
        "ERPT mean {m:.5} (runs {means:?}) vs MCPT {ref_mean:.5}"
    );
}

#[test]
fn mutations_never_move_a_point_light_vertex_and_keep_detailed_balance() {
    use flowlight_core::path::{NodeType, Path};
    use flowlight_core::rng::Rng;
    use flowlight_host::intersector::UnitTracer;
    use flowlight_pathtrace::{untangled, PathSettings, Variant};
    use flowlight_sdk::{Scene, Stats, Tracer};

    let light = Vec3::new(0.3, 1.0, 0.0);
    let gltf = quads_gltf(
        &[FLOOR, WALL],
        LAMBERT,
        &[light_node(0, light.to_array(), [0.0, 0.0, 0.0, 1.0])],
        r#"[{"type": "point", "intensity": 4.0}]"#,
    );
    let cfg = r#"[render]
width = 32
height = 32
intersector = "bvh"
[camera]
position = [0.0, 2.0, 3.0]
look_at = [0.0, 0.5, -1.0]
fov_y = 60.0
[integrator]
plugin = "erpt"
[[integrator.mutations]]
plugin = "hard-reconnection"
[[integrator.mutations]]
plugin = "soft-reconnection"
cap_degrees = 8.0
[[integrator.mutations]]
plugin = "bxdf-extension"
[[integrator.mutations]]
plugin = "blow"
[[integrator.mutations]]
plugin = "drill"
width = "wide"
"#;
    let s = renderer_from("erpt-balance", &gltf, cfg, 1);
    let set = s.instance.mutation_set();
    // SAFETY: the renderer keeps the view's data alive.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    let mut unit_tracer = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let mut settings = PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[])).unwrap();
    settings.variant = Variant::Untangled;
    settings.path_depth = 4;
    let mut rng = Rng::new(21, 5);
    let mut x = Box::new(Path::empty());
    let mut y = Box::new(Path::empty());
    let mut valid = vec![0usize; set.len()];
    for _ in 0..3000 {
        let raster = Vec2::new(rng.uniform() * 32.0, rng.uniform() * 32.0);
        let sample = untangled::trace(&scene, &tracer, &settings, &mut rng, raster, Some(&mut x));
        if sample.value.is_black() {
            continue;
        }
        let n = x.vertex_count as usize - 1;
        // Every seed ends on the point light, at its position.
        assert_eq!(x.vertices[n].node, NodeType::Light);
        assert_eq!(x.vertices[n].p, light);
        x.film_window = 8;
        for (i, count) in valid.iter_mut().enumerate() {
            let p = set
                .propose(i, &tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))
                .unwrap();
            if !p.is_move() {
                continue;
            }
            assert_eq!(
                y.vertices[n].p,
                light,
                "{} moved the point light's vertex",
                set.name(i)
            );
            let forward = set.density(i, &x, &y).unwrap();
            let reverse = set.density(i, &y, &x).unwrap();
            assert!(forward > 0.0, "{}", set.name(i));
            let expected = reverse / forward;
            let got = p.transition_ratio().unwrap() as f64;
            assert!(
                (got - expected).abs() <= 2e-3 * expected.max(got) + 1e-30,
                "{}: ratio {got} vs {expected}",
                set.name(i)
            );
            *count += 1;
        }
    }
    // Strategies that end in a reconnection make valid proposals; pure extensions can never
    // land on a point, so they may not.
    assert!(valid[0] > 100, "hard reconnection: {valid:?}");
}

/// A scene whose only light carries no power — a lamp switched off in Blender (intensity 0),
/// a black lamp, a spot whose cone is closed to nothing — renders black with every
/// integrator, says so in one warning that names the cause, and does not crash: the light
/// tables given to the plugins hold one CDF entry per light even then.
#[test]
fn d1_switched_off_only_light_renders_black() {
    let dir = common::scratch("d1-dark-lights");
    let dark_lights = [
        (
            "off",
            r#"[{"type": "point", "intensity": 0.0, "color": [1.0, 1.0, 1.0]}]"#,
        ),
        (
            "black",
            r#"[{"type": "point", "intensity": 10.0, "color": [0.0, 0.0, 0.0]}]"#,
        ),
        (
            "closed-spot",
            r#"[{"type": "spot", "intensity": 10.0, "spot": {"innerConeAngle": 0.0, "outerConeAngle": 1e-30}}]"#,
        ),
    ];
    for (name, lights) in dark_lights {
        let gltf = quads_gltf(
            &[FLOOR],
            LAMBERT,
            &[light_node(0, [0.2, 2.0, -0.1], down_tilted(0.0))],
            lights,
        );
        let scene = dir.join(format!("{name}.gltf"));
        std::fs::write(&scene, gltf).unwrap();
        for integrator in [
            "plugin = \"mcpt\"\nvariant = \"entangled\"",
            "plugin = \"mcpt\"\nvariant = \"untangled\"",
            "plugin = \"erpt\"",
        ] {
            let cfg = dir.join(format!("{name}.toml"));
            let mut body = config("entangled", 2, "")
                .replace("plugin = \"mcpt\"\nvariant = \"entangled\"", integrator);
            if integrator.contains("erpt") {
                body += "\n[[integrator.mutations]]\nplugin = \"blow\"\n";
            }
            std::fs::write(&cfg, format!("scene = \"{name}.gltf\"\n{body}")).unwrap();
            let out = dir.join(format!("{name}.exr"));
            let o = std::process::Command::new(env!("CARGO_BIN_EXE_flowlight"))
                .args(["render", cfg.to_str().unwrap(), "--spp", "2", "-q", "--out"])
                .arg(&out)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert!(o.status.success(), "{name} / {integrator}: {o:?}\n{stderr}");
            assert_eq!(
                stderr.matches("carry no power").count(),
                1,
                "{name} / {integrator}: {stderr}"
            );
            assert!(!stderr.contains("has no light"), "{stderr}");
            let (_, _, layers) = flowlight_host::output::read_exr_rgb(&out).unwrap();
            assert!(
                layers[0].1.iter().all(|c| c.is_black()),
                "{name} / {integrator}"
            );
        }
    }
}
