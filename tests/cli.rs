//! The `flowlight` command line, run as a user would.

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn flowlight() -> Command {
    Command::new(env!("CARGO_BIN_EXE_flowlight"))
}

#[test]
fn render_writes_an_exr_and_a_summary() {
    let dir = common::scratch("cli-render");
    let out = dir.join("nested/furnace.exr");
    let o = flowlight()
        .args([
            "render",
            common::scene_config("furnace/furnace.toml")
                .to_str()
                .unwrap(),
            "--spp",
            "2",
            "-q",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for key in [
        "wall time",
        "samples/s",
        "rays/s",
        "NaN/Inf samples 0 discarded",
        "intersector     ",
    ] {
        assert!(stdout.contains(key), "summary lacks '{key}':\n{stdout}");
    }
    let (w, h, layers) = flowlight_host::output::read_exr_rgb(&out).unwrap();
    assert_eq!((w, h), (32, 32));
    assert!(layers[0]
        .1
        .iter()
        .all(|c| c.is_valid_radiance() && c.luminance() > 0.5));
}

#[test]
fn bad_config_is_one_clear_line_and_exit_code_1() {
    let dir = common::scratch("cli-bad");
    let cfg = dir.join("bad.toml");
    std::fs::write(&cfg, "scene = \"x.gltf\"\n[render]\nwidht = 5\n").unwrap();
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with("error: "), "{err}");
    assert!(err.contains("bad.toml") && err.contains("widht"), "{err}");

    let o = flowlight()
        .args(["render", "/nonexistent/config.toml"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/config.toml"));
}

#[test]
fn plugins_lists_versions_and_parameters_and_refuses_mismatches() {
    let o = flowlight().arg("plugins").output().unwrap();
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(s.contains("mcpt (Integrator)"), "{s}");
    assert!(
        s.contains(flowlight_sdk::abi::SDK_VERSION) && s.contains("rustc"),
        "{s}"
    );
    assert!(s.contains("termination") && s.contains("path_depth"), "{s}");
    assert!(
        s.contains("flowlight_test_bad_abi")
            && s.contains("refused: ")
            && s.contains("ABI version"),
        "{s}"
    );
}

#[test]
fn interrupt_saves_what_has_accumulated() {
    let dir = common::scratch("cli-interrupt");
    let out = dir.join("partial.exr");
    let child = flowlight()
        .args([
            "render",
            common::scene_config("furnace/furnace.toml")
                .to_str()
                .unwrap(),
            "--spp",
            "100000000",
            "-q",
            "--threads",
            "1",
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Let it render for a moment, then press Ctrl-C.
    std::thread::sleep(Duration::from_millis(1500));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let start = Instant::now();
    let o = child.wait_with_output().unwrap();
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "render did not stop promptly"
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("interrupted"), "{stdout}");
    let (_, _, layers) = flowlight_host::output::read_exr_rgb(&out).unwrap();
    let lit = layers[0].1.iter().filter(|c| c.luminance() > 0.0).count();
    assert!(lit > 0, "the partial image is empty");
    assert!(layers[0].1.iter().all(|c| c.is_valid_radiance()));
}
