//! `flowlight compare`: an image against a reference (RMSE, relMSE, luminance ratio, error map).

use anyhow::{anyhow, Result};

pub fn run(
    a: &std::path::Path,
    b: &std::path::Path,
    out: Option<&std::path::Path>,
    eps: f64,
    layer: Option<&str>,
) -> Result<()> {
    use flowlight_bench as bench;
    use flowlight_host::metrics;
    if let Some(out) = out {
        crate::refuse_input_as_output(out, &[("the image", a), ("the reference", b)])?;
    }
    let mut ra = bench::read_reference(a).map_err(|e| anyhow!(e))?;
    if let Some(name) = layer {
        // Another layer of the image (e.g. `denoised`) against the reference's main image.
        let (_, _, layers) = flowlight_host::output::read_exr_rgb(a).map_err(|e| anyhow!(e))?;
        ra.image = layers
            .into_iter()
            .find(|(n, _)| n == name)
            .ok_or_else(|| anyhow!("{} has no layer \"{name}\"", a.display()))?
            .1;
    }
    let rb = bench::read_reference(b).map_err(|e| anyhow!(e))?;
    if (ra.width, ra.height) != (rb.width, rb.height) {
        return Err(anyhow!(
            "{} is {}x{} but {} is {}x{}",
            a.display(),
            ra.width,
            ra.height,
            b.display(),
            rb.width,
            rb.height
        ));
    }
    let e = metrics::compare_with(&ra.image, &rb.image, rb.variance.as_deref(), eps)
        .map_err(|e| anyhow!("{} vs {}: {e}", a.display(), b.display()))?;
    match layer {
        Some(name) => println!(
            "compare {} (layer {name}) against {}",
            a.display(),
            b.display()
        ),
        None => println!("compare {} against {}", a.display(), b.display()),
    }
    println!(
        "  pixels          {} ({}x{})",
        e.pixels, ra.width, ra.height
    );
    if e.non_finite > 0 {
        println!("  non-finite      {} pixels skipped", e.non_finite);
    }
    println!("  RMSE            {:.6e}", e.rmse);
    println!(
        "  relMSE          {:.6e}  (mean (a-b)^2/(b^2+eps), eps = {eps})",
        e.relmse
    );
    if let Some(f) = e.reference_floor {
        println!(
            "  reference floor {f:.6e}  (the reference's own variance in relMSE units; {} spp)",
            rb.spp
        );
    }
    println!(
        "  luminance ratio {:.6}  (mean {:.6} / {:.6})",
        e.luminance_ratio, e.mean_luminance_a, e.mean_luminance_b
    );
    for k in 0.. {
        match (ra.layer(k), rb.layer(k)) {
            (Some(la), Some(lb)) => {
                let le = metrics::compare_with(la, lb, None, eps).map_err(|e| anyhow!(e))?;
                println!(
                    "  layer{k:<9} relMSE {:.4e}  RMSE {:.4e}  luminance ratio {:.4}",
                    le.relmse, le.rmse, le.luminance_ratio
                );
            }
            _ => break,
        }
    }
    if let Some(out) = out {
        let map = metrics::relative_error_map(&ra.image, &rb.image, eps);
        let (lo, hi) = metrics::FALSE_COLOUR_LOG10_RANGE;
        metrics::write_rgb8_png(out, ra.width, ra.height, &metrics::false_colour(&map))
            .map_err(|e| anyhow!(e))?;
        println!(
            "  wrote           {} (relative squared error, log scale 1e{lo}..1e{hi}: black..yellow-white; magenta = not finite)",
            out.display()
        );
    }
    Ok(())
}
