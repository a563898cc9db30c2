//! `flowlight reference`: a long two-half reference render, or one made from existing EXRs.

use crate::parse_sets;
use anyhow::{anyhow, Result};
use std::path::PathBuf;

#[allow(clippy::too_many_arguments)]
pub fn run(
    config: Option<PathBuf>,
    spp: Option<u32>,
    time: Option<f64>,
    out: Option<PathBuf>,
    (width, height): (Option<u32>, Option<u32>),
    seed: u64,
    threads: usize,
    set: &[String],
    from: &[PathBuf],
) -> Result<()> {
    use flowlight_bench::{self as bench, Budget, RenderRequest};
    let t0 = std::time::Instant::now();
    let scene = match &config {
        Some(c) if from.is_empty() => Some(
            flowlight_scene::config::load_config(c)
                .map_err(|e| anyhow!("{e}"))?
                .scene,
        ),
        _ => None,
    };
    let config_path = config.clone();
    // The reference and its preview must not be one of the inputs: checked before rendering.
    let check_out = |out: &std::path::Path| -> Result<()> {
        let mut inputs: Vec<(&str, &std::path::Path)> = from
            .iter()
            .map(|f| ("a --from image", f.as_path()))
            .collect();
        if let Some(c) = &config_path {
            inputs.push(("the config", c.as_path()));
        }
        if let Some(s) = &scene {
            inputs.push(("the scene", s.as_path()));
        }
        for o in [out.to_path_buf(), out.with_extension("png")] {
            crate::refuse_input_as_output(&o, &inputs)?;
        }
        Ok(())
    };
    let (r, out) = if !from.is_empty() {
        let out = out.ok_or_else(|| anyhow!("--from needs --out"))?;
        check_out(&out)?;
        (
            bench::reference_from_exrs(from).map_err(|e| anyhow!(e))?,
            out,
        )
    } else {
        let config = config.ok_or_else(|| anyhow!("a config is required"))?;
        let cfg = flowlight_scene::config::load_config(&config).map_err(|e| anyhow!("{e}"))?;
        let budget = match (spp, time, cfg.budget) {
            (_, Some(t), _) if t > 0.0 && t.is_finite() => Budget::Time(t),
            (_, Some(t), _) => {
                return Err(anyhow!(
                    "--time must be a positive number of seconds, got {t}"
                ))
            }
            (Some(n), None, _) => Budget::Spp(n),
            (None, None, flowlight_scene::config::SampleBudget::Spp(n)) => Budget::Spp(n),
            (None, None, flowlight_scene::config::SampleBudget::Time(t)) => Budget::Time(t),
        };
        let out = out.unwrap_or_else(|| {
            let stem = config
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "reference".into());
            cfg.base_dir.join(format!("{stem}.ref.exr"))
        });
        check_out(&out)?;
        let req = RenderRequest {
            config,
            plugin: None,
            params: parse_sets(set)?,
            width,
            height,
            budget,
            seed,
            threads,
        };
        let mut r = bench::render_reference(&req, &|m| eprintln!("flowlight reference: {m}"))
            .map_err(|e| anyhow!(e))?;
        // The command that made it, for whoever has to make it again.
        let args: Vec<String> = std::env::args().skip(1).collect();
        r.meta.push((
            "flowlight.reference.command".into(),
            format!("flowlight {}", args.join(" ")),
        ));
        (r, out)
    };
    let png = out.with_extension("png");
    bench::write_reference(&out, &r).map_err(|e| anyhow!(e))?;
    // An sRGB preview beside it, to look at the reference without an EXR viewer.
    flowlight_host::output::write_png_preview(&png, r.width, r.height, &r.image, 0.0)
        .map_err(|e| anyhow!("{e}"))?;
    println!("reference summary");
    println!("  size            {}x{}", r.width, r.height);
    println!("  samples         {} spp", r.spp);
    if let Some(f) = r.floor() {
        println!("  floor           {f:.4e} (relMSE the reference's own noise adds)");
    }
    if let Some(v) = &r.variance {
        let n = v.len().max(1) as f64;
        let mean_var = v.iter().map(|c| c.luminance() as f64).sum::<f64>() / n;
        println!(
            "  variance        mean per-pixel variance of the mean (luminance) {mean_var:.4e}"
        );
    } else {
        println!("  variance        unknown (one image without a variance layer)");
    }
    if !r.layers.is_empty() {
        println!("  layers          {}", r.layers.len());
    }
    println!("  wall time       {:.3} s", t0.elapsed().as_secs_f64());
    println!("  wrote           {}", out.display());
    println!("  wrote           {}", png.display());
    Ok(())
}
