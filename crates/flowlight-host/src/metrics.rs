//! Image error metrics: what `flowlight compare` and `flowlight bench` report.
//!
//! All metrics compare a test image `a` with a reference `b` of the same size, per colour
//! channel, and average over pixels *and* channels (R, G, B weigh equally):
//!
//! - **MSE / RMSE**: mean of (a − b)², and its square root (absolute, in radiance units).
//! - **relMSE**: mean of (a − b)² / (b² + ε) with ε = [`REL_EPS`] = 10⁻², the definition of
//!   Rousselle, Knaus & Zwicker (2011) used throughout the pbrt/Mitsuba-era denoising and
//!   MCMC papers. ε keeps black or near-black reference pixels from dominating the mean (a
//!   relative error is meaningless where b ≈ 0). It fits images whose interesting pixels have
//!   radiance of order 0.1–10, like every scene in `scenes/`; for a much darker or brighter
//!   scene, scale the images (or compare with another ε through [`compare_with`]).
//! - **mean luminance ratio**: mean luminance of `a` over that of `b` (1 = no energy lost or
//!   gained; the first thing a bias shows in).
//! - **reference floor** (when the reference comes with a per-pixel variance of its own mean,
//!   as `flowlight reference` writes): mean of Var(b) / (b² + ε). A noisy reference adds its own
//!   variance to E[(a − b)²], so a relMSE near this floor cannot be told apart from zero.
//!
//! Pixels where either image is not finite are left out of every mean and counted in
//! [`Errors::non_finite`].

use flowlight_core::Rgb;

/// The ε of relMSE: (a − b)² / (b² + ε).
pub const REL_EPS: f64 = 1e-2;

/// The errors of an image against a reference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Errors {
    pub mse: f64,
    pub rmse: f64,
    pub relmse: f64,
    /// mean luminance(a) / mean luminance(b); NaN when b is black.
    pub luminance_ratio: f64,
    pub mean_luminance_a: f64,
    pub mean_luminance_b: f64,
    /// Mean of Var(b)/(b² + ε) over the compared pixels, when the reference variance is known.
    pub reference_floor: Option<f64>,
    /// Pixels compared.
    pub pixels: usize,
    /// Pixels skipped because a value (in `a`, `b` or the variance) was NaN or infinite.
    pub non_finite: usize,
}

/// Compares `a` with reference `b` (same length, row-major) using ε = [`REL_EPS`].
pub fn compare(a: &[Rgb], b: &[Rgb], variance: Option<&[Rgb]>) -> Result<Errors, String> {
    compare_with(a, b, variance, REL_EPS)
}

fn channels(c: Rgb) -> [f64; 3] {
    [c.r as f64, c.g as f64, c.b as f64]
}

fn finite(c: Rgb) -> bool {
    c.r.is_finite() && c.g.is_finite() && c.b.is_finite()
}

/// [`compare`] with another ε.
pub fn compare_with(
    a: &[Rgb],
    b: &[Rgb],
    variance: Option<&[Rgb]>,
    eps: f64,
) -> Result<Errors, String> {
    if a.len() != b.len() {
        return Err(format!(
            "the images differ in size ({} and {} pixels)",
            a.len(),
            b.len()
        ));
    }
    if let Some(v) = variance {
        if v.len() != b.len() {
            return Err(format!(
                "the reference variance has {} pixels, the reference {}",
                v.len(),
                b.len()
            ));
        }
    }
    if !(eps > 0.0 && eps.is_finite()) {
        return Err(format!("relMSE epsilon must be positive, got {eps}"));
    }
    let (mut se, mut rel, mut floor, mut la, mut lb) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut n, mut bad) = (0usize, 0usize);
    for i in 0..a.len() {
        let var = variance.map(|v| v[i]);
        if !finite(a[i]) || !finite(b[i]) || var.is_some_and(|v| !finite(v)) {
            bad += 1;
            continue;
        }
        n += 1;
        let (ca, cb) = (channels(a[i]), channels(b[i]));
        for k in 0..3 {
            let d = ca[k] - cb[k];
            se += d * d;
            rel += d * d / (cb[k] * cb[k] + eps);
        }
        if let Some(v) = var {
            let cv = channels(v);
            for k in 0..3 {
                floor += cv[k] / (cb[k] * cb[k] + eps);
            }
        }
        la += a[i].luminance() as f64;
        lb += b[i].luminance() as f64;
    }
    if n == 0 {
        return Err(format!(
            "no pixel to compare ({} pixels, {bad} of them not finite)",
            a.len()
        ));
    }
    let samples = 3.0 * n as f64;
    let mse = se / samples;
    let (la, lb) = (la / n as f64, lb / n as f64);
    Ok(Errors {
        mse,
        rmse: mse.sqrt(),
        relmse: rel / samples,
        luminance_ratio: if lb > 0.0 { la / lb } else { f64::NAN },
        mean_luminance_a: la,
        mean_luminance_b: lb,
        reference_floor: variance.map(|_| floor / samples),
        pixels: n,
        non_finite: bad,
    })
}

/// Per-pixel relative squared error, mean over the channels: the quantity whose mean is
/// relMSE. Non-finite pixels give +∞.
pub fn relative_error_map(a: &[Rgb], b: &[Rgb], eps: f64) -> Vec<f64> {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            if !finite(x) || !finite(y) {
                return f64::INFINITY;
            }
            let (cx, cy) = (channels(x), channels(y));
            (0..3)
                .map(|k| (cx[k] - cy[k]).powi(2) / (cy[k] * cy[k] + eps))
                .sum::<f64>()
                / 3.0
        })
        .collect()
}

/// The range of the false-colour error image: relative squared errors from 10^LO to 10^HI
/// map onto the colour ramp (log scale); below is the darkest colour, above the brightest,
/// non-finite pixels are magenta.
pub const FALSE_COLOUR_LOG10_RANGE: (f64, f64) = (-4.0, 1.0);

/// Control points of the colour ramp (roughly matplotlib's "inferno": black → purple → red
/// → yellow → white).
const RAMP: [[f64; 3]; 6] = [
    [0.0, 0.0, 0.02],
    [0.26, 0.04, 0.41],
    [0.58, 0.15, 0.40],
    [0.87, 0.32, 0.23],
    [0.99, 0.65, 0.04],
    [0.99, 1.0, 0.64],
];

/// Maps `t` in [0, 1] to an 8-bit RGB colour of the ramp.
pub fn ramp_colour(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (RAMP.len() - 1) as f64;
    let i = (x.floor() as usize).min(RAMP.len() - 2);
    let f = x - i as f64;
    let mut out = [0u8; 3];
    for k in 0..3 {
        let v = RAMP[i][k] * (1.0 - f) + RAMP[i + 1][k] * f;
        out[k] = (v * 255.0 + 0.5).clamp(0.0, 255.0) as u8;
    }
    out
}

/// The false-colour error image as 8-bit RGB (row-major), from a [`relative_error_map`].
pub fn false_colour(errors: &[f64]) -> Vec<[u8; 3]> {
    let (lo, hi) = FALSE_COLOUR_LOG10_RANGE;
    errors
        .iter()
        .map(|&e| {
            if !e.is_finite() {
                [255, 0, 255]
            } else if e <= 0.0 {
                ramp_colour(0.0)
            } else {
                ramp_colour((e.log10() - lo) / (hi - lo))
            }
        })
        .collect()
}

/// Writes `pixels` (8-bit RGB, row-major; e.g. a [`false_colour`] image) as an
/// sRGB-tagged PNG, atomically, through the host's one PNG encoder
/// ([`crate::output::PngPreview`]).
pub fn write_rgb8_png(
    path: &std::path::Path,
    width: usize,
    height: usize,
    pixels: &[[u8; 3]],
) -> Result<(), String> {
    crate::output::PngPreview::from_rgb8(path, width, height, pixels)
        .and_then(|png| png.write(path))
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(v: &[f32]) -> Vec<Rgb> {
        v.iter().map(|&x| Rgb::splat(x)).collect()
    }

    #[test]
    fn identical_images_have_zero_error() {
        let a = img(&[0.0, 0.5, 2.0, 10.0]);
        let e = compare(&a, &a, None).unwrap();
        assert_eq!(e.mse, 0.0);
        assert_eq!(e.relmse, 0.0);
        assert_eq!(e.luminance_ratio, 1.0);
        assert_eq!(e.pixels, 4);
        assert_eq!(e.reference_floor, None);
    }

    #[test]
    fn values_match_the_definitions() {
        let a = img(&[1.0, 3.0]);
        let b = img(&[2.0, 1.0]);
        let e = compare(&a, &b, None).unwrap();
        assert!((e.mse - (1.0 + 4.0) / 2.0).abs() < 1e-12);
        assert!((e.rmse - 2.5f64.sqrt()).abs() < 1e-12);
        let rel = (1.0 / (4.0 + REL_EPS) + 4.0 / (1.0 + REL_EPS)) / 2.0;
        assert!((e.relmse - rel).abs() < 1e-12);
        assert!((e.luminance_ratio - 4.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn channels_are_averaged() {
        let a = vec![Rgb::new(1.0, 0.0, 0.0)];
        let b = vec![Rgb::ZERO];
        let e = compare(&a, &b, None).unwrap();
        assert!((e.mse - 1.0 / 3.0).abs() < 1e-12);
        assert!((e.relmse - 1.0 / REL_EPS / 3.0).abs() < 1e-9);
    }

    #[test]
    fn relmse_is_scale_invariant_away_from_epsilon() {
        let a = img(&[100.0, 220.0]);
        let b = img(&[110.0, 200.0]);
        let a2 = img(&[1000.0, 2200.0]);
        let b2 = img(&[1100.0, 2000.0]);
        let e1 = compare(&a, &b, None).unwrap().relmse;
        let e2 = compare(&a2, &b2, None).unwrap().relmse;
        assert!((e1 / e2 - 1.0).abs() < 1e-4);
    }

    #[test]
    fn non_finite_pixels_are_skipped_and_counted() {
        let a = img(&[1.0, f32::NAN, 1.0]);
        let b = img(&[1.0, 1.0, f32::INFINITY]);
        let e = compare(&a, &b, None).unwrap();
        assert_eq!(e.pixels, 1);
        assert_eq!(e.non_finite, 2);
        assert_eq!(e.mse, 0.0);
        assert!(compare(&img(&[f32::NAN]), &img(&[1.0]), None).is_err());
    }

    #[test]
    fn size_mismatch_is_an_error() {
        assert!(compare(&img(&[1.0]), &img(&[1.0, 2.0]), None).is_err());
        assert!(compare(&img(&[1.0]), &img(&[1.0]), Some(&img(&[1.0, 1.0]))).is_err());
        assert!(compare_with(&img(&[1.0]), &img(&[1.0]), None, 0.0).is_err());
    }

    #[test]
    fn reference_floor_uses_the_variance() {
        let b = img(&[1.0, 0.0]);
        let v = img(&[0.02, 0.0]);
        let e = compare(&b, &b, Some(&v)).unwrap();
        let floor = (0.02 / (1.0 + REL_EPS)) / 2.0;
        assert!((e.reference_floor.unwrap() - floor).abs() < 1e-9);
    }

    #[test]
    fn black_reference_gives_nan_ratio() {
        let e = compare(&img(&[1.0]), &img(&[0.0]), None).unwrap();
        assert!(e.luminance_ratio.is_nan());
    }

    #[test]
    fn false_colour_is_monotone_in_brightness_and_flags_non_finite() {
        let errs = [0.0, 1e-5, 1e-3, 1e-1, 10.0, 1e3, f64::INFINITY, f64::NAN];
        let c = false_colour(&errs);
        let bright = |p: [u8; 3]| p.iter().map(|&x| x as u32).sum::<u32>();
        assert_eq!(c[0], c[1], "below the range: darkest colour");
        assert!(bright(c[1]) < bright(c[2]));
        assert!(bright(c[2]) < bright(c[3]));
        assert!(bright(c[3]) < bright(c[4]));
        assert_eq!(c[4], c[5], "above the range: brightest colour");
        assert_eq!(c[6], [255, 0, 255]);
        assert_eq!(c[7], [255, 0, 255]);
    }

    #[test]
    fn error_map_matches_relmse() {
        let a = img(&[1.0, 3.0, 0.5]);
        let b = img(&[2.0, 1.0, 0.5]);
        let m = relative_error_map(&a, &b, REL_EPS);
        let mean = m.iter().sum::<f64>() / 3.0;
        let e = compare(&a, &b, None).unwrap();
        assert!((mean - e.relmse).abs() < 1e-12);
    }

    #[test]
    fn png_is_written() {
        let dir = std::env::temp_dir().join(format!("flowlight-metrics-{}", std::process::id()));
        let p = dir.join("err.png");
        write_rgb8_png(&p, 2, 1, &[[0, 0, 0], [255, 255, 255]]).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(write_rgb8_png(&p, 3, 1, &[[0, 0, 0]]).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
