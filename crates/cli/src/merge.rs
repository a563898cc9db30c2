//! `flowlight merge OUT.exr PART.exr...`: joins the parts of a distributed render
//! (docs/distributed.md; the rules are `flowlight_host::parts::merge`'s).

use anyhow::{anyhow, Result};
use std::path::{Path, PathBuf};

pub fn run(out: &Path, parts: &[PathBuf], allow_missing: bool) -> Result<()> {
    let report = flowlight_host::parts::merge(out, parts, allow_missing).map_err(|e| anyhow!(e))?;
    if let Some(w) = &report.stats_warning {
        eprintln!("warning: {w}");
    }
    if !report.missing.is_empty() {
        eprintln!(
            "warning: samples {} of 0..{} are missing: wrote a partial image (flowlight.partial = true)",
            flowlight_host::parts::format_ranges(&report.missing),
            report.total
        );
    }
    println!("merge summary");
    println!("  parts           {}", parts.len());
    println!(
        "  samples         {} of 0..{}",
        flowlight_host::parts::format_ranges(&report.ranges),
        report.total
    );
    for p in &report.written {
        println!("  wrote           {}", p.display());
    }
    Ok(())
}
