//! References: the mean of two independent renders and the variance of that mean (see the
//! crate doc for the formula), stored as EXR layers `variance` and `layer0..layerN`.

use crate::run::{render_request, Budget, RenderRequest};
use flowlight_core::Rgb;
use flowlight_host::metrics;
use flowlight_host::output::{read_exr_metadata, read_exr_rgb, write_exr, ExrMetadata, ImageLayer};
use std::path::{Path, PathBuf};

/// A reference image with its sample count and (when known) the variance of its mean.
#[derive(Clone, Debug)]
pub struct Reference {
    pub width: usize,
    pub height: usize,
    pub image: Vec<Rgb>,
    /// Per-pixel, per-channel variance of `image` (the estimate's own noise).
    pub variance: Option<Vec<Rgb>>,
    /// Lighting layers by name (`layer0`, …).
    pub layers: Vec<(String, Vec<Rgb>)>,
    /// Mean samples per pixel in total.
    pub spp: f64,
    /// Extra metadata (integrator, parameters, seeds, wall time).
    pub meta: Vec<(String, String)>,
}

impl Reference {
    /// The metadata value of `key` (`flowlight.spp`, `flowlight.path_depth`, …), if recorded.
    pub fn meta_value(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The reference floor, mean Var(b) / (b² + ε) over pixels and channels (the relMSE its
    /// own noise adds to every comparison; `docs/bench.md`), from the `variance` layer.
    pub fn floor(&self) -> Option<f64> {
        let v = self.variance.as_deref()?;
        metrics::compare(&self.image, &self.image, Some(v))
            .ok()?
            .reference_floor
    }

    /// The integrator's `path_depth` it was rendered with (metadata `flowlight.path_depth`).
    pub fn path_depth(&self) -> Option<u32> {
        self.meta_value("flowlight.path_depth")?.trim().parse().ok()
    }

    /// Layer `k` (`layerK`), if the reference has it.
    pub fn layer(&self, k: usize) -> Option<&[Rgb]> {
        let name = format!("layer{k}");
        self.layers
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, p)| p.as_slice())
    }
}

/// Combines two independent estimates of the same image (means of `na`, `nb` samples per
/// pixel) into their weighted mean and the estimated variance of that mean.
pub fn combine_halves(a: &[Rgb], na: f64, b: &[Rgb], nb: f64) -> (Vec<Rgb>, Vec<Rgb>) {
    let (wa, wb) = (na / (na + nb), nb / (na + nb));
    let k = 1.0 / ((1.0 / na + 1.0 / nb) * (na + nb));
    let mut mean = Vec::with_capacity(a.len());
    let mut var = Vec::with_capacity(a.len());
    for (x, y) in a.iter().zip(b) {
        let m = |p: f32, q: f32| (wa * p as f64 + wb * q as f64) as f32;
        let v = |p: f32, q: f32| (k * (p as f64 - q as f64).powi(2)) as f32;
        mean.push(Rgb::new(m(x.r, y.r), m(x.g, y.g), m(x.b, y.b)));
        var.push(Rgb::new(v(x.r, y.r), v(x.g, y.g), v(x.b, y.b)));
    }
    (mean, var)
}

fn weighted_mean(a: &[Rgb], na: f64, b: &[Rgb], nb: f64) -> Vec<Rgb> {
    combine_halves(a, na, b, nb).0
}

/// Renders a reference: two independent halves of `budget` (seeds `seed`, `seed + 1`).
/// `progress` is told about each half as it starts.
pub fn render_reference(req: &RenderRequest, progress: &dyn Fn(&str)) -> Result<Reference, String> {
    // An odd sample count gives the first half the extra sample: the halves add up to the
    // budget asked for (combine_halves weighs them by their counts).
    let (first, second) = match req.budget {
        Budget::Spp(n) if n >= 2 => (Budget::Spp(n - n / 2), Budget::Spp(n / 2)),
        Budget::Spp(n) => return Err(format!("a reference needs at least 2 spp, got {n}")),
        Budget::Time(t) => (Budget::Time(t / 2.0), Budget::Time(t / 2.0)),
    };
    let mut a_req = req.clone();
    a_req.budget = first;
    let mut b_req = a_req.clone();
    b_req.budget = second;
    b_req.seed = req.seed.wrapping_add(1);
    progress(&format!("first half (seed {})", a_req.seed));
    let a = render_request(&a_req)?;
    progress(&format!("second half (seed {})", b_req.seed));
    let b = render_request(&b_req)?;
    let (image, variance) = combine_halves(&a.image, a.spp, &b.image, b.spp);
    let layers = a
        .layers
        .iter()
        .zip(&b.layers)
        .enumerate()
        .map(|(k, (la, lb))| (format!("layer{k}"), weighted_mean(la, a.spp, lb, b.spp)))
        .collect();
    Ok(Reference {
        width: a.width,
        height: a.height,
        image,
        variance: Some(variance),
        layers,
        spp: a.spp + b.spp,
        meta: vec![
            ("flowlight.integrator".into(), a.plugin.clone()),
            ("flowlight.params".into(), a.params.clone()),
            (
                "flowlight.seed".into(),
                format!("{} and {}", a_req.seed, b_req.seed),
            ),
            (
                "flowlight.reference.wall".into(),
                format!("{:.3}", a.wall + b.wall),
            ),
            (
                "flowlight.reference.invalid_samples".into(),
                (a.invalid_samples + b.invalid_samples).to_string(),
            ),
            (
                "flowlight.reference.halves".into(),
                format!(
                    "{} spp (seed {}) + {} spp (seed {})",
                    a.spp, a_req.seed, b.spp, b_req.seed
                ),
            ),
        ]
        .into_iter()
        .chain(depth_meta("flowlight.path_depth", a.path_depth))
        .chain(depth_meta("flowlight.max_ray_depth", a.max_ray_depth))
        .collect(),
    })
}

fn depth_meta(key: &str, v: Option<u32>) -> Option<(String, String)> {
    v.map(|d| (key.to_string(), d.to_string()))
}

fn parse_spp(meta: &ExrMetadata) -> Option<f64> {
    meta.get("flowlight.spp")?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The `flowlight.*` metadata of an EXR (seeds, parameters, depths, floor), kept when a
/// reference is read so that writing it again loses nothing; the keys [`write_reference`]
/// computes itself are left out.
fn kept_meta(p: &Path) -> Result<Vec<(String, String)>, String> {
    let meta = read_exr_metadata(p).map_err(|e| e.to_string())?;
    let mut kept: Vec<(String, String)> = meta
        .entries
        .iter()
        .filter(|(k, _)| {
            k.starts_with("flowlight.")
                && ![
                    "flowlight.reference",
                    "flowlight.spp",
                    "flowlight.variance",
                    FLOOR_KEY,
                ]
                .contains(&k.as_str())
        })
        .cloned()
        .collect();
    if meta.get("flowlight.reference") != Some("true") {
        kept.push(("flowlight.reference.from".into(), p.display().to_string()));
    }
    Ok(kept)
}

/// Metadata key of the recorded reference floor.
pub const FLOOR_KEY: &str = "flowlight.reference.floor";

/// Makes a reference from existing renders: one EXR (its variance is unknown unless it is
/// itself a reference with a `variance` layer), or two independent renders of the same scene
/// (averaged, with the variance estimated from their difference).
pub fn reference_from_exrs(paths: &[PathBuf]) -> Result<Reference, String> {
    type Loaded = (usize, usize, Vec<(String, Vec<Rgb>)>, f64);
    let load = |p: &Path| -> Result<Loaded, String> {
        let (w, h, layers) = read_exr_rgb(p).map_err(|e| e.to_string())?;
        let meta = read_exr_metadata(p).map_err(|e| e.to_string())?;
        if layers.first().is_none_or(|(n, _)| !n.is_empty()) {
            return Err(format!("{}: no main RGB layer", p.display()));
        }
        let spp = parse_spp(&meta).unwrap_or(f64::NAN);
        Ok((w, h, layers, spp))
    };
    match paths {
        [one] => {
            let (w, h, mut layers, spp) = load(one)?;
            let image = layers.remove(0).1;
            let variance = layers
                .iter()
                .position(|(n, _)| n == "variance")
                .map(|i| layers.remove(i).1);
            Ok(Reference {
                width: w,
                height: h,
                image,
                variance,
                layers,
                spp,
                meta: kept_meta(one)?,
            })
        }
        [p, q] => {
            check_independent(p, q)?;
            let (w, h, mut la, na) = load(p)?;
            let (w2, h2, mut lb, nb) = load(q)?;
            if la.first().map(|l| &l.1) == lb.first().map(|l| &l.1) {
                return Err(format!(
                    "{} and {} hold the same image: a reference's variance comes from two independent renders (render the second with another --seed)",
                    p.display(),
                    q.display()
                ));
            }
            if (w, h) != (w2, h2) {
                return Err(format!(
                    "{} is {w}x{h}, {} is {w2}x{h2}",
                    p.display(),
                    q.display()
                ));
            }
            if !(na > 0.0 && nb > 0.0) {
                return Err(format!(
                    "{} or {} has no flowlight.spp metadata: cannot weigh them",
                    p.display(),
                    q.display()
                ));
            }
            let (a, b) = (la.remove(0).1, lb.remove(0).1);
            let (image, variance) = combine_halves(&a, na, &b, nb);
            let layers = la
                .iter()
                .filter(|(n, _)| n.starts_with("layer"))
                .filter_map(|(n, x)| {
                    let (_, y) = lb.iter().find(|(m, _)| m == n)?;
                    Some((n.clone(), weighted_mean(x, na, y, nb)))
                })
                .collect();
            Ok(Reference {
                width: w,
                height: h,
                image,
                variance: Some(variance),
                layers,
                spp: na + nb,
                meta: vec![(
                    "flowlight.reference.from".into(),
                    format!("{} + {}", p.display(), q.display()),
                )],
            })
        }
        _ => Err("--from takes one EXR, or two independent renders of the same scene".into()),
    }
}

/// Refuses two `--from` files that cannot be independent renders: the same file (under any
/// name), or two renders of the same seed. Their difference would estimate a variance of
/// 0 and a floor of 0.
fn check_independent(p: &Path, q: &Path) -> Result<(), String> {
    let canonical = |x: &Path| x.canonicalize().unwrap_or_else(|_| x.to_path_buf());
    if canonical(p) == canonical(q) {
        return Err(format!(
            "--from {} is given twice (also as {}): a reference's variance comes from two independent renders",
            p.display(),
            q.display()
        ));
    }
    let seed = |x: &Path| -> Result<Option<String>, String> {
        let meta = read_exr_metadata(x).map_err(|e| e.to_string())?;
        Ok(meta.get("flowlight.seed").map(str::to_string))
    };
    if let (Some(a), Some(b)) = (seed(p)?, seed(q)?) {
        if a == b {
            return Err(format!(
                "{} and {} were rendered with the same seed ({a}): they are not independent; render the second with another --seed",
                p.display(),
                q.display()
            ));
        }
    }
    Ok(())
}

/// Writes a reference EXR: main image, `variance` (when known), lighting layers, and metadata
/// (`flowlight.reference`, `flowlight.spp`, …).
///
/// The image and the lighting layers are stored rounded to half-float precision (11
/// significant bits, relative error ≤ 2⁻¹¹ per value, kept in 32-bit channels so nothing
/// overflows or goes subnormal): the zeroed low bits let ZIP shrink the file, and the
/// rounding adds at most (2⁻¹¹)² ≈ 2.4·10⁻⁷ (about 8·10⁻⁸ on average) to any relMSE against
/// it, far below every floor (≥ 10⁻⁵ here). The
/// `variance` layer keeps full precision (the floor of dark pixels is made of tiny values).
pub fn write_reference(path: &Path, r: &Reference) -> Result<(), String> {
    let image = to_half_precision(&r.image);
    let lighting: Vec<(String, Vec<Rgb>)> = r
        .layers
        .iter()
        .map(|(n, p)| (n.clone(), to_half_precision(p)))
        .collect();
    let mut layers = vec![ImageLayer {
        name: String::new(),
        pixels: &image,
    }];
    if let Some(v) = &r.variance {
        layers.push(ImageLayer {
            name: "variance".into(),
            pixels: v,
        });
    }
    for (n, p) in &lighting {
        layers.push(ImageLayer {
            name: n.clone(),
            pixels: p,
        });
    }
    let mut entries = vec![
        (
            "software".to_string(),
            format!("flowlight {}", env!("CARGO_PKG_VERSION")),
        ),
        ("flowlight.reference".into(), "true".into()),
        ("flowlight.spp".into(), format!("{}", r.spp)),
        (
            "flowlight.variance".into(),
            if r.variance.is_some() {
                "layer 'variance': per-pixel variance of the mean, from two independent renders"
                    .into()
            } else {
                "unknown".into()
            },
        ),
    ];
    if let Some(f) = r.floor() {
        entries.push((
            FLOOR_KEY.into(),
            format!(
                "{f:.6e} (mean Var/(b^2 + {}) of the main image)",
                metrics::REL_EPS
            ),
        ));
    }
    for (k, v) in &r.meta {
        if !entries.iter().any(|(e, _)| e == k) {
            entries.push((k.clone(), v.clone()));
        }
    }
    write_exr(path, r.width, r.height, &layers, &ExrMetadata { entries }).map_err(|e| e.to_string())
}

/// Rounds every channel to the nearest value with 11 significant bits (IEEE half's
/// precision, f32's range): the low 13 mantissa bits become zero.
pub fn to_half_precision(pixels: &[Rgb]) -> Vec<Rgb> {
    let round = |x: f32| {
        if !x.is_finite() {
            return x;
        }
        f32::from_bits(x.to_bits().wrapping_add(0x1000) & !0x1fff)
    };
    pixels
        .iter()
        .map(|p| Rgb::new(round(p.r), round(p.g), round(p.b)))
        .collect()
}

/// Reads a reference written by [`write_reference`] (or any EXR: then without variance).
pub fn read_reference(path: &Path) -> Result<Reference, String> {
    reference_from_exrs(&[path.to_path_buf()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_combine_into_mean_and_variance_of_the_mean() {
        let a = vec![Rgb::splat(1.0)];
        let b = vec![Rgb::splat(3.0)];
        let (m, v) = combine_halves(&a, 10.0, &b, 10.0);
        assert_eq!(m[0], Rgb::splat(2.0));
        // (A − B)² / 4 for equal halves.
        assert_eq!(v[0], Rgb::splat(1.0));
        let (m, _) = combine_halves(&a, 30.0, &b, 10.0);
        assert_eq!(m[0], Rgb::splat(1.5));
    }

    #[test]
    fn half_precision_rounding_keeps_11_bits() {
        for x in [1.0f32, 0.1, 3.3e-6, 123.456, 7.0e5, -2.5] {
            let y = to_half_precision(&[Rgb::splat(x)])[0].r;
            assert_eq!(y.to_bits() & 0x1fff, 0, "{x}");
            assert!(((y - x) / x).abs() <= 2f32.powi(-11) * 1.0001, "{x} -> {y}");
        }
        // 1 + 2^-11 + 2^-13 is nearer 1 + 2^-10 than 1.
        let up = 1.0 + 2f32.powi(-11) + 2f32.powi(-13);
        assert_eq!(
            to_half_precision(&[Rgb::splat(up)])[0].r,
            1.0 + 2f32.powi(-10)
        );
    }

    #[test]
    fn variance_estimate_is_unbiased() {
        // Two independent means of n uniform samples: E[estimate] = Var(U)/(2n).
        let mut rng = flowlight_core::rng::Rng::new(7, 1);
        let n = 8;
        let trials = 20000;
        let mut sum = 0.0;
        for _ in 0..trials {
            let mut half = || (0..n).map(|_| rng.uniform() as f64).sum::<f64>() / n as f64;
            let (x, y) = (half(), half());
            let (_, v) = combine_halves(
                &[Rgb::splat(x as f32)],
                n as f64,
                &[Rgb::splat(y as f32)],
                n as f64,
            );
            sum += v[0].r as f64;
        }
        let expected = 1.0 / 12.0 / (2 * n) as f64;
        let got = sum / trials as f64;
        assert!((got / expected - 1.0).abs() < 0.05, "{got} vs {expected}");
    }
}
