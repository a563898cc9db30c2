//! The live preview of `flowlight render`: `--tev` against a loopback server that decodes
//! tev's IPC packets as tev does (`flowlight_host::output::tev` for the protocol), a tev
//! that is not there, and `--preview-every` rewriting the PNG preview while rendering.

use crate::common;

use common::{repo, scratch};
use flowlight_core::Rgb;
use flowlight_host::output::live::LivePreview;
use flowlight_host::renderer::{Overrides, Renderer};
use std::io::Read;
use std::net::TcpListener;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::Mutex;
use std::time::Duration;

fn flowlight() -> Command {
    Command::new(env!("CARGO_BIN_EXE_flowlight"))
}

/// A 48×40 Cornell box config in `dir` (the scene by absolute path), 16-pixel tiles.
fn config(dir: &Path, spp: u32) -> std::path::PathBuf {
    let gltf = repo().join("scenes/cornell-box/cornell-box.gltf");
    let cfg = dir.join("live.toml");
    std::fs::write(
        &cfg,
        format!(
            "scene = \"{}\"\n[render]\nwidth = 48\nheight = 40\nspp = {spp}\nthreads = 2\ntile_size = 16\n[integrator]\nplugin = \"mcpt\"\n[output]\nexr = \"live.exr\"\npng = \"live.png\"\n",
            gltf.display()
        ),
    )
    .unwrap();
    cfg
}

/// A decoded packet, read the way tev's `IpcPacket::interpretAs…` reads them.
#[derive(Debug)]
enum Packet {
    Create {
        name: String,
        width: i32,
        height: i32,
        channels: Vec<String>,
    },
    Update {
        name: String,
        channels: Vec<String>,
        rect: [i32; 4],
        data: Vec<Vec<f32>>,
    },
}

struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        assert!(self.0.len() >= n, "packet too short");
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn string(&mut self) -> String {
        let end = self
            .0
            .iter()
            .position(|&b| b == 0)
            .expect("a NUL-terminated string");
        let s = String::from_utf8(self.0[..end].to_vec()).unwrap();
        self.0 = &self.0[end + 1..];
        s
    }
}

/// Splits a byte stream into packets (u32 total length first) and decodes them.
fn decode(mut stream: &[u8]) -> Vec<Packet> {
    let mut out = Vec::new();
    while !stream.is_empty() {
        let len = u32::from_le_bytes(stream[..4].try_into().unwrap()) as usize;
        assert!(len >= 5 && len <= stream.len(), "bad packet length {len}");
        let mut r = Reader(&stream[4..len]);
        stream = &stream[len..];
        let kind = r.take(1)[0];
        let _grab_focus = r.take(1)[0];
        let name = r.string();
        match kind {
            4 => {
                let (width, height, n) = (r.i32(), r.i32(), r.i32());
                let channels = (0..n).map(|_| r.string()).collect();
                out.push(Packet::Create {
                    name,
                    width,
                    height,
                    channels,
                });
            }
            5 => {
                let n = r.i32();
                let channels: Vec<String> = (0..n).map(|_| r.string()).collect();
                let rect = [r.i32(), r.i32(), r.i32(), r.i32()];
                let pixels = (rect[2] * rect[3]) as usize;
                let data = (0..n)
                    .map(|_| {
                        r.take(4 * pixels)
                            .chunks(4)
                            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                            .collect()
                    })
                    .collect();
                assert!(r.0.is_empty(), "trailing bytes in an update");
                out.push(Packet::Update {
                    name,
                    channels,
                    rect,
                    data,
                });
            }
            k => panic!("unexpected packet type {k}"),
        }
    }
    out
}

#[test]
fn tev_receives_the_image_forming_and_the_final_film() {
    let dir = scratch("live-tev");
    let cfg = config(&dir, 64);
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let server = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut bytes = Vec::new();
        s.read_to_end(&mut bytes).unwrap();
        bytes
    });
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "-q"])
        .arg(format!("--tev={address}"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let packets = decode(&server.join().unwrap());
    let Some(Packet::Create {
        name,
        width: 48,
        height: 40,
        channels,
    }) = packets.first()
    else {
        panic!("first packet: {:?}", packets.first());
    };
    assert_eq!(
        (name.as_str(), channels.as_slice()),
        ("live.exr", &["R", "G", "B"].map(String::from)[..])
    );
    // Replay the updates; each sweep covers the image once.
    let (w, h) = (48usize, 40usize);
    let mut image = vec![[0f32; 3]; w * h];
    let mut covered = 0usize;
    let mut sweeps = 0;
    for p in &packets[1..] {
        let Packet::Update {
            name,
            channels,
            rect: [x, y, tw, th],
            data,
        } = p
        else {
            panic!("a second CreateImage");
        };
        assert_eq!(name, "live.exr");
        assert_eq!(channels, &["R", "G", "B"]);
        for j in 0..*th as usize {
            for i in 0..*tw as usize {
                let px = (*y as usize + j) * w + *x as usize + i;
                for c in 0..3 {
                    image[px][c] = data[c][j * *tw as usize + i];
                }
            }
        }
        covered += (*tw * *th) as usize;
        if covered == w * h {
            sweeps += 1;
            covered = 0;
        }
    }
    assert_eq!(covered, 0, "a partial last sweep");
    assert!(sweeps >= 2, "{sweeps} sweeps: none while rendering");
    // The last sweep is the film, exactly as the EXR holds it.
    let (_, _, layers) = flowlight_host::output::read_exr_rgb(&dir.join("live.exr")).unwrap();
    let film = &layers.iter().find(|(n, _)| n.is_empty()).unwrap().1;
    let got: Vec<Rgb> = image.iter().map(|c| Rgb::new(c[0], c[1], c[2])).collect();
    assert_eq!(&got, film);
}

#[test]
fn a_tev_that_is_not_there_is_a_warning_and_the_image_is_the_same() {
    let dir = scratch("live-no-tev");
    let cfg = config(&dir, 4);
    // A port nothing listens on: bound, then closed.
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "-q"])
        .arg(format!("--tev=127.0.0.1:{port}"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.contains("--tev")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("cannot connect"), "{err}");
    let with = std::fs::read(dir.join("live.exr")).unwrap();
    let o = flowlight()
        .args(["render", cfg.to_str().unwrap(), "-q"])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert_eq!(with, std::fs::read(dir.join("live.exr")).unwrap());
    // A bad interval is refused before rendering.
    let o = flowlight()
        .args([
            "render",
            cfg.to_str().unwrap(),
            "-q",
            "--preview-every",
            "0",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--preview-every"),
        "{err}"
    );
}

#[test]
fn the_png_preview_is_rewritten_while_rendering() {
    let dir = scratch("live-png");
    let cfg = config(&dir, 96);
    let ov = Overrides {
        threads: Some(2),
        ..Default::default()
    };
    let renderer = Renderer::prepare(&cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    let png = renderer.png_path.clone().unwrap();
    let preview = Mutex::new(LivePreview::new(
        48,
        40,
        None,
        "live.exr",
        Some((png.clone(), Duration::from_millis(1))),
    ));
    // Whether the preview file existed while units were still being rendered.
    let seen = AtomicBool::new(false);
    let progress = |p: &flowlight_host::render::Progress| {
        let mut preview = preview.lock().unwrap();
        preview.update(p);
        if preview.png_writes > 0 && p.pixel_samples < 96 * 48 * 40 && png.exists() {
            seen.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let out = renderer
        .render(&AtomicBool::new(false), &progress)
        .unwrap_or_else(|e| panic!("{e}"));
    let preview = preview.into_inner().unwrap();
    assert!(preview.png_writes >= 2, "{} previews", preview.png_writes);
    assert!(seen.into_inner(), "no preview file during the render");
    let decoded = image_size(&png);
    assert_eq!(decoded, (48, 40));
    assert!(out.error.is_none());
}

/// Width and height from a PNG's IHDR chunk.
fn image_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}
