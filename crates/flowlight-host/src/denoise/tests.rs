//! The denoiser's library search and, where OIDN is present, its effect on noise.

use super::*;
use flowlight_core::rng::Rng;

/// An `OIDN_DIR` without the library is one line naming the variable and the folder.
#[test]
fn a_wrong_oidn_dir_is_named_in_one_line() {
    let e = Denoiser::open_from(Some("/nonexistent/oidn".into()), None, 0)
        .err()
        .expect("no library there");
    assert!(!e.contains('\n'), "{e}");
    for part in ["OIDN_DIR=/nonexistent/oidn", SONAME, "--denoise"] {
        assert!(e.contains(part), "{e} lacks {part}");
    }
}

/// With no `OIDN_DIR`, the system library and the fetched wheel are tried, in that order;
/// the fetched one under `FLOWLIGHT_OIDN_FETCH_DIR/lib` when that is set.
#[test]
fn the_search_tries_the_system_then_the_fetched_wheel() {
    let c = candidates(None, Some("/x/fetch".into())).unwrap();
    assert_eq!(c[0], ("system".to_string(), PathBuf::from(SONAME)));
    assert_eq!(c[1].1, PathBuf::from("/x/fetch/lib").join(SONAME));
    let c = candidates(None, None).unwrap();
    assert_eq!(c[1].1, PathBuf::from(FETCHED_LIB));
}

/// The error when no candidate opens says how to provision OIDN and what was tried.
#[test]
fn a_missing_library_says_how_to_get_one() {
    let fetch = std::env::temp_dir().join("flowlight-no-oidn-here");
    // Only meaningful where no system library exists; where one does, it opens instead, and
    // so does the fetched one once another test of this process has loaded it (the loader
    // then finds its SONAME loaded): tests/integration/aovs.rs checks this in a process of
    // its own.
    match Denoiser::open_from(None, Some(fetch.clone().into()), 0) {
        Ok(d) => println!(
            "skipped: a system Open Image Denoise is installed ({})",
            d.source
        ),
        Err(e) => {
            assert!(!e.contains('\n'), "{e}");
            for part in ["OIDN_DIR", "fetch.py", &fetch.display().to_string()] {
                assert!(e.contains(part), "{e} lacks {part}");
            }
        }
    }
}

/// The device keeps to the render's thread count (OIDN would take every core). Skipped,
/// saying why, only where OIDN is absent.
#[test]
fn the_device_takes_the_renders_thread_count() {
    for threads in [1usize, 2] {
        let d = match Denoiser::open(threads) {
            Ok(d) => d,
            Err(e) => {
                println!("skipped: Open Image Denoise is not available: {e}");
                return;
            }
        };
        // SAFETY: a device parameter read by its documented name.
        let n = unsafe { (d.api.get_device_int)(d.device, c"numThreads".as_ptr()) };
        assert_eq!(n, threads as i32);
    }
}

/// A smooth HDR image with independent per-pixel noise comes out of the filter far closer
/// to the clean one (its mean squared error at least 4× smaller), with flat guides; and
/// the filter keeps the image's mean. Skipped, saying why, only where OIDN is absent.
#[test]
fn denoising_reduces_independent_noise() {
    let mut d = match Denoiser::open(0) {
        Ok(d) => d,
        Err(e) => {
            println!("skipped: Open Image Denoise is not available: {e}");
            return;
        }
    };
    let (w, h) = (64usize, 48usize);
    let mut rng = Rng::new(5, 1);
    let mut clean = Vec::new();
    let mut noisy = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let v = 0.3 + 0.5 * (x as f32 / w as f32) + 0.2 * (y as f32 / h as f32);
            for c in 0..3 {
                let v = v * [1.0, 0.8, 0.6][c];
                clean.push(v);
                // Monte Carlo-like noise: mean-preserving, 40% relative.
                noisy.push(v * (1.0 + 0.4 * (2.0 * rng.uniform() - 1.0) * 3f32.sqrt()));
            }
        }
    }
    let albedo = vec![0.8f32; w * h * 3];
    let normal: Vec<f32> = (0..w * h).flat_map(|_| [0.0, 0.0, 1.0]).collect();
    let out = d.denoise(w, h, &noisy, &albedo, &normal).unwrap();
    let mse = |a: &[f32]| {
        a.iter()
            .zip(&clean)
            .map(|(p, q)| ((p - q) as f64).powi(2))
            .sum::<f64>()
            / a.len() as f64
    };
    let (before, after) = (mse(&noisy), mse(&out));
    println!("{}: MSE {before:.3e} -> {after:.3e}", d.source);
    assert!(after * 4.0 < before, "MSE {before} -> {after}");
    let mean = |a: &[f32]| a.iter().map(|&v| v as f64).sum::<f64>() / a.len() as f64;
    assert!((mean(&out) / mean(&clean) - 1.0).abs() < 0.03);
    let e = d.denoise(w, h, &noisy[3..], &albedo, &normal).unwrap_err();
    assert!(e.contains("64x48"), "{e}");
}
