//! The `flowlight` command line, run as a user would.

use crate::common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn flowlight() -> Command {
    Command::new(env!("CARGO_BIN_EXE_flowlight"))
}

#[test]
fn render_writes_an_exr_and_a_summary() {
    let dir = common::scratch("cli-render");
    let out = dir.join("nested/furnace.exr");
    let stdout = common::run_ok(
        flowlight()
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
            .arg(&out),
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
    // Ranges and roles are listed with each parameter.
    assert!(s.contains("in 1..=32 [role PathDepth]"), "{s}");
}

/// `flowlight plugins --markdown` prints each plugin's generated table between the markers
/// the docs hold it in; plugins without parameters and refused ones print none.
#[test]
fn plugins_markdown_prints_the_generated_tables() {
    let o = flowlight()
        .args(["plugins", "--markdown"])
        .output()
        .unwrap();
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("<!-- params:mcpt -->\n| parameter | type | default | values | meaning |"),
        "{s}"
    );
    assert!(
        s.contains("| `path_depth` | integer | `8` | `1..=32` |"),
        "{s}"
    );
    assert!(
        s.contains("<!-- params:drill -->") && s.contains("<!-- /params -->"),
        "{s}"
    );
    assert!(!s.contains("params:hard-reconnection"), "{s}");
    assert!(
        !s.contains("test_bad_abi") && !s.contains("search path"),
        "{s}"
    );
}

/// Ctrl-C once: the render finishes the units in flight and writes what has accumulated.
/// The signal goes out when the CLI's debug log reports the first finished work unit, so
/// the handler is installed and the image cannot be empty, however slow the machine.
#[test]
fn interrupt_saves_what_has_accumulated() {
    let dir = common::scratch("cli-interrupt");
    let out = dir.join("partial.exr");
    let mut child = flowlight()
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
        .env("FLOWLIGHT_LOG", "warn,flowlight_cli=debug")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (lines, stderr) = forward_lines(child.stderr.take().unwrap());
    let first_unit = wait_for_line(&lines, "first work unit finished", Duration::from_secs(60));
    if first_unit.is_err() {
        let _ = child.kill();
    }
    first_unit.unwrap_or_else(|seen| panic!("no work unit finished within 60 s:\n{seen}"));
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
    let stderr = stderr.join().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("interrupted: finishing"), "{stderr}");
    assert!(stdout.contains("interrupted"), "{stdout}");
    let (_, _, layers) = flowlight_host::output::read_exr_rgb(&out).unwrap();
    let lit = layers[0].1.iter().filter(|c| c.luminance() > 0.0).count();
    assert!(lit > 0, "the partial image is empty");
    assert!(layers[0].1.iter().all(|c| c.is_valid_radiance()));
}

/// Forwards `stream`'s lines, as they come, to the receiver; the thread returns all of them.
fn forward_lines(
    stream: impl std::io::Read + Send + 'static,
) -> (
    std::sync::mpsc::Receiver<String>,
    std::thread::JoinHandle<String>,
) {
    use std::io::BufRead;
    let (send, receive) = std::sync::mpsc::channel();
    let all = std::thread::spawn(move || {
        let mut all = String::new();
        for line in std::io::BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            all.push_str(&line);
            all.push('\n');
            // The receiver stops listening once it has what it waited for.
            let _ = send.send(line);
        }
        all
    });
    (receive, all)
}

/// Waits until a line containing `needle` arrives, at most `limit`; on failure, the lines
/// seen so far.
fn wait_for_line(
    lines: &std::sync::mpsc::Receiver<String>,
    needle: &str,
    limit: Duration,
) -> Result<(), String> {
    let deadline = Instant::now() + limit;
    let mut seen = String::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if line.contains(needle) => return Ok(()),
            Ok(line) => {
                seen.push_str(&line);
                seen.push('\n');
            }
            // Timed out, or the process closed its stderr (it exited).
            Err(_) => return Err(seen),
        }
    }
}

/// The furnace scene copied into `dir` with a config `f.toml` that writes `f.exr` and a PNG
/// preview `preview.png`.
fn furnace_copy(dir: &std::path::Path) -> std::path::PathBuf {
    let gltf = std::fs::read_to_string(common::scene_config("furnace/furnace.gltf")).unwrap();
    std::fs::write(dir.join("f.gltf"), gltf).unwrap();
    let cfg = dir.join("f.toml");
    std::fs::write(
        &cfg,
        "scene = \"f.gltf\"\n[render]\nwidth = 16\nheight = 12\n[integrator]\nplugin = \"mcpt\"\npath_depth = 2\n[output]\nexr = \"f.exr\"\npng = \"preview.png\"\n",
    )
    .unwrap();
    cfg
}

#[test]
fn out_moves_the_png_preview_beside_the_exr() {
    let dir = common::scratch("cli-out-png");
    let cfg = furnace_copy(&dir);
    let out = dir.join("elsewhere/x.exr");
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "--spp", "1", "-q", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let png = dir.join("elsewhere/x.png");
    assert!(out.exists() && png.exists(), "{stdout}");
    assert!(stdout.contains(&png.display().to_string()), "{stdout}");
    // The config's own outputs are left alone.
    assert!(!dir.join("preview.png").exists() && !dir.join("f.exr").exists());
    // A PNG of the render's size: the IHDR chunk's big-endian width and height.
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    assert_eq!((be(16), be(20)), (16, 12));

    // Without --out, the config's paths.
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "--spp", "1", "-q"])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(dir.join("preview.png").exists() && dir.join("f.exr").exists());

    // --out naming a PNG would put both images in one file: refused before rendering.
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "--spp", "1", "-q", "--out"])
        .arg(dir.join("y.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("y.png") && err.contains("EXR"), "{err}");
}

#[test]
fn a_scene_without_a_camera_renders_through_the_automatic_camera() {
    // An emitting quad [−1, 1]² in z = 0 facing +Z (radiance 1), no camera, no [camera].
    let dir = common::scratch("cli-auto-camera");
    common::emitting_square(&dir);
    let cfg = dir.join("q.toml");
    std::fs::write(
        &cfg,
        "scene = \"q.gltf\"\n[render]\nwidth = 24\nheight = 16\n[integrator]\nplugin = \"mcpt\"\n",
    )
    .unwrap();
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "--spp", "4", "-q"])
        .env("FLOWLIGHT_LOG", "info")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(
        err.matches("automatic perspective camera").count(),
        1,
        "one info line: {err}"
    );
    // The camera looks at the quad's centre from the front: the centre pixels see radiance
    // 1; the corners lie outside the bounding sphere's image and see nothing.
    let (w, h, layers) = flowlight_host::output::read_exr_rgb(&dir.join("q.exr")).unwrap();
    let px = |x: usize, y: usize| layers[0].1[y * w + x];
    for (x, y) in [(w / 2, h / 2), (w / 2 - 1, h / 2 - 1)] {
        assert!((px(x, y).luminance() - 1.0).abs() < 1e-3, "{:?}", px(x, y));
    }
    for (x, y) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        assert_eq!(px(x, y).luminance(), 0.0);
    }
}

/// The summary names Embree's mode, which changes its speed by about 15%: a timing read
/// from it says which mode it measured (docs/embree.md).
#[test]
fn summary_names_embrees_mode() {
    let dir = common::scratch("cli-embree-mode");
    let gltf = common::scene_config("cornell-box/cornell-box.gltf");
    for (robust, expected) in [
        ("true", "intersector     embree, robust mode ("),
        (
            "false",
            "intersector     embree, fast mode (robust = false) (",
        ),
    ] {
        let cfg = dir.join(format!("robust-{robust}.toml"));
        std::fs::write(
            &cfg,
            format!(
                "scene = {:?}\n[render]\nwidth = 8\nheight = 8\nspp = 1\nintersector = \"embree\"\n\
                 robust = {robust}\n[integrator]\nplugin = \"mcpt\"\n",
                gltf.to_str().unwrap()
            ),
        )
        .unwrap();
        let stdout = common::run_ok(
            flowlight()
                .args(["render", cfg.to_str().unwrap(), "-q", "--out"])
                .arg(dir.join(format!("robust-{robust}.exr"))),
        );
        assert!(stdout.contains(expected), "no '{expected}' in:\n{stdout}");
    }
}
