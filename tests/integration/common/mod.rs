//! Helpers shared by the integration tests. Plugins must have been built first
//! (`cargo build --workspace`, as `.ci/run` does); the host finds them next to the test
//! executable's parent directory (`target/<profile>/`).
#![allow(dead_code)]

use flowlight_core::Rgb;
use flowlight_host::error::HostError;
use flowlight_host::render::RenderOutcome;
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_host::PluginError;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

// Not every test file uses both.
#[allow(unused_imports)]
pub use flowlight_testkit::gltf::{InTempDir, TempDir};

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn scene_config(rel: &str) -> PathBuf {
    repo().join("scenes").join(rel)
}

/// A fresh scratch directory under the system temp dir, removed when dropped (unless the
/// test fails). Numbered, because all the tests share one process and two of them may pick
/// the same name.
pub fn scratch(name: &str) -> TempDir {
    static N: AtomicUsize = AtomicUsize::new(0);
    TempDir::new(&format!(
        "flowlight-test-{}-{}-{name}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}

/// What `plugin` said when it refused to prepare a `Renderer` (its `create`, or the host checking the
/// parameters it declares): the message of the [`PluginError::Call`]. Panics, naming the
/// error, on any other error.
pub fn plugin_refusal<'e>(e: &'e HostError, plugin: &str) -> &'e str {
    if let HostError::Plugin { error, .. } = e {
        if let PluginError::Call { name, message, .. } = error.as_ref() {
            if name == plugin {
                return message;
            }
        }
    }
    panic!("not a refusal by plugin '{plugin}': {e:?}")
}

pub fn toml_params(pairs: &[(&str, toml::Value)]) -> Vec<(String, toml::Value)> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// Prepares a renderer for a scene config with integrator parameter overrides and no outputs.
pub fn renderer(config: &str, spp: u32, params: &[(&str, toml::Value)]) -> Renderer {
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Renderer::prepare(&scene_config(config), &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

/// Like [`renderer`], at another resolution.
pub fn renderer_at(
    config: &str,
    width: u32,
    height: u32,
    spp: u32,
    params: &[(&str, toml::Value)],
) -> Renderer {
    renderer_with(config, None, (width, height), spp, params)
}

/// Like [`renderer_at`]; with `plugin`, the config's integrator is replaced by that plugin
/// with `params` alone (the config's own parameters are another plugin's).
pub fn renderer_with(
    config: &str,
    plugin: Option<&str>,
    (width, height): (u32, u32),
    spp: u32,
    params: &[(&str, toml::Value)],
) -> Renderer {
    let mut cfg = flowlight_scene::config::load_config(&scene_config(config))
        .unwrap_or_else(|e| panic!("{e}"));
    cfg.width = width;
    cfg.height = height;
    if let Some(plugin) = plugin {
        cfg.integrator_plugin = plugin.to_string();
        cfg.integrator_params.clear();
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

pub fn render(s: &Renderer) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let out = s.render(&stop, &|_| {}).unwrap();
    if let Some(e) = &out.error {
        panic!("render failed: {e}");
    }
    out
}

/// Mean luminance and its standard error over the pixels of `img` (pixels are independent).
pub fn mean_and_stderr(img: &[Rgb], f: impl Fn(Rgb) -> f32) -> (f64, f64) {
    let n = img.len() as f64;
    let mean = img.iter().map(|&c| f(c) as f64).sum::<f64>() / n;
    let var = img
        .iter()
        .map(|&c| (f(c) as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// The glTF builders of the conformance kit (one writer for every test).
#[allow(unused_imports)]
pub use flowlight_testkit::gltf::{base64, emitting_square, quads_gltf};

/// Writes `gltf` and a config (`body` is everything after the `scene =` line) into a scratch
/// folder and prepares a renderer with `spp` samples and no outputs.
pub fn renderer_from(name: &str, gltf: &str, body: &str, spp: u32) -> Renderer {
    let dir = scratch(name);
    std::fs::write(dir.join("scene.gltf"), gltf).unwrap();
    let cfg = dir.join("scene.toml");
    std::fs::write(&cfg, format!("scene = \"scene.gltf\"\n{body}")).unwrap();
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        ..Default::default()
    };
    let mut s = Renderer::prepare(&cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s
}

/// A Lambertian white of albedo ½ (glTF: metallic 0, roughness 1, and no specular layer, as
/// `KHR_materials_specular.specularFactor = 0` defines it), for scenes with a known answer.
pub const LAMBERT: &str = r#"{"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}, "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}}"#;

/// A 20 × 20 floor quad at y = 0 facing +Y, centred on the origin.
pub const FLOOR: [[f32; 3]; 4] = [
    [-10.0, 0.0, -10.0],
    [-10.0, 0.0, 10.0],
    [10.0, 0.0, 10.0],
    [10.0, 0.0, -10.0],
];

/// A TOML table of `pairs`.
pub fn table(pairs: &[(&str, toml::Value)]) -> toml::Value {
    toml::Value::Table(
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect(),
    )
}

/// `[[integrator.mutations]]` with one entry per (plugin, extra params).
pub fn mutations(entries: &[(&str, &[(&str, toml::Value)])]) -> toml::Value {
    toml::Value::Array(
        entries
            .iter()
            .map(|(plugin, extra)| {
                let mut pairs = vec![("plugin", toml::Value::String(plugin.to_string()))];
                pairs.extend(extra.iter().cloned());
                table(&pairs)
            })
            .collect(),
    )
}

/// Region means of `img` (8×8 blocks of a 32×32 image).
pub fn regions(img: &[Rgb]) -> Vec<f64> {
    let mut out = vec![0.0; 16];
    for (i, c) in img.iter().enumerate() {
        let (x, y) = (i % 32, i / 32);
        out[(y / 8) * 4 + x / 8] += c.luminance() as f64 / 64.0;
    }
    out
}

/// Chromaticity (r, b over r + g + b) of an image's mean.
pub fn chromaticity(img: &[Rgb]) -> (f64, f64) {
    let sum = img.iter().fold([0.0f64; 3], |a, c| {
        [a[0] + c.r as f64, a[1] + c.g as f64, a[2] + c.b as f64]
    });
    let t = sum[0] + sum[1] + sum[2];
    (sum[0] / t, sum[2] / t)
}

/// The red/blue hue test on 64-pixel-wide images of `cornell-box/red-blue.toml`: the
/// chromaticity of the left and right thirds (the red and the blue wall with the light they
/// bleed) of `erpt` within 0.008 of `mcpt`'s. A chain that carried its seed's colour into
/// every deposit drops the blue side's b share by about 0.025.
pub fn assert_same_wall_hues(mcpt: &[Rgb], erpt: &[Rgb]) {
    for (name, range) in [("red side", 0..21usize), ("blue side", 43..64usize)] {
        let pick = |img: &[Rgb]| -> Vec<Rgb> {
            img.iter()
                .enumerate()
                .filter(|(i, _)| range.contains(&(i % 64)))
                .map(|(_, c)| *c)
                .collect()
        };
        let (a, b) = (chromaticity(&pick(mcpt)), chromaticity(&pick(erpt)));
        assert!(
            (a.0 - b.0).abs() < 0.008 && (a.1 - b.1).abs() < 0.008,
            "{name}: MCPT chromaticity (r {:.4}, b {:.4}) vs ERPT (r {:.4}, b {:.4})",
            a.0,
            a.1,
            b.0,
            b.1
        );
    }
}

/// A directional light node travelling down and tilted by `tilt` degrees towards +Z (it comes
/// from behind the wall): a rotation about +X by −(90° + tilt) of the node's −Z.
pub fn sun_node(tilt: f32) -> String {
    let a = -(90.0 + tilt).to_radians();
    let q = [(a / 2.0).sin(), 0.0, 0.0, (a / 2.0).cos()];
    format!(
        r#"{{"translation": [0.0, 5.0, 0.0], "rotation": {q:?}, "extensions": {{"KHR_lights_punctual": {{"light": 0}}}}}}"#
    )
}

/// Renders `runs` independent renderers from `make` (seeds `seed_base` + r, 16-pixel tiles)
/// and checks each for invalid deposits and non-finite pixels; returns the images and the
/// last outcome (for its statistics).
pub fn independent_runs(
    label: &str,
    runs: u64,
    seed_base: u64,
    make: &dyn Fn() -> Renderer,
) -> (Vec<Vec<Rgb>>, RenderOutcome) {
    let mut images = Vec::new();
    let mut last = None;
    for r in 0..runs {
        let mut s = make();
        s.options.seed = seed_base + r;
        s.options.tile_size = 16;
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0, "{label}: invalid deposits");
        let img = out.frame.image();
        assert!(
            img.iter().all(|c| c.is_valid_radiance()),
            "{label}: NaN/Inf in the image"
        );
        images.push(img);
        last = Some(out);
    }
    (images, last.expect("at least one run"))
}

/// The unbiasedness z-test per 8×8 region of 32×32 `images` (independent runs) against
/// `reference`, with the reference's own noise: |z| < 5 in each of the 16 regions.
///
/// A region's variance from n runs has only n − 1 degrees of freedom and is often several
/// times too small by chance (with 6 runs, |t| > 5 has probability 0.4% per region, about 6%
/// per check of 16 regions): it is floored at a quarter of the relative variance pooled over
/// all regions (16·(n − 1) degrees of freedom), so that one region's lucky spread cannot fail
/// the test. A bias shifts the region's mean, and the image mean ([`assert_image_mean`]).
/// `ERPT_DEBUG=1` prints every region.
pub fn assert_regions_unbiased(label: &str, images: &[Vec<Rgb>], reference: &[Rgb]) {
    let runs = images.len() as f64;
    let per_run: Vec<Vec<f64>> = images.iter().map(|img| regions(img)).collect();
    let refs = regions(reference);
    let ref_se: Vec<f64> = (0..16)
        .map(|k| {
            let px: Vec<Rgb> = reference
                .iter()
                .enumerate()
                .filter(|(i, _)| ((i / 32) / 8) * 4 + (i % 32) / 8 == k)
                .map(|(_, c)| *c)
                .collect();
            mean_and_stderr(&px, |c| c.luminance()).1
        })
        .collect();
    let mean_var = |k: usize| {
        let vals: Vec<f64> = per_run.iter().map(|r| r[k]).collect();
        let m = vals.iter().sum::<f64>() / runs;
        (
            m,
            vals.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (runs - 1.0),
        )
    };
    let pooled_rel_var = (0..16)
        .filter(|&k| refs[k].abs() > 1e-12)
        .map(|k| mean_var(k).1 / refs[k].powi(2))
        .sum::<f64>()
        / 16.0;
    for k in 0..16 {
        let (m, var) = mean_var(k);
        let var = var.max(0.25 * pooled_rel_var * refs[k].powi(2));
        let se = (var / runs + ref_se[k].powi(2))
            .sqrt()
            .max(1e-4 * refs[k].abs())
            .max(1e-12); // a region that sees only a black sky
        let z = (m - refs[k]) / se;
        if std::env::var("ERPT_DEBUG").is_ok() {
            eprintln!("{label}: region {k}: {m:.5} vs {:.5}, z = {z:.2}", refs[k]);
        }
        assert!(
            z.abs() < 5.0,
            "{label}: region {k}: ERPT {m:.5} vs reference {:.5} (z = {z:.2})",
            refs[k]
        );
    }
}

/// How close the runs' image mean must come to the reference's ([`assert_image_mean`]).
#[derive(Clone, Copy, Debug)]
pub enum MeanRule {
    /// Within this relative distance.
    Within(f64),
    /// Within the relative distance, or within `z` standard errors (the runs' spread and
    /// the reference's pixel noise) where caustics make both sides heavy-tailed.
    WithinOrZ(f64, f64),
    /// Within `z` standard errors (floored at 1e-4 of the mean).
    Z(f64),
}

/// The mean luminance of `images` (independent runs) against `reference`'s, by `rule`.
pub fn assert_image_mean(label: &str, images: &[Vec<Rgb>], reference: &[Rgb], rule: MeanRule) {
    let runs = images.len() as f64;
    let means: Vec<f64> = images
        .iter()
        .map(|img| img.iter().map(|c| c.luminance() as f64).sum::<f64>() / img.len() as f64)
        .collect();
    let (ref_mean, ref_mean_se) = mean_and_stderr(reference, |c| c.luminance());
    let m = means.iter().sum::<f64>() / runs;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (runs - 1.0);
    let se = (var / runs + ref_mean_se.powi(2))
        .sqrt()
        .max(1e-4 * ref_mean)
        .max(1e-12);
    let (rel, z) = ((m / ref_mean - 1.0).abs(), (m - ref_mean) / se);
    let ok = match rule {
        MeanRule::Within(r) => rel < r,
        MeanRule::WithinOrZ(r, zmax) => rel < r || z.abs() < zmax,
        MeanRule::Z(zmax) => z.abs() < zmax,
    };
    assert!(
        ok,
        "{label}: image mean {m:.5} vs reference {ref_mean:.5} (relative {rel:.4}, z = {z:.2}, rule {rule:?})"
    );
}

/// Runs `body` with what a test that drives mutations by hand needs from renderer `s`: its
/// scene view, a tracer over its intersector and the untangled seed sampler's settings.
pub fn with_seed_sampler<R>(
    s: &Renderer,
    body: impl FnOnce(
        &flowlight_sdk::Scene,
        &flowlight_sdk::Tracer,
        flowlight_pathtrace::PathSettings,
    ) -> R,
) -> R {
    // SAFETY: the renderer keeps the view's data alive.
    let scene = unsafe { flowlight_sdk::Scene::from_view(s.instance.view()) };
    let mut unit_tracer =
        flowlight_host::intersector::UnitTracer::new(&s.scene, s.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = flowlight_sdk::Tracer::new(&table);
    let mut settings =
        flowlight_pathtrace::PathSettings::from_params(&flowlight_sdk::Params::from_slice(&[]))
            .unwrap();
    settings.variant = flowlight_pathtrace::Variant::Untangled;
    body(&scene, &tracer, settings)
}

/// Runs `cmd`, which must succeed (else the failure shows the command and both streams),
/// and returns its standard output.
pub fn run_ok(cmd: &mut std::process::Command) -> String {
    let o = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{cmd:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// Entangled MCPT of the config `config` (relative to `scenes/`) at 32², `spp` samples per
/// pixel, seed 77, 2 threads, at the config's `path_depth` and nothing else of its
/// `[integrator]`: the reference the ERPT seed tests compare with (the same path space).
pub fn mcpt_reference(config: &str, spp: u32) -> Vec<Rgb> {
    let mut cfg = flowlight_scene::config::load_config(&scene_config(config)).unwrap();
    cfg.width = 32;
    cfg.height = 32;
    cfg.integrator_plugin = "mcpt".into();
    cfg.integrator_params.retain(|(k, _)| k == "path_depth");
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov).unwrap();
    s.exr_path = None;
    s.png_path = None;
    s.options.seed = 77;
    render(&s).frame.image()
}
