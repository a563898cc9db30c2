//! Property-based fuzzing (proptest) of the two parsers that read user files: the glTF loader
//! (random bytes, mutated .glb and .gltf) and the TOML render config (random text, mutated
//! and recombined configs). They must never panic, and every error must be one clear message
//! naming the file. The loader turns a panic into `SceneError::Internal` as a last resort;
//! here that counts as a failure too.
//!
//! CI runs a short deterministic campaign (fixed seed, about a second per target). A longer
//! run (docs/testing.md):
//!
//! ```sh
//! FLOWLIGHT_FUZZ_CASES=20000 FLOWLIGHT_FUZZ_SEED=$RANDOM cargo test -p flowlight-scene --test integration fuzz:: --release
//! ```

use flowlight_scene::config::parse_config;
use flowlight_scene::{load_gltf, SceneError};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestRunner};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// A deterministic runner: `cases` (scaled by FLOWLIGHT_FUZZ_CASES / 100 when set) with the
/// seed FLOWLIGHT_FUZZ_SEED (default fixed), no failure files.
fn runner(cases: u32) -> TestRunner {
    let cases = match std::env::var("FLOWLIGHT_FUZZ_CASES") {
        Ok(v) => v.parse().unwrap_or(cases),
        Err(_) => cases,
    };
    TestRunner::new(Config {
        cases,
        rng_seed: RngSeed::Fixed(env_or("FLOWLIGHT_FUZZ_SEED", 0x5eed_f10e)),
        failure_persistence: None,
        max_shrink_iters: 200,
        ..Config::default()
    })
}

fn scratch(tag: &str) -> flowlight_testkit::gltf::TempDir {
    static N: AtomicUsize = AtomicUsize::new(0);
    flowlight_testkit::gltf::TempDir::new(&format!(
        "flowlight-fuzz-{}-{}-{tag}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}

/// Loads `bytes` as `file` and checks the outcome: Ok, or an error that names the file and
/// is not a caught panic.
fn check_load(file: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    std::fs::write(file, bytes).unwrap();
    match load_gltf(file, &BTreeMap::new()) {
        Ok(scene) => {
            // Whatever loads must be usable: finite vertices, valid material indices.
            prop_assert!(scene.positions.iter().all(|p| p.is_finite()));
            for t in &scene.triangles {
                prop_assert!(t.iter().all(|&i| (i as usize) < scene.positions.len()));
            }
            for &m in &scene.triangle_material {
                prop_assert!((m as usize) < scene.materials.len());
            }
        }
        Err(SceneError::Internal { reason, .. }) => {
            return Err(TestCaseError::fail(format!(
                "the loader panicked: {reason}"
            )));
        }
        Err(e) => {
            let m = e.to_string();
            prop_assert!(
                m.contains(&file.display().to_string()),
                "error does not name the file: {m}"
            );
            prop_assert!(!m.contains('\n') || m.len() < 2000, "unwieldy error: {m}");
        }
    }
    Ok(())
}

/// A mutation of a byte string: overwrite, insert, delete a span, truncate, or duplicate.
#[derive(Clone, Debug)]
enum Edit {
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    Duplicate(usize, usize),
    /// Overwrite a little-endian u32 (lengths, counts, offsets in a .glb).
    SetU32(usize, u32),
}

fn edit() -> impl Strategy<Value = Edit> {
    let pos = any::<usize>();
    prop_oneof![
        4 => (pos, any::<u8>()).prop_map(|(p, b)| Edit::Set(p, b)),
        2 => (pos, prop::collection::vec(any::<u8>(), 1..16)).prop_map(|(p, v)| Edit::Insert(p, v)),
        2 => (pos, 1usize..64).prop_map(|(p, n)| Edit::Delete(p, n)),
        1 => pos.prop_map(Edit::Truncate),
        1 => (pos, 1usize..64).prop_map(|(p, n)| Edit::Duplicate(p, n)),
        2 => (pos, prop_oneof![Just(0u32), Just(1), Just(u32::MAX), Just(0x7fff_ffff), any::<u32>()])
            .prop_map(|(p, v)| Edit::SetU32(p, v)),
    ]
}

fn apply(data: &mut Vec<u8>, e: &Edit) {
    if data.is_empty() {
        if let Edit::Insert(_, v) = e {
            data.extend(v);
        }
        return;
    }
    let n = data.len();
    match e {
        Edit::Set(p, b) => data[p % n] = *b,
        Edit::Insert(p, v) => {
            let at = p % (n + 1);
            data.splice(at..at, v.iter().copied());
        }
        Edit::Delete(p, k) => {
            let at = p % n;
            data.drain(at..(at + k).min(n));
        }
        Edit::Truncate(p) => data.truncate(p % n),
        Edit::Duplicate(p, k) => {
            let at = p % n;
            let span: Vec<u8> = data[at..(at + k).min(n)].to_vec();
            data.splice(at..at, span);
        }
        Edit::SetU32(p, v) => {
            // Aligned to 4 like the .glb header and chunk fields.
            let at = (p % n) & !3;
            for (i, b) in v.to_le_bytes().into_iter().enumerate() {
                if at + i < n {
                    data[at + i] = b;
                }
            }
        }
    }
}

#[test]
fn gltf_loader_survives_random_bytes() {
    let dir = scratch("random");
    let bytes = prop_oneof![
        prop::collection::vec(any::<u8>(), 0..512),
        // Past the magic, so the .glb parser goes further.
        prop::collection::vec(any::<u8>(), 0..512).prop_map(|mut v| {
            let mut h = b"glTF\x02\x00\x00\x00".to_vec();
            h.extend((v.len() as u32 + 12).to_le_bytes());
            h.append(&mut v);
            h
        }),
    ];
    runner(1500)
        .run(&(bytes, any::<bool>()), |(b, glb)| {
            let file = dir.join(if glb { "x.glb" } else { "x.gltf" });
            check_load(&file, &b)
        })
        .unwrap();
}

#[test]
fn gltf_loader_survives_mutated_glb() {
    let dir = scratch("glb");
    let original = std::fs::read(scenes().join("cornell-box/cornell-box.glb")).unwrap();
    runner(1500)
        .run(&prop::collection::vec(edit(), 1..6), |edits| {
            let mut b = original.clone();
            for e in &edits {
                apply(&mut b, e);
            }
            check_load(&dir.join("m.glb"), &b)
        })
        .unwrap();
}

/// JSON-aware mutations of a .gltf: numbers replaced by hostile values, strings and keys
/// renamed, spans deleted; the .bin beside it stays valid (or is mutated as well).
#[derive(Clone, Debug)]
enum JsonEdit {
    Number(usize, String),
    Bytes(Edit),
    Bin(Edit),
}

fn json_edit() -> impl Strategy<Value = JsonEdit> {
    let hostile = prop_oneof![
        Just("-1".to_string()),
        Just("0".to_string()),
        Just("4294967295".to_string()),
        Just("18446744073709551616".to_string()),
        Just("1e40".to_string()),
        Just("-0.0".to_string()),
        Just("3.5".to_string()),
        Just("null".to_string()),
        Just("\"x\"".to_string()),
        Just("[]".to_string()),
        Just("{}".to_string()),
        (-100i64..100_000).prop_map(|v| v.to_string()),
    ];
    prop_oneof![
        6 => (any::<usize>(), hostile).prop_map(|(i, v)| JsonEdit::Number(i, v)),
        3 => edit().prop_map(JsonEdit::Bytes),
        1 => edit().prop_map(JsonEdit::Bin),
    ]
}

/// Replaces the `i`-th (mod count) JSON number in `text` by `v`.
fn replace_number(text: &str, i: usize, v: &str) -> String {
    let b = text.as_bytes();
    let mut spans = Vec::new();
    let mut k = 0;
    while k < b.len() {
        let c = b[k];
        let starts = (c.is_ascii_digit() || c == b'-')
            && (k == 0 || !(b[k - 1].is_ascii_alphanumeric() || b[k - 1] == b'.'));
        if starts {
            let s = k;
            k += 1;
            while k < b.len() && (b[k].is_ascii_digit() || b"+-.eE".contains(&b[k])) {
                k += 1;
            }
            spans.push((s, k));
        } else {
            k += 1;
        }
    }
    if spans.is_empty() {
        return text.to_string();
    }
    let (s, e) = spans[i % spans.len()];
    format!("{}{}{}", &text[..s], v, &text[e..])
}

#[test]
fn gltf_loader_survives_mutated_gltf_json() {
    let dir = scratch("json");
    let src = scenes().join("cornell-box");
    let text = std::fs::read_to_string(src.join("cornell-box.gltf")).unwrap();
    let bin = std::fs::read(src.join("cornell-box.bin")).unwrap();
    runner(1500)
        .run(&prop::collection::vec(json_edit(), 1..5), |edits| {
            let mut t = text.clone().into_bytes();
            let mut b = bin.clone();
            for e in &edits {
                match e {
                    JsonEdit::Number(i, v) => {
                        t = replace_number(&String::from_utf8_lossy(&t), *i, v).into_bytes()
                    }
                    JsonEdit::Bytes(e) => apply(&mut t, e),
                    JsonEdit::Bin(e) => apply(&mut b, e),
                }
            }
            std::fs::write(dir.join("cornell-box.bin"), &b).unwrap();
            check_load(&dir.join("m.gltf"), &t)
        })
        .unwrap();
}

/// Found by `gltf_loader_survives_mutated_gltf_json`: a primitive whose POSITION refers to
/// accessor 0 in a file without an `accessors` array made gltf-json 1.4.1's validation hook
/// (`mesh.rs:151`, `&root.accessors[index]`) panic. The loader now checks primitives'
/// accessor indices before that validation runs, and names the primitive and the index.
#[test]
fn missing_accessors_array_is_a_validation_error_not_a_panic() {
    let dir = scratch("known-bug");
    let src = scenes().join("cornell-box");
    let text = std::fs::read_to_string(src.join("cornell-box.gltf")).unwrap();
    std::fs::copy(src.join("cornell-box.bin"), dir.join("cornell-box.bin")).unwrap();
    let file = dir.join("no-accessors.gltf");
    std::fs::write(&file, text.replace("\"accessors\"", "\"#ccessors\"")).unwrap();
    match load_gltf(&file, &BTreeMap::new()) {
        Err(SceneError::Internal { reason, .. }) => panic!("the loader panicked: {reason}"),
        Err(e) => assert!(e.to_string().contains("accessor"), "{e}"),
        Ok(_) => panic!("loaded a file without accessors"),
    }
}

// ---------------------------------------------------------------------------------------
// The TOML config

const VALID: &str = r#"scene = "cornell-box.gltf"

[render]
width = 64
height = 48
spp = 4
seed = 1
threads = 0
tile_size = 16
intersector = "auto"

[camera]
position = [0.278, 0.273, -0.8]
look_at = [0.278, 0.273, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 39.3

[integrator]
plugin = "mcpt"
variant = "entangled"

[output]
exr = "out.exr"
png = "out.png"

[plugins]
search_paths = ["../p"]

[materials.white]
diffuse = "oren-nayar"
sigma_degrees = 20.0
two_sided_emission = false
"#;

fn toml_value() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("4294967296".to_string()),
        Just("9223372036854775807".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e300".to_string()),
        Just("0.0".to_string()),
        Just("-0.0".to_string()),
        Just("\"\"".to_string()),
        Just("\"\\u0000\"".to_string()),
        Just("[]".to_string()),
        Just("[0.0, 0.0, 0.0]".to_string()),
        Just("[nan, 1.0, 2.0]".to_string()),
        Just("[1.0, 2.0]".to_string()),
        Just("{}".to_string()),
        Just("true".to_string()),
        (-1_000_000i64..1_000_000).prop_map(|v| v.to_string()),
        (-1e6f64..1e6).prop_map(|v| format!("{v:?}")),
        "[a-z/._-]{0,12}".prop_map(|s| format!("{s:?}")),
    ]
}

#[derive(Clone, Debug)]
enum ConfigEdit {
    /// Replace the value of the `i`-th `key = value` line.
    Value(usize, String),
    /// Delete the `i`-th line.
    DropLine(usize),
    /// Duplicate the `i`-th line (duplicate keys).
    DupLine(usize),
    /// Insert `key = value` after the `i`-th line.
    Insert(usize, String, String),
    /// Raw byte edit.
    Bytes(Edit),
}

fn config_edit() -> impl Strategy<Value = ConfigEdit> {
    let key = prop_oneof![
        Just("spp".to_string()),
        Just("time".to_string()),
        Just("fov_y".to_string()),
        Just("forward".to_string()),
        Just("width".to_string()),
        "[a-z_]{1,10}",
    ];
    prop_oneof![
        6 => (any::<usize>(), toml_value()).prop_map(|(i, v)| ConfigEdit::Value(i, v)),
        2 => any::<usize>().prop_map(ConfigEdit::DropLine),
        1 => any::<usize>().prop_map(ConfigEdit::DupLine),
        2 => (any::<usize>(), key, toml_value()).prop_map(|(i, k, v)| ConfigEdit::Insert(i, k, v)),
        2 => edit().prop_map(ConfigEdit::Bytes),
    ]
}

fn apply_config(text: &str, e: &ConfigEdit) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    if lines.is_empty() {
        lines.push(String::new());
    }
    let n = lines.len();
    match e {
        ConfigEdit::Value(i, v) => {
            let kv: Vec<usize> = (0..n).filter(|&j| lines[j].contains(" = ")).collect();
            if let Some(&j) = kv.get(i % kv.len().max(1)) {
                let k = lines[j].split(" = ").next().unwrap().to_string();
                lines[j] = format!("{k} = {v}");
            }
        }
        ConfigEdit::DropLine(i) => {
            lines.remove(i % n);
        }
        ConfigEdit::DupLine(i) => {
            let l = lines[i % n].clone();
            lines.insert(i % n, l);
        }
        ConfigEdit::Insert(i, k, v) => lines.insert(i % (n + 1), format!("{k} = {v}")),
        ConfigEdit::Bytes(e) => {
            let mut b = lines.join("\n").into_bytes();
            apply(&mut b, e);
            return String::from_utf8_lossy(&b).into_owned();
        }
    }
    lines.join("\n")
}

fn check_config(
    path: &Path,
    text: &str,
    scene: &flowlight_scene::Scene,
) -> Result<(), TestCaseError> {
    match parse_config(path, text) {
        Ok(cfg) => {
            prop_assert!(cfg.width > 0 && cfg.height > 0 && cfg.tile_size > 0);
            // The camera is built from the config: degenerate values must be errors too.
            match cfg.camera(scene) {
                Ok(_) => {}
                Err(e) => {
                    let m = e.to_string();
                    prop_assert!(m.contains(&path.display().to_string()), "{m}");
                }
            }
        }
        Err(e) => {
            let m = e.to_string();
            prop_assert!(
                m.contains(&path.display().to_string()),
                "error does not name the file: {m}"
            );
        }
    }
    Ok(())
}

fn cornell() -> flowlight_scene::Scene {
    load_gltf(
        &scenes().join("cornell-box/cornell-box.gltf"),
        &BTreeMap::new(),
    )
    .unwrap()
}

#[test]
fn config_parser_survives_random_text() {
    let path = Path::new("/fuzz/config.toml");
    let scene = cornell();
    let text = prop_oneof![
        ".{0,200}",
        // TOML-looking noise: tables, keys, values.
        prop::collection::vec(
            prop_oneof![
                "\\[[a-z.]{0,12}\\]",
                ("[a-z_]{1,8}", toml_value()).prop_map(|(k, v)| format!("{k} = {v}")),
            ],
            0..12
        )
        .prop_map(|l| l.join("\n")),
    ];
    runner(3000)
        .run(&text, |t| check_config(path, &t, &scene))
        .unwrap();
}

#[test]
fn config_parser_survives_mutated_configs() {
    let path = Path::new("/fuzz/config.toml");
    let scene = cornell();
    // The base config must itself be valid, or the mutations test nothing.
    parse_config(path, VALID).unwrap();
    runner(3000)
        .run(&prop::collection::vec(config_edit(), 1..5), |edits| {
            let mut t = VALID.to_string();
            for e in &edits {
                t = apply_config(&t, e);
            }
            check_config(path, &t, &scene)
        })
        .unwrap();
}
