//! Cornell box: the two MCPT variants estimate the same image, lighting layers sum to it, and
//! nothing invalid is produced.

use crate::common;

use common::{render, renderer_at};
use flowlight_core::Rgb;

type Channel = fn(Rgb) -> f32;

/// Per-block means and standard errors of one channel (pixels are independent samples).
fn block_stats(
    img: &[Rgb],
    w: usize,
    h: usize,
    block: usize,
    ch: fn(Rgb) -> f32,
) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for by in (0..h).step_by(block) {
        for bx in (0..w).step_by(block) {
            let vals: Vec<f64> = (by..by + block)
                .flat_map(|y| (bx..bx + block).map(move |x| (x, y)))
                .map(|(x, y)| ch(img[y * w + x]) as f64)
                .collect();
            let n = vals.len() as f64;
            let mean = vals.iter().sum::<f64>() / n;
            let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
            out.push((mean, (var / n).sqrt()));
        }
    }
    out
}

#[test]
fn entangled_and_untangled_agree_per_region() {
    let (w, h) = (64usize, 64usize);
    let ent = render(&renderer_at(
        "cornell-box/cornell-box.toml",
        w as u32,
        h as u32,
        64,
        &[("variant", "entangled".into())],
    ));
    let mut unt = renderer_at(
        "cornell-box/cornell-box.toml",
        w as u32,
        h as u32,
        256,
        &[("variant", "untangled".into())],
    );
    unt.options.seed += 1; // independent of the entangled render
    let unt = render(&unt);
    assert_eq!(ent.stats.invalid_deposits + unt.stats.invalid_deposits, 0);
    let (a, b) = (ent.frame.image(), unt.frame.image());
    let channels: [(&str, Channel); 3] = [("r", |c| c.r), ("g", |c| c.g), ("b", |c| c.b)];
    let mut worst = 0.0f64;
    for (name, ch) in channels {
        let sa = block_stats(&a, w, h, 8, ch);
        let sb = block_stats(&b, w, h, 8, ch);
        for (i, ((ma, ea), (mb, eb))) in sa.iter().zip(&sb).enumerate() {
            let se = (ea * ea + eb * eb).sqrt().max(1e-6);
            let z = (ma - mb) / se;
            worst = worst.max(z.abs());
            assert!(z.abs() < 5.0, "channel {name} block {i}: entangled {ma:.4}±{ea:.4} vs untangled {mb:.4}±{eb:.4} (z = {z:.2})");
        }
    }
    let (ma, mb) = (mean_lum(&a), mean_lum(&b));
    assert!(
        (ma / mb - 1.0).abs() < 0.02,
        "image means differ: {ma} vs {mb} (worst block z {worst:.2})"
    );
}

fn mean_lum(img: &[Rgb]) -> f64 {
    img.iter().map(|c| c.luminance() as f64).sum::<f64>() / img.len() as f64
}

#[test]
fn lighting_layers_sum_to_the_image() {
    for variant in ["entangled", "untangled"] {
        let s = renderer_at(
            "cornell-box/cornell-box.toml",
            32,
            32,
            8,
            &[
                ("variant", variant.into()),
                ("layers", true.into()),
                ("path_depth", toml::Value::Integer(5)),
            ],
        );
        let out = render(&s);
        assert_eq!(out.frame.layer_count, 6, "layers 0..=N");
        let img = out.frame.image();
        let layers: Vec<Vec<Rgb>> = (0..6).map(|k| out.frame.layer(k)).collect();
        for (i, px) in img.iter().enumerate() {
            let sum = layers.iter().fold(Rgb::ZERO, |acc, l| acc + l[i]);
            for (s, p) in [(sum.r, px.r), (sum.g, px.g), (sum.b, px.b)] {
                assert!(
                    (s - p).abs() <= 1e-4 * p.abs().max(1.0),
                    "{variant}: pixel {i}: layers sum {s} vs image {p}"
                );
            }
        }
        // Layer 0 is light seen directly: only the lamp's pixels; layer 1 is direct lighting.
        let l0 = mean_lum(&layers[0]);
        let l1 = mean_lum(&layers[1]);
        assert!(l0 > 0.0 && l1 > 0.0, "{variant}: empty layers 0/1");
        assert!(layers[0].iter().filter(|c| c.luminance() > 0.0).count() < 32 * 32 / 10);
    }
}
