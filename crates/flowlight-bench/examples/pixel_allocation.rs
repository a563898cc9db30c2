//! What giving each pixel a share of the samples by its own error could take off an image's
//! relMSE at the same total of samples (docs/performance.md, "What sampling by pixel error
//! could reach"). Nothing in the renderer does this yet; this measures whether it would pay.
//!
//! ```text
//! pixel_allocation REF.exr --pilot P1.exr P2.exr … --eval E1.exr E2.exr … [--tile 32]
//! ```
//!
//! `REF` is the reference the relMSE is taken against; the pilot renders (one sample per
//! pixel each, independent seeds) give each pixel's estimated relative variance, and the
//! evaluation renders (independent of the pilot: other seeds) give it again, unbiased, to
//! score the allocation with. For pixel i with relative variance v_i per sample (summed over
//! the three channels, each over its reference value squared plus relMSE's ε, `REL_EPS`),
//! an image with n_i samples at pixel i has relMSE ∝ Σ v_i / n_i. With the same total of
//! samples, uniform sampling gives Σ v_i, and the least is (Σ √v_i)² / P at n_i ∝ √v_i
//! (Neyman's allocation). The allocation tried here is what a renderer could do from a pilot:
//!
//! * the pilot's per-pixel relative variance, averaged over a 5 × 5 window (one pixel's few
//!   pilot samples are too noisy alone), its square root floored at 5% of its mean (a pixel
//!   the pilot saw as noiseless still gets samples);
//! * the rate n_i / n̄ rounded to a power of two in 1/8 … 8 (which keeps a pixel's samples
//!   one stratified Sobol' sequence, unbiased with weight n̄ / n_i);
//! * normalised over the whole image (`global`), or within each `--tile` × `--tile` tile, so
//!   that a tile's work stays what it was (`per tile`: no pass over the whole image first).
//!
//! Printed per allocation: the gain, uniform relMSE over the allocation's relMSE at the same
//! total (the mean rate after rounding is divided out), with the evaluation renders' variance
//! as the scorer. The pilot's own samples are not counted: a renderer that spends them apart
//! from the image divides the gain by 1 + pilot spp / image spp.

use flowlight_core::Rgb;
use flowlight_host::metrics::REL_EPS;
use flowlight_host::output::read_exr_rgb;
use std::path::Path;

const WINDOW: usize = 5;
const FLOOR: f64 = 0.05;
const RATES: (i32, i32) = (-3, 3);

struct Image {
    width: usize,
    height: usize,
    pixels: Vec<Rgb>,
}

/// Channel `c` (0, 1, 2: R, G, B) of `p`.
fn channel(p: Rgb, c: usize) -> f64 {
    p.to_array()[c] as f64
}

fn read(path: &Path) -> Result<Image, String> {
    let (width, height, layers) =
        read_exr_rgb(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let pixels = layers
        .into_iter()
        .next()
        .ok_or_else(|| format!("{}: no RGB layer", path.display()))?
        .1;
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Per pixel, the sample variance over `images` of each channel, summed over the channels
/// each divided by `scale`'s channel squared plus ε.
fn relative_variance(images: &[Image], scale: impl Fn(usize, usize) -> f64) -> Vec<f64> {
    let n = images.len() as f64;
    (0..images[0].pixels.len())
        .map(|i| {
            (0..3)
                .map(|c| {
                    let values = images.iter().map(|im| channel(im.pixels[i], c));
                    let mean = values.clone().sum::<f64>() / n;
                    let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
                    var / (scale(i, c).powi(2) + REL_EPS)
                })
                .sum()
        })
        .collect()
}

/// The mean of `v` over the `WINDOW` × `WINDOW` window around each pixel of the region
/// `[x0, x1) × [y0, y1)`, clamped to the region.
fn smoothed(v: &[f64], width: usize, (x0, x1, y0, y1): (usize, usize, usize, usize)) -> Vec<f64> {
    let h = WINDOW / 2;
    let mut out = Vec::with_capacity((x1 - x0) * (y1 - y0));
    for y in y0..y1 {
        for x in x0..x1 {
            let (ya, yb) = (y.saturating_sub(h).max(y0), (y + h + 1).min(y1));
            let (xa, xb) = (x.saturating_sub(h).max(x0), (x + h + 1).min(x1));
            let mut s = 0.0;
            for yy in ya..yb {
                s += v[yy * width + xa..yy * width + xb].iter().sum::<f64>();
            }
            out.push(s / ((yb - ya) * (xb - xa)) as f64);
        }
    }
    out
}

/// Rates (mean about 1) for a region's smoothed relative variances.
fn rates(v: &[f64]) -> Vec<f64> {
    let r: Vec<f64> = v.iter().map(|x| x.max(0.0).sqrt()).collect();
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    if mean <= 0.0 {
        return vec![1.0; r.len()];
    }
    r.iter()
        .map(|&x| {
            let k = x.max(FLOOR * mean) / mean;
            2f64.powi((k.log2().round() as i32).clamp(RATES.0, RATES.1))
        })
        .collect()
}

/// Uniform relMSE over the allocation's at the same total of samples.
fn gain(eval: &[f64], n: &[f64]) -> (f64, f64) {
    let mean_n = n.iter().sum::<f64>() / n.len() as f64;
    let uniform: f64 = eval.iter().sum();
    let allocated: f64 = eval.iter().zip(n).map(|(v, k)| v / k).sum();
    (uniform / (allocated * mean_n), mean_n)
}

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: pixel_allocation REF.exr --pilot P.exr… --eval E.exr… [--tile N]";
    let reference = read(Path::new(&args.next().ok_or(usage)?))?;
    let (mut pilot, mut eval, mut tile, mut list) = (Vec::new(), Vec::new(), 32usize, 0);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--pilot" => list = 1,
            "--eval" => list = 2,
            "--tile" => {
                let t = args.next().ok_or(usage)?;
                tile = t
                    .parse()
                    .map_err(|_| format!("--tile {t}: not a whole number"))?;
            }
            path if list == 1 => pilot.push(read(Path::new(path))?),
            path if list == 2 => eval.push(read(Path::new(path))?),
            _ => return Err(usage.into()),
        }
    }
    if pilot.len() < 2 || eval.len() < 2 || tile == 0 {
        return Err(format!(
            "{usage}: at least two pilot and two evaluation renders"
        ));
    }
    let (w, h) = (reference.width, reference.height);
    for im in pilot.iter().chain(&eval) {
        if (im.width, im.height) != (w, h) {
            return Err(format!(
                "a render is {}x{}, the reference {w}x{h}",
                im.width, im.height
            ));
        }
    }
    let pilot_mean = |i: usize, c: usize| {
        pilot.iter().map(|im| channel(im.pixels[i], c)).sum::<f64>() / pilot.len() as f64
    };
    let pilot_v = relative_variance(&pilot, pilot_mean);
    let eval_v = relative_variance(&eval, |i, c| channel(reference.pixels[i], c));
    let zero = eval_v.iter().filter(|&&v| v == 0.0).count();

    let global = rates(&smoothed(&pilot_v, w, (0, w, 0, h)));
    let mut per_tile = vec![0.0; w * h];
    for ty in (0..h).step_by(tile) {
        for tx in (0..w).step_by(tile) {
            let region = (tx, (tx + tile).min(w), ty, (ty + tile).min(h));
            let r = rates(&smoothed(&pilot_v, w, region));
            let mut k = r.into_iter();
            for y in region.2..region.3 {
                for x in region.0..region.1 {
                    per_tile[y * w + x] = k.next().expect("one rate per pixel");
                }
            }
        }
    }
    let sqrt_mean = eval_v.iter().map(|v| v.sqrt()).sum::<f64>() / eval_v.len() as f64;
    let mean = eval_v.iter().sum::<f64>() / eval_v.len() as f64;
    println!(
        "pixels {}, with no variance in the evaluation renders {:.3}; \
         pilot {} renders, evaluation {} renders",
        w * h,
        zero as f64 / (w * h) as f64,
        pilot.len(),
        eval.len()
    );
    println!(
        "Neyman bound from the evaluation renders themselves (biased high by their noise): {:.3}",
        mean / (sqrt_mean * sqrt_mean)
    );
    for (name, n) in [("global", &global), ("per tile", &per_tile)] {
        let (g, mean_n) = gain(&eval_v, n);
        println!("{name}: gain {g:.3} at equal samples (mean rate after rounding {mean_n:.3})");
    }
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("pixel_allocation: {e}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Neyman's allocation by hand: relative variances 4 and 1 want rates ∝ 2 : 1, i.e.
    /// 4/3 and 2/3; rounded to powers of two, 1 and 1/2 (mean 3/4), which the gain divides
    /// out: uniform Σv = 5, allocated 4/1 + 1/(1/2) = 6, gain 5 / (6 · 3/4) = 10/9.
    #[test]
    fn rates_follow_the_relative_standard_deviation_in_powers_of_two() {
        let n = rates(&[4.0, 1.0]);
        assert_eq!(n, vec![1.0, 0.5]);
        let (g, mean_n) = gain(&[4.0, 1.0], &n);
        assert!((mean_n - 0.75).abs() < 1e-12);
        assert!((g - 10.0 / 9.0).abs() < 1e-12, "{g}");
        // Uniform variance: every rate 1, no gain.
        let n = rates(&[2.0; 5]);
        assert!(n.iter().all(|&k| k == 1.0));
        assert!((gain(&[2.0; 5], &n).0 - 1.0).abs() < 1e-12);
    }

    /// A pixel the pilot saw as noiseless keeps samples (the floor), rates stay in 1/8 … 8,
    /// and a region with no variance at all is sampled uniformly.
    #[test]
    fn rates_are_floored_and_clamped() {
        let mut v = vec![0.0; 64];
        v[0] = 1e6;
        let n = rates(&v);
        assert_eq!(n[0], 8.0);
        assert!(n[1..].iter().all(|&k| k == 0.125), "{:?}", &n[..4]);
        assert_eq!(rates(&[0.0; 3]), vec![1.0; 3]);
    }

    /// The window mean stays inside its region: a spike outside the region does not leak in,
    /// and a constant region stays constant.
    #[test]
    fn smoothing_is_confined_to_the_region() {
        let (w, h) = (8, 8);
        let mut v = vec![1.0; w * h];
        v[7] = 100.0; // x = 7, y = 0: outside the region x < 4
        let s = smoothed(&v, w, (0, 4, 0, h));
        assert_eq!(s.len(), 4 * h);
        assert!(s.iter().all(|&x| (x - 1.0).abs() < 1e-12));
        let s = smoothed(&v, w, (4, 8, 0, 4));
        // (7, 0)'s window clamped to the region: 3 × 3 pixels, one of them the spike.
        assert!((s[3] - (8.0 + 100.0) / 9.0).abs() < 1e-12, "{}", s[3]);
    }

    /// The sample variance over images, relative to a scale: two images 1 and 3 in every
    /// channel have variance 2 per channel; over a scale of 1, 3 · 2 / (1 + ε).
    #[test]
    fn relative_variance_sums_the_channels() {
        let im = |x: f32| Image {
            width: 1,
            height: 1,
            pixels: vec![Rgb::new(x, x, x)],
        };
        let v = relative_variance(&[im(1.0), im(3.0)], |_, _| 1.0);
        assert!((v[0] - 6.0 / (1.0 + REL_EPS)).abs() < 1e-12, "{}", v[0]);
    }
}
