//! `flowlight seams`: the seam metric of an EXR (tile-edge artefacts of tile-based ERPT,
//! thesis §5.9): mean |ΔY| across tile borders over mean |ΔY| inside tiles
//! ([`flowlight_bench::seams`]).

use anyhow::{anyhow, Result};
use std::path::Path;

/// Prints the seam metric of `layer` (the main RGB layer when `None`) of `image` for square
/// tiles of `tile` pixels, on one line.
pub fn run(image: &Path, tile: usize, layer: Option<&str>) -> Result<()> {
    // The error's text already names the file and its cause: as a string, so `{:#}` does
    // not print the cause chain again.
    let (width, height, layers) =
        flowlight_host::output::read_exr_rgb(image).map_err(|e| anyhow!(e.to_string()))?;
    let name = layer.unwrap_or("");
    let Some((_, pixels)) = layers.iter().find(|(n, _)| n == name) else {
        let names: Vec<String> = layers
            .iter()
            .map(|(n, _)| {
                if n.is_empty() {
                    "(main)".to_owned()
                } else {
                    n.clone()
                }
            })
            .collect();
        let wanted = if name.is_empty() {
            "the main RGB layer"
        } else {
            name
        };
        return Err(anyhow!(
            "{}: no layer {wanted:?} (layers: {})",
            image.display(),
            if names.is_empty() {
                "none".to_owned()
            } else {
                names.join(", ")
            }
        ));
    };
    let m = flowlight_bench::seam_metric(pixels, width, height, tile)
        .map_err(|e| anyhow!("{}: {e}", image.display()))?;
    println!(
        "seam ratio {:.4} (border mean |dY| {} over {} pairs, inside {} over {} pairs)",
        m.ratio,
        sig4(m.border_mean),
        m.border_pairs,
        sig4(m.inside_mean),
        m.inside_pairs
    );
    Ok(())
}

/// Four significant digits, plain for 1e-3 ≤ |v| < 1e6 (0.01234), else in exponent form.
fn sig4(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".to_owned()
    } else if (1e-3..1e6).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::sig4;

    #[test]
    fn four_significant_digits() {
        assert_eq!(sig4(0.012_341), "0.01234");
        assert_eq!(sig4(0.011_97), "0.01197");
        assert_eq!(sig4(1.5), "1.500");
        assert_eq!(sig4(12_345.6), "12346");
        assert_eq!(sig4(0.0), "0");
        assert_eq!(sig4(2.5e-7), "2.500e-7");
    }
}
