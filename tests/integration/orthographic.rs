//! Orthographic cameras through the renderer: the image of an emitter has its exact extent,
//! every ERPT mutation keeps the eye vertex on the film plane where its raster position
//! puts it, and ERPT agrees with path tracing through an orthographic view.

use crate::common;

use common::{mean_and_stderr, render, toml_params};
use flowlight_core::camera::{Camera, Projection};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_host::intersector::UnitTracer;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_pathtrace::{untangled, PathSettings, Variant};
use flowlight_scene::config::load_config;
use flowlight_sdk::{Scene, Stats, Tracer};
use glam::Vec3;

/// A renderer of `config` at `w`×`h` through an orthographic camera with the config's (or
/// the file's) placement and `ortho_height`.
fn ortho_renderer(
    config: &std::path::Path,
    w: u32,
    h: u32,
    spp: u32,
    ortho_height: f32,
    params: &[(&str, toml::Value)],
) -> Renderer {
    let mut cfg = load_config(config).unwrap_or_else(|e| panic!("{e}"));
    cfg.width = w;
    cfg.height = h;
    let mut cam = cfg.camera_override.clone().unwrap_or_default();
    cam.projection = Some(Projection::Orthographic);
    cam.ortho_height = Some(ortho_height);
    cam.fov_y = None;
    cfg.camera_override = Some(cam);
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    assert_eq!(s.camera.kind(), Projection::Orthographic);
    s
}

#[test]
fn the_image_of_an_emitter_has_its_orthographic_extent() {
    // An emitting quad [−1, 1]² in z = 0 (radiance 1 towards +Z), seen along −Z from z = 5
    // with a view 4 high on a 16×16 film: x ∈ [−2, 2] ↦ [0, 16], so the quad covers pixels
    // 4…11 exactly, at any distance (a pinhole at z = 5 with the same view at z = 0 would
    // see it grow as it approaches).
    let dir = common::scratch("ortho-quad");
    common::emitting_square(&dir);
    for z in [5.0f32, 1.5] {
        let cfg = dir.join("q.toml");
        std::fs::write(
            &cfg,
            format!("scene = \"q.gltf\"\n[camera]\nposition = [0.0, 0.0, {z}]\nforward = [0.0, 0.0, -1.0]\n[integrator]\nplugin = \"mcpt\"\n"),
        )
        .unwrap();
        let s = ortho_renderer(&cfg, 16, 16, 4, 4.0, &[]);
        let img = render(&s).frame.image();
        for y in 0..16 {
            for x in 0..16 {
                let inside = (4..12).contains(&x) && (4..12).contains(&y);
                let l = img[y * 16 + x].luminance();
                assert!(
                    (l - if inside { 1.0 } else { 0.0 }).abs() < 1e-4,
                    "z {z}: pixel ({x}, {y}) = {l}"
                );
            }
        }
    }
}

fn mutations(plugins: &[(&str, &[(&str, &str)])]) -> toml::Value {
    toml::Value::Array(
        plugins
            .iter()
            .map(|(p, extra)| {
                let mut t = toml::Table::new();
                t.insert("plugin".into(), toml::Value::String(p.to_string()));
                for (k, v) in *extra {
                    t.insert(k.to_string(), toml::Value::String(v.to_string()));
                }
                toml::Value::Table(t)
            })
            .collect(),
    )
}

const STRATEGIES: &[(&str, &[(&str, &str)])] = &[
    ("hard-reconnection", &[]),
    ("bxdf-extension", &[]),
    ("blow", &[("width", "wide")]),
    ("drill", &[("width", "narrow")]),
];

#[test]
fn every_mutation_keeps_the_eye_vertex_on_the_orthographic_film() {
    let s = ortho_renderer(
        &common::scene_config("cornell-box/erpt.toml"),
        48,
        48,
        1,
        0.6,
        &[("mutations", mutations(STRATEGIES))],
    );
    let camera: Camera = s.camera;
    let set = s.instance.mutation_set();
    // SAFETY: the renderer keeps the view's data alive.
    let scene = unsafe { Scene::from_view(s.instance.view()) };
    let mut unit_tracer = UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let mut settings = PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[])).unwrap();
    settings.variant = Variant::Untangled;
    let mut rng = Rng::new(5, 9);
    let mut x = Box::new(Path::empty());
    let mut y = Box::new(Path::empty());
    let near = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
    let mut moved = vec![0usize; set.len()];
    for _ in 0..1500 {
        let raster = glam::Vec2::new(rng.uniform() * 48.0, rng.uniform() * 48.0);
        let sample = untangled::trace(&scene, &tracer, &settings, &mut rng, raster, Some(&mut x));
        if sample.value.is_black() || x.vertex_count < 3 {
            continue;
        }
        let x_eye = x.vertices()[0].p;
        assert!(near(x_eye, camera.eye_point(x.raster)), "{x_eye}");
        x.film_window = 8;
        for (i, count) in moved.iter_mut().enumerate() {
            let p = set
                .propose(i, &tracer, &mut rng, &x, &mut y, &mut Stats::new(&mut []))
                .unwrap();
            if !p.is_move() {
                continue;
            }
            let y_eye = y.vertices()[0].p;
            assert!(
                near(y_eye, camera.eye_point(y.raster)),
                "{}: eye {y_eye} for raster {} (film point {})",
                set.name(i),
                y.raster,
                camera.eye_point(y.raster)
            );
            // The eye ray of y is the camera ray of its raster position: y₁ lies on it.
            let to_y1 = (y.vertices()[1].p - y_eye).normalize();
            assert!(to_y1.dot(camera.forward) > 1.0 - 1e-4, "{}", set.name(i));
            if y.raster != x.raster {
                *count += 1;
            }
        }
    }
    for (i, c) in moved.iter().enumerate() {
        assert!(
            *c > 50,
            "{}: only {c} proposals moved on the film",
            set.name(i)
        );
    }
}

#[test]
fn erpt_agrees_with_path_tracing_through_an_orthographic_camera() {
    let config = common::scene_config("cornell-box/erpt.toml");
    let mcpt = ortho_renderer(
        &common::scene_config("cornell-box/cornell-box.toml"),
        32,
        32,
        512,
        0.6,
        &[],
    );
    let reference = render(&mcpt).frame.image();
    let (ref_mean, ref_se) = mean_and_stderr(&reference, |c| c.luminance());
    let mut means = Vec::new();
    for seed in 0..6 {
        let mut s = ortho_renderer(
            &config,
            32,
            32,
            8,
            0.6,
            &[
                ("mutations_per_sample", 16.0.into()),
                ("chain_length", toml::Value::Integer(16)),
            ],
        );
        s.options.seed = 500 + seed;
        s.options.tile_size = 16;
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0);
        let img = out.frame.image();
        means.push(mean_and_stderr(&img, |c| c.luminance()).0);
    }
    let n = means.len() as f64;
    let m = means.iter().sum::<f64>() / n;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    let se = (var / n + ref_se * ref_se).sqrt();
    let z = (m - ref_mean) / se;
    assert!(
        z.abs() < 4.0 && (m / ref_mean - 1.0).abs() < 0.05,
        "ERPT mean {m:.5} ({means:?}) vs path tracing {ref_mean:.5} ± {ref_se:.5}: z = {z:.2}"
    );
}
