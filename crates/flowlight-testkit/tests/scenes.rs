//! The committed benchmark and research scenes are what `make-scenes` writes: edit
//! `crates/flowlight-testkit/src/scenes.rs` or `research.rs` and run it, never the files.
//! The research scenes also load, name their methods, and render with MCPT to an image that
//! is finite and not black.

use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_testkit::research::{self, ResearchScene};
use serde_json::Value;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// `a` and `b` equal as JSON, numbers within a relative 1e-12 (the same values printed
/// another way), everything else exactly.
fn same(a: &Value, b: &Value, at: &str) -> Result<(), String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (x - y).abs() <= 1e-12 * x.abs().max(y.abs()) {
                Ok(())
            } else {
                Err(format!("{at}: {x} vs {y}"))
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .try_for_each(|(i, (p, q))| same(p, q, &format!("{at}[{i}]"))),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => {
            x.iter().try_for_each(|(k, v)| {
                let w = y.get(k).ok_or_else(|| format!("{at}.{k}: missing"))?;
                same(v, w, &format!("{at}.{k}"))
            })
        }
        _ if a == b => Ok(()),
        _ => Err(format!("{at}: {a} vs {b}")),
    }
}

/// `text` is the committed file `path`, as JSON when `json`, else byte for byte.
fn committed(path: &Path, text: &str, json: bool) {
    let on_disk = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e} (run make-scenes)", path.display()));
    if json {
        let parse = |t: &str| serde_json::from_str::<Value>(t).unwrap();
        same(&parse(text), &parse(&on_disk), &path.display().to_string())
            .unwrap_or_else(|e| panic!("{e} (run make-scenes)"));
    } else {
        assert_eq!(text, on_disk, "{} (run make-scenes)", path.display());
    }
}

#[test]
fn the_committed_scenes_are_what_make_scenes_writes() {
    let dir = flowlight_testkit::scenes_dir();
    for (name, gltf, toml, triangles) in flowlight_testkit::scenes::all() {
        committed(&dir.join(name).join(format!("{name}.gltf")), &gltf, true);
        committed(&dir.join(name).join(format!("{name}.toml")), &toml, false);
        assert!(triangles >= 20, "{name}: {triangles} triangles");
    }
}

#[test]
fn the_committed_research_scenes_are_what_make_scenes_writes() {
    let dir = flowlight_testkit::scenes_dir();
    let scenes = research::all();
    assert_eq!(
        scenes.len(),
        6,
        "the four research scenes and the two untuned caustic scenes"
    );
    for ResearchScene {
        files: (name, gltf, toml, _),
        method_config: (file, text),
    } in scenes
    {
        committed(&dir.join(name).join(format!("{name}.gltf")), &gltf, true);
        committed(&dir.join(name).join(format!("{name}.toml")), &toml, false);
        committed(&dir.join(name).join(file), &text, false);
    }
}

/// The integer parameter `key` of a config's `[integrator]`.
fn int_param(cfg: &flowlight_scene::config::RenderConfig, key: &str) -> Option<i64> {
    cfg.integrator_params
        .iter()
        .find(|(k, _)| k == key)
        .and_then(|(_, v)| v.as_integer())
}

/// Both configs of every research scene load, the glTF has the generator's triangles and
/// at least one emitter, and each config names its method and path depth.
#[test]
fn the_research_scenes_load_with_both_configs() {
    let dir = flowlight_testkit::scenes_dir();
    for scene in research::all() {
        let (name, _, _, triangles) = scene.files;
        let (file, _) = scene.method_config;
        let mcpt = dir.join(name).join(format!("{name}.toml"));
        let method = dir.join(name).join(file);
        for (path, plugin) in [(&mcpt, "mcpt"), (&method, file.trim_end_matches(".toml"))] {
            let cfg = flowlight_scene::config::load_config(path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert_eq!(cfg.integrator_plugin, plugin, "{}", path.display());
            assert_eq!((cfg.width, cfg.height), (256, 256), "{}", path.display());
            let depth = int_param(&cfg, "path_depth").expect("path_depth");
            assert!(
                (6..=12).contains(&depth),
                "{}: path_depth {depth}",
                path.display()
            );
            let loaded = flowlight_scene::load_gltf(&cfg.scene, &cfg.material_overrides)
                .unwrap_or_else(|e| panic!("{}: {e}", cfg.scene.display()));
            assert_eq!(loaded.triangles.len(), triangles, "{name}");
            assert!(!loaded.emitters.is_empty(), "{name}: no emitter");
        }
    }
}

/// Every research scene's MCPT config at 24×24 and 8 spp renders an image whose pixels are
/// finite and non-negative and whose mean luminance is above 10⁻³: no scene is black by
/// mistake (a lamp facing away, a closed door, water that lets no light through).
#[test]
fn the_research_scenes_render_with_mcpt() {
    let dir = flowlight_testkit::scenes_dir();
    for scene in research::all() {
        let name = scene.files.0;
        let path = dir.join(name).join(format!("{name}.toml"));
        let mut cfg = flowlight_scene::config::load_config(&path).unwrap();
        (cfg.width, cfg.height) = (24, 24);
        let ov = Overrides {
            spp: Some(8),
            threads: Some(2),
            ..Default::default()
        };
        let mut r = Renderer::from_config(cfg, &ov).unwrap_or_else(|e| panic!("{name}: {e}"));
        r.exr_path = None;
        r.png_path = None;
        let out = r.render(&AtomicBool::new(false), &|_| {}).unwrap();
        assert!(out.error.is_none(), "{name}: {:?}", out.error);
        let image = out.frame.image();
        assert!(
            image.iter().all(|c| c.is_valid_radiance()),
            "{name}: invalid pixel"
        );
        let mean = image.iter().map(|c| c.luminance() as f64).sum::<f64>() / image.len() as f64;
        println!("{name}: mean luminance {mean:.4}");
        assert!(
            mean > 1e-3,
            "{name}: mean luminance {mean}: black by mistake?"
        );
    }
}
