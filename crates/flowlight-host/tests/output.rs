//! Tests for `flowlight_host::output`: EXR round trip, atomic writes, non-finite guard, PNG.

use std::fs;
use std::io::{BufReader, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use flowlight_core::spectrum::Rgb;
use flowlight_host::output::{
    read_exr_metadata, read_exr_rgb, write_atomically, write_exr, write_png_preview, ExrMetadata,
    ImageLayer, OutputError,
};

/// A fresh, unique directory under the system temp dir; removed on drop.
struct ScratchDir(PathBuf);

impl ScratchDir {
    fn new(tag: &str) -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        let dir = std::env::temp_dir().join(format!(
            "flowlight-output-test-{tag}-{}-{nanos}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).unwrap();
        ScratchDir(dir)
    }
    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        restore_writable(&self.0);
        let _ = fs::remove_dir_all(&self.0);
    }
}

#[cfg(unix)]
fn restore_writable(dir: &Path) {
    use std::os::unix::fs::PermissionsExt;
    if let Ok(entries) = fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.file_type().map(|t| t.is_dir()).unwrap_or(false) {
                let _ = fs::set_permissions(e.path(), fs::Permissions::from_mode(0o755));
            }
        }
    }
}
#[cfg(not(unix))]
fn restore_writable(_dir: &Path) {}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

const W: usize = 7;
const H: usize = 5;

/// Pixels that differ per position and per channel, including values that would not survive
/// a half-float or lossy round trip.
fn test_pixels(seed: f32) -> Vec<Rgb> {
    (0..W * H)
        .map(|i| {
            let (x, y) = ((i % W) as f32, (i / W) as f32);
            Rgb::new(
                seed + x * 0.1 + y * 10.0 + 1.0e-7,
                -(seed * 3.0 + x) / 7.0,
                1.0e-40 * (i as f32 + 1.0) + y * 12345.678,
            )
        })
        .collect()
}

fn bits(pixels: &[Rgb]) -> Vec<[u32; 3]> {
    pixels
        .iter()
        .map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
        .collect()
}

fn sample_meta() -> ExrMetadata {
    ExrMetadata {
        entries: vec![
            ("integrator".into(), "mcpt".into()),
            ("spp".into(), "64".into()),
            ("seed".into(), "42".into()),
            ("biased".into(), "false".into()),
            ("software".into(), "Flowlight".into()),
        ],
    }
}

#[test]
fn exr_round_trip_is_bit_exact_with_layers_and_metadata() {
    let dir = ScratchDir::new("roundtrip");
    // Also exercises creation of missing parent directories.
    let path = dir.path().join("nested/deeper/out.exr");
    let main = test_pixels(1.0);
    let extra = test_pixels(2.5);
    let layers = [
        ImageLayer {
            name: String::new(),
            pixels: &main,
        },
        ImageLayer {
            name: "layer1".into(),
            pixels: &extra,
        },
    ];
    write_exr(&path, W, H, &layers, &sample_meta()).unwrap();

    let (w, h, read) = read_exr_rgb(&path).unwrap();
    assert_eq!((w, h), (W, H));
    let names: Vec<&str> = read.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["", "layer1"]);
    assert_eq!(bits(&read[0].1), bits(&main), "main layer differs");
    assert_eq!(bits(&read[1].1), bits(&extra), "layer1 differs");

    let meta = read_exr_metadata(&path).unwrap();
    let mut expected = sample_meta().entries;
    expected.sort();
    assert_eq!(meta.entries, expected);

    // Nothing but the image is left in its directory (no temp file).
    assert_eq!(dir_entries(path.parent().unwrap()), ["out.exr"]);
}

#[test]
fn exr_layer_channels_use_dotted_names() {
    let dir = ScratchDir::new("channels");
    let path = dir.path().join("out.exr");
    let main = test_pixels(0.0);
    let layers = [
        ImageLayer {
            name: "albedo".into(),
            pixels: &main,
        },
        ImageLayer {
            name: String::new(),
            pixels: &main,
        },
    ];
    write_exr(&path, W, H, &layers, &ExrMetadata::default()).unwrap();
    let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
    assert_eq!(meta.headers.len(), 1, "expected a single-part file");
    let channels: Vec<String> = meta.headers[0]
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    assert_eq!(
        channels,
        ["B", "G", "R", "albedo.B", "albedo.G", "albedo.R"]
    );
    assert!(matches!(
        meta.headers[0].compression,
        exr::prelude::Compression::ZIP16
            | exr::prelude::Compression::ZIP1
            | exr::prelude::Compression::PIZ
    ));
}

#[test]
fn uncreatable_directory_fails_naming_the_path() {
    let dir = ScratchDir::new("uncreatable");
    let blocker = dir.path().join("blocker");
    fs::write(&blocker, b"not a directory").unwrap();
    let path = blocker.join("sub/out.exr");
    let main = test_pixels(0.0);
    let err = write_exr(
        &path,
        W,
        H,
        &[ImageLayer {
            name: String::new(),
            pixels: &main,
        }],
        &ExrMetadata::default(),
    )
    .unwrap_err();
    assert!(matches!(err, OutputError::CreateDir { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains(&path.display().to_string()),
        "message lacks path: {msg}"
    );
    assert_eq!(fs::read(&blocker).unwrap(), b"not a directory");

    let err = write_png_preview(&path.with_extension("png"), W, H, &main, 0.0).unwrap_err();
    assert!(err.to_string().contains("out.png"), "{err}");
}

#[cfg(unix)]
#[test]
fn read_only_directory_fails_naming_the_path() {
    use std::os::unix::fs::PermissionsExt;
    let dir = ScratchDir::new("readonly");
    let ro = dir.path().join("ro");
    fs::create_dir(&ro).unwrap();
    fs::set_permissions(&ro, fs::Permissions::from_mode(0o555)).unwrap();
    // Privileged users (root in containers) ignore directory permissions: nothing to test.
    if fs::write(ro.join("probe"), b"x").is_ok() {
        eprintln!("skipping: directory permissions are not enforced for this user");
        return;
    }
    let path = ro.join("out.exr");
    let main = test_pixels(0.0);
    let err = write_exr(
        &path,
        W,
        H,
        &[ImageLayer {
            name: String::new(),
            pixels: &main,
        }],
        &ExrMetadata::default(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains(&path.display().to_string()),
        "message lacks path: {msg}"
    );
    assert!(dir_entries(&ro).is_empty());
}

#[test]
fn failing_write_keeps_existing_file_and_removes_temp() {
    let dir = ScratchDir::new("atomic");
    let path = dir.path().join("image.exr");
    fs::write(&path, b"previous render").unwrap();

    let mut seen_tmp = None;
    let err = write_atomically(&path, |tmp| {
        seen_tmp = Some(tmp.to_owned());
        assert_eq!(
            tmp.parent(),
            path.parent(),
            "temp file must be in the same directory"
        );
        let mut f = fs::File::create(tmp).unwrap();
        f.write_all(b"half-written garb").unwrap();
        Err(OutputError::Io {
            path: path.clone(),
            source: std::io::Error::other("simulated failure"),
        })
    })
    .unwrap_err();
    assert!(err.to_string().contains("simulated failure"));
    let tmp = seen_tmp.expect("closure was not called");
    assert!(!tmp.exists(), "temp file left behind: {}", tmp.display());
    assert_eq!(fs::read(&path).unwrap(), b"previous render");
    assert_eq!(dir_entries(dir.path()), ["image.exr"]);

    // A rejected image (non-finite pixel) must not touch the existing file either.
    let mut bad = test_pixels(0.0);
    bad[3].g = f32::NAN;
    write_exr(
        &path,
        W,
        H,
        &[ImageLayer {
            name: String::new(),
            pixels: &bad,
        }],
        &ExrMetadata::default(),
    )
    .unwrap_err();
    assert_eq!(fs::read(&path).unwrap(), b"previous render");
    assert_eq!(dir_entries(dir.path()), ["image.exr"]);
}

#[test]
fn successful_write_replaces_existing_file() {
    let dir = ScratchDir::new("replace");
    let path = dir.path().join("image.exr");
    fs::write(&path, b"previous render").unwrap();
    let main = test_pixels(3.0);
    write_exr(
        &path,
        W,
        H,
        &[ImageLayer {
            name: String::new(),
            pixels: &main,
        }],
        &ExrMetadata::default(),
    )
    .unwrap();
    let (_, _, layers) = read_exr_rgb(&path).unwrap();
    assert_eq!(bits(&layers[0].1), bits(&main));
    assert_eq!(dir_entries(dir.path()), ["image.exr"]);
}

#[test]
fn non_finite_pixel_is_rejected_with_layer_and_position() {
    let dir = ScratchDir::new("nonfinite");
    let path = dir.path().join("out.exr");
    let main = test_pixels(0.0);
    for bad_value in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut extra = test_pixels(1.0);
        extra[2 * W + 3].b = bad_value; // pixel (3, 2)
        let err = write_exr(
            &path,
            W,
            H,
            &[
                ImageLayer {
                    name: String::new(),
                    pixels: &main,
                },
                ImageLayer {
                    name: "layer1".into(),
                    pixels: &extra,
                },
            ],
            &ExrMetadata::default(),
        )
        .unwrap_err();
        match &err {
            OutputError::NonFinite { layer, x, y, .. } => {
                assert_eq!((layer.as_str(), *x, *y), ("layer1", 3, 2), "{err}");
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
        let msg = err.to_string();
        assert!(msg.contains("layer1") && msg.contains("(3, 2)"), "{msg}");
        assert!(!path.exists());
    }
    assert!(dir_entries(dir.path()).is_empty());
}

#[test]
fn pixel_count_mismatch_is_rejected() {
    let dir = ScratchDir::new("count");
    let path = dir.path().join("out.exr");
    let short = vec![Rgb::ZERO; W * H - 1];
    let err = write_exr(
        &path,
        W,
        H,
        &[ImageLayer {
            name: String::new(),
            pixels: &short,
        }],
        &ExrMetadata::default(),
    )
    .unwrap_err();
    assert!(
        matches!(err, OutputError::PixelCount { expected, actual, .. } if expected == W * H && actual == W * H - 1),
        "{err:?}"
    );
    let err = write_png_preview(&path.with_extension("png"), W, H, &short, 0.0).unwrap_err();
    assert!(matches!(err, OutputError::PixelCount { .. }), "{err:?}");
    assert!(dir_entries(dir.path()).is_empty());
}

fn decode_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(BufReader::new(fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn png_preview_applies_srgb_and_clamps() {
    let dir = ScratchDir::new("png");
    let path = dir.path().join("sub/preview.png");
    let pixels = [
        Rgb::new(0.5, 0.0, 1.0),
        Rgb::new(2.0, 1.0e6, -3.0),
        Rgb::new(0.002, 0.18, 0.25),
    ];
    write_png_preview(&path, 3, 1, &pixels, 0.0).unwrap();
    let (w, h, data) = decode_png(&path);
    assert_eq!((w, h), (3, 1));
    // 0.002 is on the linear segment: 12.92 * 0.002 * 255 = 6.59 -> 7.
    // 0.18 -> 0.4614 * 255 = 117.7 -> 118; 0.25 -> 0.5371 * 255 = 137.0 -> 137.
    assert_eq!(data, [188, 0, 255, 255, 255, 0, 7, 118, 137]);
    assert_eq!(dir_entries(path.parent().unwrap()), ["preview.png"]);

    // Exposure +1 doubles the linear value: 0.25 -> 0.5 -> 188.
    write_png_preview(&path, 1, 1, &[Rgb::splat(0.25)], 1.0).unwrap();
    assert_eq!(decode_png(&path).2, [188, 188, 188]);

    let err = write_png_preview(&path, 1, 1, &[Rgb::new(0.1, f32::NAN, 0.1)], 0.0).unwrap_err();
    assert!(
        matches!(err, OutputError::NonFinite { x: 0, y: 0, .. }),
        "{err:?}"
    );
    assert_eq!(
        decode_png(&path).2,
        [188, 188, 188],
        "failed write changed the file"
    );
}

/// A header `magic version attr… 0` followed by `tail`, attributes in the given order.
fn exr_header(attrs: &[(&str, &str, &[u8])], tail: &[u8]) -> Vec<u8> {
    let mut f = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    for (name, kind, value) in attrs {
        f.extend_from_slice(name.as_bytes());
        f.push(0);
        f.extend_from_slice(kind.as_bytes());
        f.push(0);
        f.extend_from_slice(&(value.len() as i32).to_le_bytes());
        f.extend_from_slice(value);
    }
    f.push(0);
    f.extend_from_slice(tail);
    f
}

#[test]
fn header_attributes_are_sorted_in_place() {
    use flowlight_host::output::sort_header_attributes;
    let tail = [9u8, 8, 7, 6];
    let a = ("channels", "chlist", &b"RGB"[..]);
    let b = ("flowlight.seed", "string", &b"7"[..]);
    let c = ("compression", "compression", &[3u8][..]);
    let d = ("flowlight.integrator", "string", &b"mcpt"[..]);
    let mut one = exr_header(&[b, a, d, c], &tail);
    let mut two = exr_header(&[d, c, a, b], &tail);
    sort_header_attributes(&mut one).unwrap();
    sort_header_attributes(&mut two).unwrap();
    assert_eq!(one, two);
    assert_eq!(one, exr_header(&[a, c, d, b], &tail));
    // Damaged headers are errors, not panics.
    for cut in 0..one.len() - tail.len() - 1 {
        assert!(
            sort_header_attributes(&mut one.clone()[..cut].to_vec()).is_err(),
            "{cut}"
        );
    }
}

#[test]
fn written_exr_bytes_do_not_depend_on_metadata_order() {
    let dir = ScratchDir::new("det");
    let pixels = test_pixels(0.5);
    let layers = [ImageLayer {
        name: String::new(),
        pixels: &pixels,
    }];
    let mut meta = sample_meta();
    let mut files = Vec::new();
    for i in 0..4 {
        meta.entries.rotate_left(1);
        let p = dir.path().join(format!("{i}.exr"));
        write_exr(&p, W, H, &layers, &meta).unwrap();
        files.push(fs::read(&p).unwrap());
    }
    assert!(files.windows(2).all(|w| w[0] == w[1]));
    let mut expected = meta.entries.clone();
    expected.sort();
    assert_eq!(
        read_exr_metadata(&dir.path().join("0.exr"))
            .unwrap()
            .entries,
        expected
    );
}

#[test]
fn check_writable_names_the_folder_and_leaves_nothing() {
    use flowlight_host::output::check_writable;
    let dir = ScratchDir::new("writable");
    fs::write(dir.path().join("file"), "x").unwrap();
    assert!(check_writable(&dir.path().join("a.exr")).is_ok());
    assert!(check_writable(&dir.path().join("new/deeper/a.exr")).is_ok());
    assert!(!dir.path().join("new").exists());
    let e = check_writable(&dir.path().join("file/a.exr"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a directory") && e.contains("file"), "{e}");
    let e = check_writable(dir.path()).unwrap_err().to_string();
    assert!(e.contains("is a directory"), "{e}");
    assert_eq!(dir_entries(dir.path()), vec!["file".to_string()]);
}

/// A writer in another PID namespace (a container on a shared volume) has a PID that is not
/// alive here; its temporary file is kept while it holds the file's lock, and removed once
/// the lock is gone (the writer died).
#[test]
fn d6_a_locked_temp_of_a_writer_elsewhere_is_kept() {
    let dir = ScratchDir::new("d6-lock");
    let out = dir.path().join("a.exr");
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let elsewhere = child.id();
    child.wait().unwrap();
    let tmp = dir.path().join(format!(".a.exr.tmp-{elsewhere}-0"));
    fs::write(&tmp, "being written").unwrap();
    let writer = fs::OpenOptions::new().read(true).open(&tmp).unwrap();
    writer.lock().unwrap();
    let write_x = |p: &Path| {
        fs::write(p, b"x").map_err(|source| OutputError::Io {
            path: p.to_owned(),
            source,
        })
    };
    write_atomically(&out, write_x).unwrap();
    assert!(tmp.exists(), "a live writer's temp file was removed");
    drop(writer);
    write_atomically(&out, write_x).unwrap();
    assert!(!tmp.exists(), "a dead writer's temp file was kept");
    assert_eq!(fs::read(&out).unwrap(), b"x");
}

/// A 1 KB EXR whose header claims 100000×100000 pixels is refused before the decoder
/// allocates them.
#[test]
fn d4_an_exr_header_claiming_more_than_the_file_holds_is_refused() {
    let dir = ScratchDir::new("d4-huge");
    let path = dir.path().join("small.exr");
    let px = vec![Rgb::splat(1.0); 4];
    write_exr(
        &path,
        2,
        2,
        &[ImageLayer {
            name: String::new(),
            pixels: &px,
        }],
        &ExrMetadata::default(),
    )
    .unwrap();
    // dataWindow and displayWindow: box2i of (xmin, ymin, xmax, ymax), i32 each.
    let mut bytes = fs::read(&path).unwrap();
    for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = bytes.windows(name.len()).position(|w| w == name).unwrap() + name.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&99_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&99_999i32.to_le_bytes());
    }
    let huge = dir.path().join("huge.exr");
    fs::write(&huge, &bytes).unwrap();
    assert!(bytes.len() < 2048);
    let e = read_exr_rgb(&huge).unwrap_err().to_string();
    assert!(e.contains("huge.exr") && e.contains("100000x100000"), "{e}");
    let e = flowlight_host::output::read_exr_u32(&huge)
        .unwrap_err()
        .to_string();
    assert!(e.contains("100000x100000"), "{e}");
}
