//! Distributed renders (docs/distributed.md): `render --part/--samples` and
//! `flowlight merge`, run as a user would, and the recipes under docs/distributed/.

use crate::common;

use flowlight_core::Rgb;
use flowlight_host::output::{read_exr_metadata, read_exr_rgb};
use std::path::{Path, PathBuf};
use std::process::Command;

fn flowlight() -> Command {
    Command::new(env!("CARGO_BIN_EXE_flowlight"))
}

/// A copy of a scene config at `size`² pixels with `spp` samples (and `extra` lines added
/// to `[render]`), its scene named by absolute path.
fn small_config(dir: &Path, base: &str, size: u32, spp: u32, extra: &str) -> PathBuf {
    let src = common::scene_config(base);
    let text = std::fs::read_to_string(&src).unwrap();
    let scene_dir = src.parent().unwrap();
    let mut out = String::new();
    let mut in_render = false;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            in_render = t.starts_with("[render]");
        }
        if t.starts_with("scene =") {
            let name = t.split('"').nth(1).unwrap();
            out += &format!("scene = {:?}\n", scene_dir.join(name).display().to_string());
        } else if in_render && (t.starts_with("width =") || t.starts_with("height =")) {
            out += &format!("{} = {size}\n", &t[..t.find(' ').unwrap()]);
        } else if t.starts_with("tile_size =") {
            out += "tile_size = 16\n";
        } else if t.starts_with("spp =") {
            out += &format!("spp = {spp}\n");
        } else if t.starts_with("png =") {
            continue;
        } else if t.starts_with("[render]") {
            out += &format!("[render]\n{extra}\n");
        } else {
            out += line;
            out += "\n";
        }
    }
    let path = dir.join(base.replace('/', "-"));
    std::fs::write(&path, out).unwrap();
    path
}

/// The stderr of a command that must fail.
fn run_err(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    assert!(!o.status.success(), "{cmd:?} succeeded");
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn render_part(cfg: &Path, out: &Path, args: &[&str]) {
    common::run_ok(
        flowlight()
            .arg("render")
            .arg(cfg)
            .args(["-q", "--out"])
            .arg(out)
            .args(args),
    );
}

fn merge(out: &Path, parts: &[PathBuf], extra: &[&str]) -> Command {
    let mut c = flowlight();
    c.arg("merge").arg(out).args(parts).args(extra);
    c
}

fn bits(layers: &[(String, Vec<Rgb>)]) -> Vec<(String, Vec<[u32; 3]>)> {
    layers
        .iter()
        .map(|(n, px)| {
            (
                n.clone(),
                px.iter()
                    .map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
                    .collect(),
            )
        })
        .collect()
}

fn meta(path: &Path, key: &str) -> String {
    read_exr_metadata(path)
        .unwrap()
        .get(key)
        .map(str::to_string)
        .unwrap_or_else(|| panic!("{} has no {key}", path.display()))
}

#[test]
fn mcpt_parts_merged_equal_the_full_render_bitwise() {
    let dir = common::scratch("dist-mcpt");
    // 16 spp: the full render's passes hold 1, 2, 4, 8 and 1 samples, the parts' 1, 2, 1:
    // the groupings differ, the sums must not.
    let cfg = small_config(&dir, "cornell-box/cornell-box.toml", 24, 16, "");
    let full = dir.join("full.exr");
    render_part(&cfg, &full, &["--threads", "2", "--set", "layers=true"]);
    let mut parts = Vec::new();
    for (k, threads) in [(0, "1"), (1, "3"), (2, "2"), (3, "1")] {
        let p = dir.join(format!("part-{k}.exr"));
        render_part(
            &cfg,
            &p,
            &[
                "--part",
                &format!("{k}/4"),
                "--threads",
                threads,
                "--set",
                "layers=true",
            ],
        );
        assert_eq!(
            meta(&p, "flowlight.samples"),
            format!("{}..{}", 4 * k, 4 * k + 4)
        );
        assert_eq!(meta(&p, "flowlight.part"), format!("{k}/4"));
        parts.push(p);
    }
    let merged = dir.join("merged.exr");
    // Any order of the inputs.
    parts.reverse();
    let summary = common::run_ok(&mut merge(&merged, &parts, &[]));
    assert!(summary.contains("0..16 of 0..16"), "{summary}");
    let (_, _, a) = read_exr_rgb(&full).unwrap();
    let (_, _, b) = read_exr_rgb(&merged).unwrap();
    assert!(a.len() > 2, "the lighting layers are in the files");
    assert!(a[0].1.iter().any(|c| c.luminance() > 0.0));
    assert_eq!(
        bits(&a),
        bits(&b),
        "merged parts differ from the full render"
    );
    assert_eq!(meta(&merged, "flowlight.partial"), "false");
    assert_eq!(meta(&merged, "flowlight.spp"), "16");
    // A part alone is a quarter of the samples: a different image.
    let (_, _, one) = read_exr_rgb(&parts[0]).unwrap();
    assert_ne!(bits(&one)[0], bits(&a)[0]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Region means of a `size`² image in 4 × 4 blocks.
fn regions(img: &[Rgb], size: usize) -> Vec<f64> {
    let b = size / 4;
    let mut out = vec![0.0; 16];
    for (i, c) in img.iter().enumerate() {
        let (x, y) = (i % size, i / size);
        out[(y / b) * 4 + x / b] += c.luminance() as f64 / (b * b) as f64;
    }
    out
}

#[test]
fn erpt_parts_merge_to_the_full_render_and_agree_with_path_tracing() {
    let dir = common::scratch("dist-erpt");
    let size = 32;
    let n = 8;
    let cfg = small_config(&dir, "cornell-box/erpt.toml", size, n, "");
    let full = dir.join("full.exr");
    render_part(&cfg, &full, &["--threads", "2"]);
    let mut parts = Vec::new();
    let mut per_part = Vec::new();
    for k in 0..n {
        let p = dir.join(format!("part-{k}.exr"));
        render_part(&cfg, &p, &["--part", &format!("{k}/{n}"), "--threads", "2"]);
        per_part.push(regions(&read_exr_rgb(&p).unwrap().2[0].1, size as usize));
        parts.push(p);
    }
    let merged = dir.join("merged.exr");
    common::run_ok(&mut merge(&merged, &parts, &[]));
    assert!(
        dir.join("merged.stats.json").exists(),
        "ERPT's statistics are merged"
    );
    let stats = std::fs::read_to_string(dir.join("merged.stats.json")).unwrap();
    let seeds = |text: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.trim().starts_with("\"seeds\":"))
            .unwrap();
        line.split(':')
            .nth(1)
            .unwrap()
            .trim()
            .trim_end_matches(',')
            .parse()
            .unwrap()
    };
    let part_seeds: f64 = (0..n)
        .map(|k| seeds(&std::fs::read_to_string(dir.join(format!("part-{k}.stats.json"))).unwrap()))
        .sum();
    assert_eq!(seeds(&stats), part_seeds);
    let (_, _, a) = read_exr_rgb(&full).unwrap();
    let (_, _, b) = read_exr_rgb(&merged).unwrap();
    // Same tiles, same per-(tile, sample) quanta and chains, exact sums: the same bits.
    assert_eq!(
        bits(&a),
        bits(&b),
        "merged ERPT parts differ from the full render"
    );

    // And unbiased: per region, the merged image against a path-traced reference, with the
    // noise of the mean estimated from the spread of the 8 one-sample parts.
    let mut s = common::renderer_at("cornell-box/cornell-box.toml", size, size, 1024, &[]);
    s.options.seed = 77;
    let reference = common::render(&s).frame.image();
    let refs = regions(&reference, size as usize);
    let m = regions(&b[0].1, size as usize);
    let b_px = (size / 4) as usize;
    for k in 0..16 {
        let vals: Vec<f64> = per_part.iter().map(|r| r[k]).collect();
        let mean = vals.iter().sum::<f64>() / n as f64;
        assert!(
            (mean - m[k]).abs() <= 1e-5 * m[k].max(1e-3),
            "region {k}: the merge is the mean of the parts"
        );
        let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0);
        let px: Vec<Rgb> = reference
            .iter()
            .enumerate()
            .filter(|(i, _)| ((i / size as usize) / b_px) * 4 + (i % size as usize) / b_px == k)
            .map(|(_, c)| *c)
            .collect();
        let ref_se = common::mean_and_stderr(&px, |c| c.luminance()).1;
        let se = (var / n as f64 + ref_se.powi(2)).sqrt().max(1e-4 * refs[k]);
        let z = (m[k] - refs[k]) / se;
        assert!(
            z.abs() < 5.0,
            "region {k}: merged ERPT {:.5} vs reference {:.5} (z = {z:.2})",
            m[k],
            refs[k]
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn merge_refuses_mismatched_parts_overlaps_and_gaps_naming_the_files() {
    let dir = common::scratch("dist-refuse");
    let cfg = small_config(&dir, "cornell-box/cornell-box.toml", 8, 8, "");
    let p = |name: &str| dir.join(name);
    render_part(&cfg, &p("a.exr"), &["--part", "0/2"]);
    render_part(&cfg, &p("b.exr"), &["--part", "1/2"]);
    render_part(
        &cfg,
        &p("depth.exr"),
        &["--part", "1/2", "--set", "path_depth=3"],
    );
    render_part(&cfg, &p("seed.exr"), &["--part", "1/2", "--seed", "9"]);
    render_part(&cfg, &p("over.exr"), &["--samples", "2..6"]);
    render_part(&cfg, &p("whole.exr"), &[]);
    let out = p("out.exr");

    let e = run_err(&mut merge(&out, &[p("a.exr"), p("depth.exr")], &[]));
    assert!(
        e.contains("different configs") && e.contains("a.exr") && e.contains("depth.exr"),
        "{e}"
    );
    let e = run_err(&mut merge(&out, &[p("a.exr"), p("seed.exr")], &[]));
    assert!(
        e.contains("different seeds (1 vs 9)") && e.contains("seed.exr"),
        "{e}"
    );
    let e = run_err(&mut merge(
        &out,
        &[p("a.exr"), p("over.exr"), p("b.exr")],
        &[],
    ));
    assert!(
        e.contains("a.exr (samples 0..4) and")
            && e.contains("over.exr (samples 2..6)")
            && e.contains("overlap"),
        "{e}"
    );
    let e = run_err(&mut merge(&out, &[p("whole.exr"), p("b.exr")], &[]));
    assert!(e.contains("whole.exr: not a part"), "{e}");
    let e = run_err(&mut merge(&p("a.exr"), &[p("a.exr"), p("b.exr")], &[]));
    assert!(e.contains("refusing to overwrite an input"), "{e}");
    assert!(!out.exists(), "nothing was written");

    // A gap: refused, or written as partial with --allow-missing.
    let e = run_err(&mut merge(&out, &[p("b.exr")], &[]));
    assert!(
        e.contains("samples 0..4 of 0..8 are in none of the parts"),
        "{e}"
    );
    let o = merge(&out, &[p("b.exr")], &["--allow-missing"])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("samples 0..4 of 0..8 are missing"));
    assert_eq!(meta(&out, "flowlight.partial"), "true");
    assert_eq!(meta(&out, "flowlight.missing"), "0..4");
    // A part with a time budget cannot be: it has no fixed range.
    let e = run_err(
        flowlight()
            .arg("render")
            .arg(&cfg)
            .args(["--part", "0/2", "--time", "1"]),
    );
    assert!(e.contains("--time"), "{e}");
    let e = run_err(
        flowlight()
            .arg("render")
            .arg(&cfg)
            .args(["--part", "2/2", "-q"])
            .arg("--out")
            .arg(p("x.exr")),
    );
    assert!(e.contains("K must be in 0..N"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_recipes_render_the_cornell_box_in_four_parts() {
    let dir = common::scratch("dist-recipes");
    let cfg = small_config(&dir, "cornell-box/cornell-box.toml", 16, 8, "");
    let full = dir.join("full.exr");
    render_part(&cfg, &full, &[]);
    let full_bits = bits(&read_exr_rgb(&full).unwrap().2);
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_flowlight"));
    let path = format!(
        "{}:{}",
        bin.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let recipes = common::repo().join("docs/distributed");

    // GNU parallel when CI has it, else the xargs -P fallback; both when it is installed.
    let has_parallel = Command::new("parallel")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let mut modes = vec![true];
    if has_parallel {
        modes.push(false);
    }
    for force_xargs in modes {
        let out = dir.join(format!("gnu-{force_xargs}.exr"));
        let mut c = Command::new("bash");
        c.arg(recipes.join("parallel.sh"))
            .arg(&cfg)
            .arg("4")
            .arg(&out)
            .env("FLOWLIGHT", &bin)
            .env("FLOWLIGHT_ARGS", "--threads 1")
            .env("JOBS", "2")
            .env("PARTS_DIR", dir.join(format!("parts-{force_xargs}")));
        if force_xargs {
            c.env("NO_GNU_PARALLEL", "1");
        }
        let o = c.output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(
            err.contains(if force_xargs { "xargs" } else { "GNU parallel" }),
            "{err}"
        );
        assert_eq!(bits(&read_exr_rgb(&out).unwrap().2), full_bits);
    }

    // The Slurm array script, as four array tasks would run it.
    let slurm_parts = dir.join("slurm");
    for k in 0..4 {
        let mut c = Command::new("bash");
        c.arg(recipes.join("slurm-array.sh"))
            .env("PATH", &path)
            .env("CONFIG", &cfg)
            .env("PARTS_DIR", &slurm_parts)
            .env("SLURM_ARRAY_TASK_ID", k.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "4")
            .env("SLURM_CPUS_PER_TASK", "1");
        common::run_ok(&mut c);
    }
    let parts: Vec<PathBuf> = (0..4)
        .map(|k| slurm_parts.join(format!("part-{k}.exr")))
        .collect();
    let out = dir.join("slurm.exr");
    common::run_ok(&mut merge(&out, &parts, &[]));
    assert_eq!(bits(&read_exr_rgb(&out).unwrap().2), full_bits);

    // The Kubernetes Indexed Job's container command, once per completion index.
    let manifest = std::fs::read_to_string(recipes.join("k8s-indexed-job.yaml")).unwrap();
    assert!(manifest.contains("completionMode: Indexed") && manifest.contains("completions: 4"));
    let script = manifest
        .lines()
        .find(|l| l.contains("--part \"$JOB_COMPLETION_INDEX/$PARTS\""))
        .unwrap()
        .trim()
        .trim_start_matches("- ")
        .to_string();
    let k8s_parts = dir.join("k8s");
    for k in 0..4 {
        let mut c = Command::new("sh");
        c.args(["-c", &script])
            .env("PATH", &path)
            .env("CONFIG", &cfg)
            .env("PARTS_DIR", &k8s_parts)
            .env("PARTS", "4")
            .env("JOB_COMPLETION_INDEX", k.to_string());
        common::run_ok(&mut c);
    }
    let parts: Vec<PathBuf> = (0..4)
        .map(|k| k8s_parts.join(format!("part-{k}.exr")))
        .collect();
    let out = dir.join("k8s.exr");
    common::run_ok(&mut merge(&out, &parts, &[]));
    assert_eq!(bits(&read_exr_rgb(&out).unwrap().2), full_bits);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn parts_of_an_enormously_bright_scene_keep_their_energy_through_the_merge() {
    // Emission 1e30: channel values beyond the fixed-point range go to the f64 side sums,
    // which the parts store and the merge adds.
    let dir = common::scratch("dist-bright");
    let src = common::scene_config("furnace/furnace.gltf");
    let gltf = std::fs::read_to_string(&src).unwrap();
    let patched = gltf.replace("\"emissiveStrength\": 1.0", "\"emissiveStrength\": 1e30");
    assert_ne!(gltf, patched);
    std::fs::write(dir.join("furnace.gltf"), patched).unwrap();
    let cfg_text = std::fs::read_to_string(common::scene_config("furnace/furnace.toml"))
        .unwrap()
        .replace("width = 32", "width = 8")
        .replace("height = 32", "height = 8");
    let cfg = dir.join("furnace.toml");
    std::fs::write(&cfg, cfg_text).unwrap();
    let full = dir.join("full.exr");
    render_part(&cfg, &full, &["--spp", "8"]);
    let parts: Vec<PathBuf> = (0..2).map(|k| dir.join(format!("p{k}.exr"))).collect();
    for (k, p) in parts.iter().enumerate() {
        render_part(&cfg, p, &["--spp", "8", "--part", &format!("{k}/2")]);
    }
    let merged = dir.join("merged.exr");
    common::run_ok(&mut merge(&merged, &parts, &[]));
    let (_, _, a) = read_exr_rgb(&full).unwrap();
    let (_, _, b) = read_exr_rgb(&merged).unwrap();
    let mean = |l: &[Rgb]| l.iter().map(|c| c.luminance() as f64).sum::<f64>() / l.len() as f64;
    // The furnace's pixels are 2·(1 − 0.5⁹)·1e30 in expectation.
    assert!(
        (mean(&a[0].1) / 1.996e30 - 1.0).abs() < 0.1,
        "{}",
        mean(&a[0].1)
    );
    for (x, y) in a[0].1.iter().zip(&b[0].1) {
        assert!((x.r / y.r - 1.0).abs() < 1e-5, "{x:?} vs {y:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn d7_a_part_without_out_never_replaces_the_final_image() {
    let dir = common::scratch("dist-d7");
    let cfg = small_config(&dir, "furnace/furnace.toml", 16, 4, "");
    common::run_ok(
        flowlight()
            .current_dir(&dir)
            .arg("render")
            .arg(&cfg)
            .args(["-q", "--part", "1/2"]),
    );
    assert!(
        !dir.join("furnace.exr").exists(),
        "the part took the final name"
    );
    let part = dir.join("furnace.part-1-of-2.exr");
    assert_eq!(meta(&part, "flowlight.part"), "1/2");
}

#[test]
fn d15_samples_beyond_the_renders_spp_are_refused() {
    let dir = common::scratch("dist-d15");
    let cfg = small_config(&dir, "furnace/furnace.toml", 16, 8, "");
    let err = run_err(
        flowlight()
            .arg("render")
            .arg(&cfg)
            .args(["-q", "--samples", "8..12", "--out"])
            .arg(dir.join("p.exr")),
    );
    assert!(err.contains("8..12") && err.contains("0..8"), "{err}");
    assert!(!dir.join("p.exr").exists());
}

#[test]
fn d16_a_part_of_a_timed_render_names_the_time_budget() {
    let dir = common::scratch("dist-d16");
    let cfg = small_config(&dir, "furnace/furnace.toml", 16, 8, "");
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, text.replace("spp = 8\n", "time = 1.0\n")).unwrap();
    let err = run_err(
        flowlight()
            .arg("render")
            .arg(&cfg)
            .args(["-q", "--part", "0/2", "--out"])
            .arg(dir.join("p.exr")),
    );
    assert!(
        err.contains("time budget") && !err.contains("0 parts"),
        "{err}"
    );
}

/// Rewrites part `from` as `to` with its `samples` channel scaled by `factor`, keeping its
/// metadata (checksum included), as another tool might.
fn scale_samples(from: &Path, to: &Path, factor: u32) {
    use flowlight_host::output::{read_exr_u32, write_exr_with_raw, ImageLayer, RawChannel};
    let (w, h, channels) = read_exr_u32(from).unwrap();
    let (_, _, layers) = read_exr_rgb(from).unwrap();
    let raw: Vec<RawChannel> = channels
        .into_iter()
        .map(|(name, samples)| RawChannel {
            samples: if name == "samples" {
                samples.iter().map(|s| s * factor).collect()
            } else {
                samples
            },
            name,
        })
        .collect();
    let image_layers: Vec<ImageLayer> = layers
        .iter()
        .map(|(n, px)| ImageLayer {
            name: n.clone(),
            pixels: px,
        })
        .collect();
    let meta = read_exr_metadata(from).unwrap();
    write_exr_with_raw(to, w, h, &image_layers, &raw, &meta).unwrap();
}

#[test]
fn d13_merge_refuses_parts_whose_sums_or_statistics_changed() {
    let dir = common::scratch("dist-d13");
    let cfg = small_config(&dir, "furnace/erpt.toml", 16, 2, "");
    let parts: Vec<PathBuf> = (0..2).map(|k| dir.join(format!("p{k}.exr"))).collect();
    for (k, p) in parts.iter().enumerate() {
        render_part(&cfg, p, &["--part", &format!("{k}/2")]);
    }
    let stats = |p: &Path| p.with_extension("stats.json");
    let out = dir.join("merged.exr");
    // The untouched parts merge.
    common::run_ok(&mut merge(&out, &parts, &[]));
    // Samples doubled or zeroed by another tool.
    for factor in [2, 0] {
        let bad = dir.join(format!("scaled{factor}.exr"));
        scale_samples(&parts[0], &bad, factor);
        std::fs::copy(stats(&parts[0]), stats(&bad)).unwrap();
        let err = run_err(&mut merge(&out, &[bad.clone(), parts[1].clone()], &[]));
        assert!(err.contains("scaled") && err.contains("checksum"), "{err}");
    }
    // A truncated statistics file, and another part's.
    let text = std::fs::read_to_string(stats(&parts[0])).unwrap();
    let cut: String = text
        .lines()
        .take(text.lines().count() / 2)
        .collect::<Vec<_>>()
        .join("\n");
    for (name, json) in [
        ("truncated", cut),
        (
            "foreign",
            std::fs::read_to_string(stats(&parts[1])).unwrap(),
        ),
    ] {
        let p = dir.join(format!("{name}.exr"));
        std::fs::copy(&parts[0], &p).unwrap();
        std::fs::write(stats(&p), json).unwrap();
        let err = run_err(&mut merge(&out, &[p.clone(), parts[1].clone()], &[]));
        assert!(err.contains(&format!("{name}.stats.json")), "{err}");
    }
}

#[test]
fn d2_merge_never_overwrites_the_config_or_scene_of_its_parts() {
    let dir = common::scratch("dist-d2");
    let cfg = small_config(&dir, "furnace/furnace.toml", 16, 2, "");
    let parts: Vec<PathBuf> = (0..2).map(|k| dir.join(format!("p{k}.exr"))).collect();
    for (k, p) in parts.iter().enumerate() {
        render_part(&cfg, p, &["--part", &format!("{k}/2")]);
    }
    let before = std::fs::read(&cfg).unwrap();
    let err = run_err(&mut merge(&cfg, &parts, &[]));
    assert!(err.contains("is the config"), "{err}");
    assert_eq!(std::fs::read(&cfg).unwrap(), before);
}

/// docs/distributed.md's Slurm recipe on a real one-node cluster (tests/slurm/one-node.sh):
/// a job array of four parts under a per-task memory limit, one task killed and
/// resubmitted, merged, and equal bit for bit to the single-machine render. Skipped, with
/// the reason printed, where it cannot run (not root, Slurm or munge not installed).
#[test]
fn slurm_job_array_with_a_killed_task_merges_to_the_full_render() {
    let dir = common::scratch("dist-slurm");
    let cfg = small_config(&dir, "cornell-box/cornell-box.toml", 16, 8, "");
    let full = dir.join("full.exr");
    render_part(&cfg, &full, &[]);
    let out = dir.join("slurm.exr");
    let script = common::repo().join("tests/slurm/one-node.sh");
    // Bounded: the script's own waits end in minutes, and `timeout` ends it regardless.
    let o = Command::new("timeout")
        .args(["-k", "10", "900", "bash"])
        .arg(&script)
        .env("FLOWLIGHT", env!("CARGO_BIN_EXE_flowlight"))
        .env("CONFIG", &cfg)
        .env("OUT", &out)
        .env("WORK", dir.join("cluster"))
        .env("PARTS", "4")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    if o.status.code() == Some(77) {
        eprintln!("slurm test {}", stdout.trim());
        return;
    }
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("killed task") && stdout.contains("resubmitted task 2"),
        "{stdout}"
    );
    assert_eq!(
        bits(&read_exr_rgb(&out).unwrap().2),
        bits(&read_exr_rgb(&full).unwrap().2)
    );
}
