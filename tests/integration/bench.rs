//! `flowlight bench`, `reference` and `compare` run as a user would, on a tiny budget: the
//! suite machinery works end to end (CSV, summary and plots appear, numbers are finite). The
//! real numbers come from `flowlight bench scenes/suite.toml` (docs/results.md).

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

fn flowlight(args: &[&str]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "flowlight {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    // The mini suite has no quoted fields with commas in the columns read here.
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

#[test]
fn mini_suite_writes_csv_plots_and_finite_numbers() {
    let dir = common::scratch("bench-mini");
    let scenes = common::repo().join("scenes");
    let suite = dir.join("mini.toml");
    // The 8-spp references of this 24x24 check are far too noisy to judge anything: the floor
    // rule is loosened here (floor_ratio), and checked at its default below. The scenes name
    // their reference files, so the committed 128x128 ones are not used.
    let text = format!(
        r#"
[bench]
budgets = [0.1, 0.2]
seeds = [1]
threads = 2
width = 24
height = 24
out = "out"
floor_ratio = 1e9

[reference]
spp = 8

[[scene]]
name = "cornell"
config = "{cornell}"
reference = "out/references/cornell.exr"

[[scene]]
name = "mirrors"
config = "{mirrors}"
reference = "out/references/mirrors.exr"

[[method]]
label = "pt"
params = {{ variant = "entangled", layers = true }}

[[method]]
label = "pt-untangled-equi"
plugin = "mcpt"
params = {{ variant = "untangled", termination = "equi" }}
scenes = ["mirrors"]
"#,
        cornell = scenes.join("cornell-box/cornell-box.toml").display(),
        mirrors = scenes.join("mirror-chain/mirror-chain.toml").display(),
    );
    std::fs::write(&suite, &text).unwrap();
    let o = flowlight(&["bench", suite.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("bench summary"), "{stdout}");
    let out = dir.join("out");
    for f in [
        "results.csv",
        "layers.csv",
        "summary.csv",
        "summary.md",
        "cornell.svg",
        "mirrors.svg",
        "cornell-layers.svg",
        "references/cornell.exr",
        "references/mirrors.exr",
    ] {
        let p = out.join(f);
        assert!(
            p.metadata().is_ok_and(|m| m.len() > 0),
            "{} missing",
            p.display()
        );
    }
    let svg = std::fs::read_to_string(out.join("cornell.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("relMSE") && svg.contains("pt"));

    // 2 budgets x 1 seed: pt on both scenes, pt-untangled-equi on one.
    let (h, rows) = csv_rows(&out.join("results.csv"));
    assert_eq!(rows.len(), 2 * 2 + 2, "{rows:?}");
    for r in &rows {
        for c in ["wall_s", "spp", "relmse", "rmse", "luminance_ratio"] {
            let v: f64 = r[column(&h, c)].parse().unwrap();
            assert!(v.is_finite() && v > 0.0, "{c} = {v} in {r:?}");
        }
        let floor: f64 = r[column(&h, "reference_floor")].parse().unwrap();
        assert!(floor.is_finite() && floor >= 0.0);
        assert_eq!(r[column(&h, "invalid_samples")], "0");
    }
    // Layer errors only for the method that writes layers.
    let (h, rows) = csv_rows(&out.join("layers.csv"));
    assert!(!rows.is_empty());
    for r in &rows {
        assert_eq!(r[column(&h, "method")], "pt");
        let v: f64 = r[column(&h, "rmse")].parse().unwrap();
        assert!(v.is_finite());
    }
    let (h, rows) = csv_rows(&out.join("summary.csv"));
    assert_eq!(rows.len(), 6);
    for r in rows.iter().filter(|r| r[column(&h, "method")] == "pt") {
        let rel: f64 = r[column(&h, "relative_efficiency")].parse().unwrap();
        assert!(
            (rel - 1.0).abs() < 1e-9,
            "baseline relative to itself: {rel}"
        );
    }
    for r in &rows {
        let e: f64 = r[column(&h, "efficiency")].parse().unwrap();
        assert!(e.is_finite() && e > 0.0);
    }

    // Cached references are reused: a second run renders none. With a strict floor rule
    // (floor ≤ 10⁻⁶ of the smallest relMSE: refused whatever the machine's speed; the rule's
    // arithmetic is checked in flowlight-bench's unit tests) the comparison is refused: one
    // line per scene naming floor, smallest relMSE and the spp needed, exit status 1, and the
    // raw rows are still written.
    // Plus a method that renders another path depth than the reference: refused by itself,
    // before its other renders, while the bench goes on.
    let strict = dir.join("strict.toml");
    let shallow =
        "\n[[method]]\nlabel = \"shallow\"\nparams = { path_depth = 3 }\nscenes = [\"cornell\"]\n";
    std::fs::write(
        &strict,
        text.replace("floor_ratio = 1e9", "floor_ratio = 1e-6") + shallow,
    )
    .unwrap();
    std::fs::remove_file(out.join("results.csv")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["bench", strict.to_str().unwrap(), "--budgets", "0.05"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("reference for"), "{stderr}");
    for scene in ["cornell", "mirrors"] {
        let line = stderr
            .lines()
            .find(|l| l.starts_with(&format!("scene '{scene}': reference floor")))
            .unwrap_or_else(|| panic!("no refusal for {scene}:\n{stderr}"));
        assert!(
            line.contains("comparison refused") && line.contains("spp (now 8)"),
            "{line}"
        );
    }
    assert!(
        stderr.lines().any(|l| l.starts_with(
            "scene 'cornell', method 'shallow': renders path_depth 3 but the reference"
        ) && l.contains("has path_depth 8")),
        "{stderr}"
    );
    let (_, rows) = csv_rows(&out.join("results.csv"));
    assert_eq!(rows.len(), 3, "{rows:?}");
}

#[test]
fn a_committed_reference_of_another_size_is_refused() {
    // glass-caustic has a committed 128x128 reference (scenes/glass-caustic/reference/): a suite
    // at 24x24 that does not name its own reference file must refuse it before rendering.
    let dir = common::scratch("bench-committed");
    let suite = dir.join("s.toml");
    std::fs::write(
        &suite,
        format!(
            "[bench]\nbudgets = [0.1]\nwidth = 24\nheight = 24\nout = \"out\"\n\
             [[scene]]\nname = \"m\"\nconfig = \"{}\"\n[[method]]\nlabel = \"pt\"\n",
            common::repo()
                .join("scenes/glass-caustic/glass-caustic.toml")
                .display()
        ),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["bench", suite.to_str().unwrap()])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("reference") && e.contains("is 128x128") && e.contains("renders at 24x24"),
        "{e}"
    );
}

#[test]
fn reference_and_compare() {
    let dir = common::scratch("bench-ref");
    let cfg = common::scene_config("furnace/furnace.toml");
    let reference = dir.join("ref.exr");
    let o = flowlight(&[
        "reference",
        cfg.to_str().unwrap(),
        "--spp",
        "32",
        "--threads",
        "2",
        "--out",
        reference.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("32 spp"));
    let (_, _, layers) = flowlight_host::output::read_exr_rgb(&reference).unwrap();
    assert!(layers.iter().any(|(n, _)| n == "variance"));
    let meta = flowlight_host::output::read_exr_metadata(&reference).unwrap();
    let get = |k: &str| meta.get(k).map(str::to_string);
    assert_eq!(get("flowlight.reference").as_deref(), Some("true"));
    assert_eq!(get("flowlight.spp").as_deref(), Some("32"));

    // Furnace: every pixel is 2 (up to the depth-16 tail); the variance of a 32-spp mean is
    // small but not zero.
    let r = flowlight_bench::read_reference(&reference).unwrap();
    let v = r.variance.as_ref().unwrap();
    let mean_var = v.iter().map(|c| c.g as f64).sum::<f64>() / v.len() as f64;
    assert!(mean_var > 0.0 && mean_var < 0.05, "{mean_var}");

    let a = dir.join("a.exr");
    flowlight(&[
        "render",
        cfg.to_str().unwrap(),
        "--spp",
        "4",
        "-q",
        "--out",
        a.to_str().unwrap(),
    ]);
    let err_png = dir.join("err.png");
    let o = flowlight(&[
        "compare",
        a.to_str().unwrap(),
        reference.to_str().unwrap(),
        "--out",
        err_png.to_str().unwrap(),
    ]);
    let s = String::from_utf8_lossy(&o.stdout);
    for key in ["RMSE", "relMSE", "luminance ratio", "reference floor"] {
        assert!(s.contains(key), "{s}");
    }
    let ratio: f64 = s
        .lines()
        .find(|l| l.contains("luminance ratio"))
        .and_then(|l| l.split_whitespace().nth(2))
        .unwrap()
        .parse()
        .unwrap();
    assert!((ratio - 1.0).abs() < 0.05, "{s}");
    assert!(std::fs::read(&err_png).unwrap().starts_with(b"\x89PNG"));

    // Identical images: zero error. Different sizes: one clear error line.
    let o = flowlight(&["compare", a.to_str().unwrap(), a.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("relMSE          0.000000e0"));
    let small = dir.join("small.exr");
    let px = vec![flowlight_core::Rgb::splat(1.0); 4 * 3];
    flowlight_host::output::write_exr(
        &small,
        4,
        3,
        &[flowlight_host::output::ImageLayer {
            name: String::new(),
            pixels: &px,
        }],
        &Default::default(),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["compare", a.to_str().unwrap(), small.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.starts_with("error:") && e.contains("32x32"), "{e}");

    // A reference from two existing renders: averaged, with a variance layer.
    let b = dir.join("b.exr");
    flowlight(&[
        "render",
        cfg.to_str().unwrap(),
        "--spp",
        "4",
        "--seed",
        "9",
        "-q",
        "--out",
        b.to_str().unwrap(),
    ]);
    let ab = dir.join("ab.exr");
    flowlight(&[
        "reference",
        "--from",
        a.to_str().unwrap(),
        "--from",
        b.to_str().unwrap(),
        "--out",
        ab.to_str().unwrap(),
    ]);
    let r = flowlight_bench::read_reference(&ab).unwrap();
    assert_eq!(r.spp, 8.0);
    assert!(r.variance.is_some());
}

/// Runs `flowlight args` expecting it to fail with one `error:` line, which it returns.
fn flowlight_error(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(args)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "flowlight {args:?}: {e}");
    let lines: Vec<&str> = e.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(lines.len(), 1, "{e}");
    lines[0].to_string()
}

#[test]
fn d14_reference_from_the_same_render_twice_is_refused() {
    let dir = common::scratch("bench-ref-twice");
    let cfg = common::scene_config("furnace/furnace.toml");
    let a = dir.join("a.exr");
    let render = |out: &Path, seed: &str| {
        flowlight(&[
            "render",
            cfg.to_str().unwrap(),
            "--spp",
            "2",
            "--seed",
            seed,
            "-q",
            "--out",
            out.to_str().unwrap(),
        ]);
    };
    render(&a, "3");
    let copy = dir.join("copy.exr");
    std::fs::copy(&a, &copy).unwrap();
    let same_seed = dir.join("same-seed.exr");
    render(&same_seed, "3");
    let out = dir.join("ref.exr");
    for (b, names) in [
        (&a, "given twice"),
        (&copy, "same seed"),
        (&same_seed, "same seed"),
    ] {
        let e = flowlight_error(&[
            "reference",
            "--from",
            a.to_str().unwrap(),
            "--from",
            b.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(e.contains(names), "{e}");
    }
    assert!(!out.exists());
}

#[test]
fn d16_reference_with_an_odd_sample_count_renders_all_of_them() {
    let dir = common::scratch("bench-ref-odd");
    let cfg = common::scene_config("furnace/furnace.toml");
    let reference = dir.join("ref.exr");
    let o = flowlight(&[
        "reference",
        cfg.to_str().unwrap(),
        "--spp",
        "3",
        "--threads",
        "2",
        "--out",
        reference.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&o.stdout).contains(" 3 spp"));
    let meta = flowlight_host::output::read_exr_metadata(&reference).unwrap();
    assert_eq!(meta.get("flowlight.spp"), Some("3"));
}

#[test]
fn d2_compare_and_reference_never_write_over_an_input() {
    let dir = common::scratch("bench-d2");
    let cfg = dir.join("furnace.toml");
    std::fs::copy(common::scene_config("furnace/furnace.toml"), &cfg).unwrap();
    std::fs::copy(
        common::scene_config("furnace/furnace.gltf"),
        dir.join("furnace.gltf"),
    )
    .unwrap();
    let a = dir.join("a.exr");
    let b = dir.join("b.exr");
    for (out, seed) in [(&a, "1"), (&b, "2")] {
        flowlight(&[
            "render",
            cfg.to_str().unwrap(),
            "--spp",
            "2",
            "--seed",
            seed,
            "-q",
            "--out",
            out.to_str().unwrap(),
        ]);
    }
    let before = std::fs::read(&a).unwrap();
    let e = flowlight_error(&[
        "compare",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--out",
        a.to_str().unwrap(),
    ]);
    assert!(e.contains("refusing to overwrite"), "{e}");
    let e = flowlight_error(&[
        "reference",
        "--from",
        a.to_str().unwrap(),
        "--from",
        b.to_str().unwrap(),
        "--out",
        b.to_str().unwrap(),
    ]);
    assert!(e.contains("refusing to overwrite"), "{e}");
    let cfg_before = std::fs::read(&cfg).unwrap();
    let e = flowlight_error(&[
        "reference",
        cfg.to_str().unwrap(),
        "--spp",
        "2",
        "--out",
        cfg.to_str().unwrap(),
    ]);
    assert!(e.contains("the config"), "{e}");
    assert_eq!(std::fs::read(&a).unwrap(), before);
    assert_eq!(std::fs::read(&cfg).unwrap(), cfg_before);
}
