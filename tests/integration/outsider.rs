//! Plugins built the way an outsider builds them: `flowlight new-plugin` into a folder
//! outside the workspace and the two examples under `plugins/examples/`, each compiled by
//! its own `cargo build --release --offline` (they are not workspace members), then loaded
//! by the host and checked against numbers computed here independently:
//!
//! * the generated integrator (one-bounce direct light) against `mcpt` with
//!   `path_depth = 1` on the Cornell box, and the CLI renders with it through
//!   `FLOWLIGHT_PLUGIN_PATH`;
//! * the generated mutations (on the regeneration engine, and by hand) and the
//!   film-perturbation and gaussian-lens examples through the conformance kit (the
//!   Gaussian one through `flowlight conformance` on its built library), ERPT with the
//!   film-perturbation example alone against path tracing on the Cornell box, and a
//!   mutation's statistics counters in ERPT's;
//! * a generated crate's lockfile against the workspace's, and the names `new-plugin`
//!   refuses because their crate would not compile;
//! * the AO example against the analytic ambient occlusion next to a wall, its albedo and
//!   normal layers against the material and the plane;
//! * docs/writing-a-plugin.md's code against the example files it quotes.
//!
//! The out-of-tree builds share one target folder, `target/outsider`, so the SDK and its
//! dependencies compile once (the first run takes a few minutes on 2 cores; dependencies
//! come from Cargo's cache, which the workspace build filled). Plugins the workspace builds
//! (`erpt`, `mcpt`) must be built first, as for every integration test.

use crate::common;

use common::{mean_and_stderr, render, renderer_at, scene_config, toml_params};
use flowlight_core::Rgb;
use flowlight_host::renderer::{Overrides, Renderer};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

/// Shared by every out-of-tree build of this file.
fn outsider_target() -> PathBuf {
    common::repo().join("target").join("outsider")
}

/// One cargo at a time in the shared target folder (cargo would wait for its lock anyway;
/// this keeps the waiting out of the builds' own output).
static CARGO: Mutex<()> = Mutex::new(());

/// Runs `cargo <args>` in `dir` as an outsider would, with the shared target folder.
fn cargo(dir: &Path, args: &[&str]) {
    let _one = CARGO.lock().unwrap_or_else(|e| e.into_inner());
    // The cargo running this test (under rustup, the toolchain's own binary) and the rustc
    // beside it: the host refuses a plugin built by another compiler, and a rustup default
    // or a folder override outside the workspace could pick another one.
    let cargo = PathBuf::from(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    let mut command = Command::new(&cargo);
    if let Some(rustc) = cargo
        .parent()
        .map(|d| d.join(format!("rustc{}", std::env::consts::EXE_SUFFIX)))
        .filter(|r| r.is_file())
    {
        command.env("RUSTC", rustc);
    }
    let out = command
        .args(args)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", outsider_target())
        // The workspace's settings must not leak into the outsider's build.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .expect("running cargo");
    assert!(
        out.status.success(),
        "cargo {args:?} in {} failed:\n{}",
        dir.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `cargo build --release` and `cargo test --release` in `dir`; the built library's path.
fn build_plugin(dir: &Path, name: &str) -> PathBuf {
    cargo(dir, &["build", "--release", "--offline", "--quiet"]);
    cargo(dir, &["test", "--release", "--offline", "--quiet"]);
    let lib = outsider_target()
        .join("release")
        .join(flowlight_host::plugin::plugin_file_name(name));
    assert!(lib.is_file(), "{} was not built", lib.display());
    lib
}

/// A folder outside the workspace, not yet made, removed with what is made there when dropped
/// (unless the test fails).
fn outside(name: &str) -> common::TempDir {
    let d = common::TempDir::new(&format!("flowlight-outsider-{}-{name}", std::process::id()));
    // `new-plugin` makes the folder itself.
    std::fs::remove_dir(&*d).unwrap();
    assert!(
        !d.starts_with(common::repo()),
        "temp dir inside the workspace"
    );
    d
}

fn flowlight(args: &[&str], plugin_path: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(args)
        .env("FLOWLIGHT_PLUGIN_PATH", plugin_path)
        .output()
        .expect("running flowlight")
}

/// Region means (8×8 blocks of a 32×32 image), by luminance.
fn regions(img: &[Rgb]) -> Vec<f64> {
    let mut out = vec![0.0; 16];
    for (i, c) in img.iter().enumerate() {
        let (x, y) = (i % 32, i / 32);
        out[(y / 8) * 4 + x / 8] += c.luminance() as f64 / 64.0;
    }
    out
}

fn image_mean(img: &[Rgb]) -> f64 {
    img.iter().map(|c| c.luminance() as f64).sum::<f64>() / img.len() as f64
}

/// A renderer of the Cornell box at 32×32 with integrator `plugin` and `params`.
fn cornell_with(plugin: &str, spp: u32, seed: u64, params: &[(&str, toml::Value)]) -> Renderer {
    let mut cfg =
        flowlight_scene::config::load_config(&scene_config("cornell-box/cornell-box.toml"))
            .unwrap_or_else(|e| panic!("{e}"));
    cfg.width = 32;
    cfg.height = 32;
    cfg.integrator_plugin = plugin.into();
    cfg.integrator_params.clear();
    let ov = Overrides {
        spp: Some(spp),
        threads: Some(2),
        seed: Some(seed),
        params: toml_params(params),
        ..Default::default()
    };
    let mut s = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    s.options.tile_size = 16;
    s
}

#[test]
fn new_plugin_integrator_builds_outside_and_renders_the_cornell_box() {
    let dir = outside("direct");
    let out = flowlight(
        &[
            "new-plugin",
            "--kind",
            "integrator",
            "my-direct",
            dir.to_str().unwrap(),
        ],
        Path::new(""),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cargo_toml = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    assert!(
        cargo_toml.contains("flowlight-sdk = { path = "),
        "{cargo_toml}"
    );
    let lib = build_plugin(&dir, "my-direct");
    let plugins = lib.parent().unwrap().to_path_buf();

    // The CLI finds it through FLOWLIGHT_PLUGIN_PATH and writes an image.
    let cfg = dir.join("cornell.toml");
    std::fs::write(
        &cfg,
        format!(
            "scene = {:?}\n[render]\nwidth = 16\nheight = 16\nspp = 4\n[integrator]\nplugin = \"my-direct\"\n[output]\nexr = \"cornell.exr\"\n",
            scene_config("cornell-box/cornell-box.gltf")
        ),
    )
    .unwrap();
    let out = flowlight(&["render", cfg.to_str().unwrap(), "--quiet"], &plugins);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("integrator      my-direct"));
    assert!(dir.join("cornell.exr").is_file());

    // The image: one-bounce direct light equals mcpt with path-space depth 1 (diffuse
    // scene), region by region.
    let mine = render(&cornell_with(lib.to_str().unwrap(), 256, 1, &[]))
        .frame
        .image();
    let reference = render(&cornell_with(
        "mcpt",
        512,
        2,
        &[("path_depth", toml::Value::Integer(1))],
    ))
    .frame
    .image();
    // Direct light leaves the ceiling dark (the lamp faces down): about 80 % of the pixels
    // are lit.
    let lit = mine.iter().filter(|c| c.luminance() > 0.0).count();
    assert!(lit > mine.len() * 2 / 3, "only {lit} lit pixels");
    let (m, r) = (image_mean(&mine), image_mean(&reference));
    eprintln!("my-direct: {lit} lit pixels, mean {m:.5}; mcpt depth 1: {r:.5}");
    assert!(
        (m / r - 1.0).abs() < 0.02,
        "mean {m:.5} vs mcpt depth 1 {r:.5}"
    );
    for (k, (a, b)) in regions(&mine).iter().zip(regions(&reference)).enumerate() {
        assert!(
            (a / b - 1.0).abs() < 0.06,
            "region {k}: {a:.5} vs mcpt depth 1 {b:.5}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The registry packages of a `Cargo.lock`: (name, version).
fn locked_registry_packages(lock: &Path) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(lock).unwrap_or_else(|e| panic!("{}: {e}", lock.display()));
    let lock: toml::Table = toml::from_str(&text).unwrap();
    lock["package"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p.get("source").is_some())
        .map(|p| {
            (
                p["name"].as_str().unwrap().into(),
                p["version"].as_str().unwrap().into(),
            )
        })
        .collect()
}

/// Every registry package the generated crate resolved is one the workspace's lockfile holds
/// at the same version.
fn assert_resolved_like_the_workspace(dir: &Path) {
    let workspace = locked_registry_packages(&common::repo().join("Cargo.lock"));
    let generated = locked_registry_packages(&dir.join("Cargo.lock"));
    assert!(
        !generated.is_empty(),
        "no registry package in {}",
        dir.display()
    );
    let newer: Vec<_> = generated
        .iter()
        .filter(|p| !workspace.contains(p))
        .collect();
    assert!(newer.is_empty(), "resolved unlike the workspace: {newer:?}");
}

/// `new-plugin --kind KIND NAME` outside, built, through the kit with `params`, and ERPT
/// rendering the Cornell box with it.
fn generated_mutation_conforms_and_renders(kind: &str, name: &str, params: &[(&str, toml::Value)]) {
    let dir = outside(name);
    let out = flowlight(
        &["new-plugin", "--kind", kind, name, dir.to_str().unwrap()],
        Path::new(""),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lib = build_plugin(&dir, name);
    assert_resolved_like_the_workspace(&dir);
    let report = flowlight_testkit::assert_mutation_conforms(lib.to_str().unwrap(), params);
    eprintln!("{report}");
    assert_eq!(report.name, name);
    // ERPT renders the Cornell box with it.
    let list = toml::Value::Array(vec![toml::Value::Table(
        [(
            "plugin".to_string(),
            toml::Value::String(lib.to_str().unwrap().into()),
        )]
        .into_iter()
        .collect(),
    )]);
    let img = render(&renderer_at(
        "cornell-box/erpt.toml",
        16,
        16,
        2,
        &[("mutations", list)],
    ))
    .frame
    .image();
    assert!(img.iter().all(|c| c.is_valid_radiance()));
    assert!(image_mean(&img) > 0.0);
    // A second run into the same folder is refused, and the files stay.
    let out = flowlight(
        &["new-plugin", "--kind", kind, name, dir.to_str().unwrap()],
        Path::new(""),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not empty") && err.trim().lines().count() == 1,
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn new_plugin_mutation_on_the_engine_builds_outside_passes_the_kit_and_renders() {
    generated_mutation_conforms_and_renders("mutation", "my-drill", &[]);
}

#[test]
fn new_plugin_raw_mutation_builds_outside_passes_the_kit_and_renders() {
    generated_mutation_conforms_and_renders("raw-mutation", "my-jitter", &[]);
}

#[test]
fn a_bad_plugin_name_is_refused_in_one_line() {
    let dir = outside("bad-name");
    let out = flowlight(
        &[
            "new-plugin",
            "--kind",
            "integrator",
            "My_AO",
            dir.to_str().unwrap(),
        ],
        Path::new(""),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("plugin name \"My_AO\"") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(!dir.exists(), "nothing is written for a bad name");
    // Names whose crate would not compile: a keyword, the prelude's or the template's own
    // types, a Flowlight crate.
    for name in [
        "self",
        "scene",
        "film",
        "ray",
        "integrator",
        "mutation",
        "result",
        "string",
        "option",
        "fn",
        "sdk",
        "strategy",
    ] {
        for kind in ["integrator", "mutation", "raw-mutation"] {
            let out = flowlight(
                &["new-plugin", "--kind", kind, name, dir.to_str().unwrap()],
                Path::new(""),
            );
            assert!(!out.status.success(), "{kind} {name} was accepted");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                err.contains(&format!("plugin name \"{name}\"")) && err.trim().lines().count() == 1,
                "{kind} {name}: {err}"
            );
            assert!(!dir.exists(), "nothing is written for {name}");
        }
    }
}

fn example(name: &str) -> PathBuf {
    let dir = common::repo().join("plugins/examples").join(name);
    build_plugin(&dir, name)
}

/// AO next to an infinite wall (module docs of the example): 1 − (acos a − a√(1−a²))/π with
/// a = min(d/r, 1).
fn ao_next_to_wall(d: f64, r: f64) -> f64 {
    let a = (d / r).min(1.0);
    1.0 - (a.acos() - a * (1.0 - a * a).sqrt()) / std::f64::consts::PI
}

#[test]
fn ao_example_matches_the_analytic_occlusion_next_to_a_wall() {
    let lib = example("ao-aov");
    // A floor z = 0 over x ∈ [−3, 1] and a wall x = 1 rising 10 above it, both 20 long in y,
    // seen from above by an orthographic camera covering x ∈ [−3, 1], y ∈ [−2, 2].
    let floor = [
        [-3.0, -10.0, 0.0],
        [1.0, -10.0, 0.0],
        [1.0, 10.0, 0.0],
        [-3.0, 10.0, 0.0],
    ];
    let wall = [
        [1.0, 10.0, 0.0],
        [1.0, -10.0, 0.0],
        [1.0, -10.0, 10.0],
        [1.0, 10.0, 10.0],
    ];
    let base = [0.25f32, 0.5, 0.75];
    let gltf = common::quads_gltf(
        &[floor, wall],
        &format!(
            r#"{{"pbrMetallicRoughness": {{"baseColorFactor": [{}, {}, {}, 1], "metallicFactor": 0}}, "doubleSided": true}}"#,
            base[0], base[1], base[2]
        ),
        &[],
        "",
    );
    let body = format!(
        "[render]\nwidth = 16\nheight = 16\nspp = 32\n[camera]\nposition = [-1.0, 0.0, 5.0]\nlook_at = [-1.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\nprojection = \"orthographic\"\northo_height = 4.0\n[integrator]\nplugin = {:?}\nradius = 1.0\nao_samples = 16\naovs = true\n",
        lib.to_str().unwrap()
    );
    let s = common::renderer_from("ao-wall", &gltf, &body, 32);
    let out = render(&s);
    let (w, h) = (16usize, 16usize);
    let ao = out.frame.layer(0);
    let albedo = out.frame.layer(1);
    let normal = out.frame.layer(2);
    // Expected AO per pixel column: the analytic value averaged over the pixel's footprint
    // on the floor (the camera's own mapping from raster to floor point).
    let floor_x = |raster_x: f32| {
        let ray = s.camera.generate_ray(glam::Vec2::new(raster_x, 8.0));
        let t = -ray.origin.z / ray.dir.z;
        (ray.origin.x + t * ray.dir.x) as f64
    };
    let mut near_wall = 0;
    for col in 0..w {
        let steps = 200;
        let expected = (0..steps)
            .map(|k| {
                ao_next_to_wall(
                    1.0 - floor_x(col as f32 + (k as f32 + 0.5) / steps as f32),
                    1.0,
                )
            })
            .sum::<f64>()
            / steps as f64;
        let column: Vec<Rgb> = (0..h).map(|row| ao[row * w + col]).collect();
        let (mean, _) = mean_and_stderr(&column, |c| c.r);
        if expected == 1.0 {
            // Nothing within the radius: every ray is open, no noise at all.
            assert!(
                column.iter().all(|c| c.r == 1.0),
                "column {col}: {column:?}"
            );
        } else {
            near_wall += 1;
            let rays = (h * 32 * 16) as f64;
            let sigma = (expected * (1.0 - expected) / rays).sqrt();
            eprintln!("column {col}: AO {mean:.4}, analytic {expected:.4} (σ {sigma:.4})");
            assert!(
                (mean - expected).abs() < 5.0 * sigma + 2e-3,
                "column {col}: AO {mean:.4}, analytic {expected:.4} (σ {sigma:.4})"
            );
        }
    }
    assert!(near_wall >= 3, "only {near_wall} columns within the radius");
    for i in 0..w * h {
        assert!(
            (albedo[i]
                .to_array()
                .iter()
                .zip(base)
                .all(|(a, b)| (a - b).abs() < 1e-5)),
            "albedo {:?} at {i}",
            albedo[i]
        );
        assert_eq!(normal[i].to_array(), [0.5, 0.5, 1.0], "normal at {i}");
    }
}

#[test]
fn film_perturbation_example_passes_the_kit_and_erpt_with_it_matches_path_tracing() {
    let lib = example("film-perturbation");
    let lib = lib.to_str().unwrap();
    let report = flowlight_testkit::assert_mutation_conforms(lib, &[("radius", 3.0.into())]);
    eprintln!("{report}");
    assert_eq!(
        report.worst_ratio_error, 0.0,
        "a symmetric move reports ratio 1 exactly"
    );

    let reference = render(&cornell_with("mcpt", 2048, 77, &[])).frame.image();
    let list = toml::Value::Array(vec![toml::Value::Table(
        [("plugin".to_string(), toml::Value::String(lib.into()))]
            .into_iter()
            .collect(),
    )]);
    let runs = 6;
    let mut per_run = Vec::new();
    for r in 0..runs {
        let mut s = renderer_at(
            "cornell-box/erpt.toml",
            32,
            32,
            4,
            &[
                ("mutations", list.clone()),
                ("mutations_per_sample", 32.0.into()),
                ("chain_length", toml::Value::Integer(32)),
            ],
        );
        s.options.seed = 500 + r;
        s.options.tile_size = 16;
        let img = render(&s).frame.image();
        assert!(img.iter().all(|c| c.is_valid_radiance()));
        per_run.push((image_mean(&img), regions(&img)));
    }
    let n = runs as f64;
    let means: Vec<f64> = per_run.iter().map(|r| r.0).collect();
    let m = means.iter().sum::<f64>() / n;
    let r = image_mean(&reference);
    eprintln!("ERPT with film-perturbation: mean {m:.5}; MCPT 2048 spp: {r:.5}");
    assert!(
        (m / r - 1.0).abs() < 0.03,
        "ERPT mean {m:.5} vs MCPT {r:.5}"
    );
    let refs = regions(&reference);
    // The reference's own noise is below 1 % per region at 2048 spp: the floor of the
    // standard error covers it.
    for (k, &expected) in refs.iter().enumerate() {
        let vals: Vec<f64> = per_run.iter().map(|r| r.1[k]).collect();
        let mk = vals.iter().sum::<f64>() / n;
        let var = vals.iter().map(|v| (v - mk).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt().max(0.01 * expected);
        let z = (mk - expected) / se;
        assert!(
            z.abs() < 5.0,
            "region {k}: ERPT {mk:.5} vs MCPT {expected:.5} (z {z:.1})"
        );
    }
}

#[test]
fn gaussian_lens_example_passes_the_kit_on_its_built_library_and_counts_in_erpt() {
    let lib = example("gaussian-lens");
    // The kit without Cargo: the CLI on the built library.
    let out = flowlight(
        &["conformance", lib.to_str().unwrap(), "--set", "sigma=1.5"],
        Path::new(""),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.trim_end().ends_with("conforms"), "{stdout}");
    // Its moves through the mirror chain and the glass sphere were checked.
    for scene in ["mirror chain", "glass caustic"] {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(scene))
            .unwrap_or_else(|| panic!("no line for the {scene}: {stdout}"));
        let through: usize = line
            .split(" valid, ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{line}"));
        assert!(
            through > 0,
            "no move through mirrors or glass in the {scene}: {line}"
        );
    }
    // A plugin that does not conform is refused in one line (the kit needs a mutation).
    let out = flowlight(&["conformance", "mcpt"], Path::new(""));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.trim().lines().count() == 1, "{err}");

    // Its counters reach ERPT's statistics, after ERPT's own.
    let list = toml::Value::Array(vec![toml::Value::Table(
        [(
            "plugin".to_string(),
            toml::Value::String(lib.to_str().unwrap().into()),
        )]
        .into_iter()
        .collect(),
    )]);
    let outcome = render(&renderer_at(
        "cornell-box/erpt.toml",
        16,
        16,
        2,
        &[("mutations", list)],
    ));
    let counters = &outcome.stats.integrator;
    let get = |name: &str| {
        counters
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| *v)
            .unwrap_or_else(|| panic!("no counter {name}: {counters:?}"))
    };
    let (proposals, misses) = (get("gaussian-lens.proposals"), get("gaussian-lens.misses"));
    assert!(
        proposals > 0.0 && misses >= 0.0 && misses < proposals,
        "{proposals} {misses}"
    );
    // ERPT counts this strategy's steps itself (its group `gaussian-lens`): each step is one
    // proposal. The mutation's counters come after ERPT's own.
    assert_eq!(proposals, get("gaussian-lens.mutations"), "{counters:?}");
    let at = |name: &str| counters.iter().position(|(n, _)| n == name).unwrap();
    assert!(
        at("gaussian-lens.proposals") > at("chains_per_seed"),
        "{counters:?}"
    );
}

/// Every ```rust block of docs/writing-a-plugin.md tagged `file=PATH region=NAME` equals the
/// lines between `// region: NAME` and `// endregion: NAME` of PATH.
#[test]
fn the_plugin_guide_quotes_the_example_files_exactly() {
    let repo = common::repo();
    let doc = std::fs::read_to_string(repo.join("docs/writing-a-plugin.md")).unwrap();
    let mut quoted = 0;
    let mut lines = doc.lines();
    while let Some(line) = lines.next() {
        let Some(info) = line.strip_prefix("```rust ") else {
            continue;
        };
        let tag = |key: &str| {
            info.split_whitespace()
                .find_map(|w| w.strip_prefix(key))
                .unwrap_or_else(|| panic!("```rust block without {key}: {line}"))
                .to_string()
        };
        let (file, region) = (tag("file="), tag("region="));
        let block: Vec<&str> = lines.by_ref().take_while(|l| *l != "```").collect();
        let source =
            std::fs::read_to_string(repo.join(&file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        let begin = format!("// region: {region}");
        let end = format!("// endregion: {region}");
        let region_lines: Vec<&str> = source
            .lines()
            .skip_while(|l| l.trim() != begin)
            .skip(1)
            .take_while(|l| l.trim() != end)
            .collect();
        assert!(!region_lines.is_empty(), "{file}: no region {region}");
        assert_eq!(
            block.join("\n"),
            region_lines.join("\n"),
            "docs/writing-a-plugin.md quotes {file} region {region} differently"
        );
        quoted += 1;
    }
    assert!(quoted >= 4, "only {quoted} quoted blocks");
}

#[test]
fn the_existing_mutation_plugins_pass_the_kit() {
    for (plugin, params) in [
        ("hard-reconnection", vec![]),
        ("soft-reconnection", vec![("cap_degrees", 8.0.into())]),
        ("bxdf-extension", vec![]),
        ("blow", vec![("width", toml::Value::from("wide"))]),
        ("drill", vec![("width", toml::Value::from("narrow"))]),
    ] {
        let report = flowlight_testkit::assert_mutation_conforms(plugin, &params);
        eprintln!("{report}");
    }
}

#[test]
fn the_kit_refuses_a_mutation_whose_ratio_is_wrong() {
    // The generated mutation with its symmetric ratio 1 replaced by 2: every acceptance
    // doubles, detailed balance fails, and the kit must say so.
    let err = kit_error_with_ratio("wrong-ratio", "2.0");
    assert!(err.contains("ratio 2 but T(y→x)/T(x→y)"), "{err}");
}

#[test]
fn the_kit_refuses_a_degenerate_ratio_where_the_densities_are_not() {
    // NaN is a strategy's word for a degenerate density, which the kit accepts only where the
    // strategy's own densities are degenerate; the symmetric mutation's never are.
    let err = kit_error_with_ratio("nan-ratio", "f32::NAN");
    assert!(
        err.contains("reports a degenerate density (ratio NaN)"),
        "{err}"
    );
}

/// The kit's error for the generated raw mutation `name` with its symmetric ratio 1
/// replaced by the Rust expression `ratio`.
fn kit_error_with_ratio(name: &str, ratio: &str) -> String {
    let dir = outside(name);
    let out = flowlight(
        &[
            "new-plugin",
            "--kind",
            "raw-mutation",
            name,
            dir.to_str().unwrap(),
        ],
        Path::new(""),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lib_rs = dir.join("src/lib.rs");
    let source = std::fs::read_to_string(&lib_rs).unwrap();
    let broken = source.replace(
        "transition_ratio: 1.0",
        &format!("transition_ratio: {ratio}"),
    );
    assert_ne!(source, broken, "the template changed: update this test");
    std::fs::write(&lib_rs, broken).unwrap();
    cargo(&dir, &["build", "--release", "--offline", "--quiet"]);
    let lib = outsider_target()
        .join("release")
        .join(flowlight_host::plugin::plugin_file_name(name));
    let err = flowlight_testkit::check_mutation(lib.to_str().unwrap(), &[]).unwrap_err();
    let _ = std::fs::remove_dir_all(&dir);
    err
}

/// Another Rust toolchain installed beside this one (rustup), whose `rustc --version`
/// differs from the host's.
fn other_rustc() -> Option<PathBuf> {
    let home = std::env::var_os("RUSTUP_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".rustup")))?;
    let mut found: Vec<PathBuf> = std::fs::read_dir(home.join("toolchains"))
        .ok()?
        .flatten()
        .map(|e| e.path().join("bin").join("rustc"))
        .filter(|r| r.is_file())
        .collect();
    found.sort();
    found.into_iter().find(|r| {
        Command::new(r)
            .arg("--version")
            .output()
            .ok()
            .filter(|o| o.status.success())
            .is_some_and(|o| {
                String::from_utf8_lossy(&o.stdout).trim() != flowlight_sdk::abi::RUSTC_VERSION
            })
    })
}

#[test]
fn a_plugin_built_by_another_rustc_is_refused_with_the_documented_message() {
    let Some(rustc) = other_rustc() else {
        eprintln!("skipped: no second Rust toolchain installed (rustup toolchain install nightly)");
        return;
    };
    let dir = outside("other-rustc");
    let out = flowlight(
        &[
            "new-plugin",
            "--kind",
            "integrator",
            "other-rustc",
            dir.to_str().unwrap(),
        ],
        Path::new(""),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Its own target folder: the other compiler's artefacts must not mix with ours.
    let target = common::repo().join("target").join("outsider-other-rustc");
    let _one = CARGO.lock().unwrap_or_else(|e| e.into_inner());
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let built = Command::new(cargo)
        .args(["build", "--release", "--offline", "--quiet"])
        .current_dir(&dir)
        .env("CARGO_TARGET_DIR", &target)
        .env("RUSTC", &rustc)
        .env_remove("RUSTFLAGS")
        .output()
        .expect("running cargo");
    drop(_one);
    assert!(
        built.status.success(),
        "building with {}: {}",
        rustc.display(),
        String::from_utf8_lossy(&built.stderr)
    );
    let lib = target
        .join("release")
        .join(flowlight_host::plugin::plugin_file_name("other-rustc"));
    let err = match flowlight_host::plugin::PluginLibrary::load(&lib) {
        Ok(_) => panic!("a plugin built by {} was accepted", rustc.display()),
        Err(e) => e.to_string(),
    };
    // The message docs/writing-a-plugin.md shows.
    let expected = format!(
        "plugin {} was refused: rustc version mismatch (plugin has rustc ",
        lib.display()
    );
    assert!(err.starts_with(&expected), "{err}");
    assert!(
        err.ends_with(&format!(
            "host has {}); rebuild the plugin against this host's SDK",
            flowlight_sdk::abi::RUSTC_VERSION
        )),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
