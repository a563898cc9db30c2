//! `flowlight bench`: a benchmark suite, error against wall time (docs/bench.md).

use anyhow::{anyhow, Result};

pub fn run(suite: &std::path::Path, ov: flowlight_bench::BenchOverrides) -> Result<()> {
    use flowlight_bench as bench;
    let s = bench::load_suite(suite).map_err(|e| anyhow!(e))?;
    if let Some(b) = &ov.budgets {
        if b.is_empty() || b.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(anyhow!("--budgets must be positive seconds"));
        }
    }
    if ov.seeds.as_ref().is_some_and(|s| s.is_empty()) {
        return Err(anyhow!("--seeds must not be empty"));
    }
    let report = bench::run_suite(&s, &ov, &|m| eprintln!("{m}")).map_err(|e| anyhow!(e))?;
    println!(
        "bench summary (efficiency = 1/(relMSE x wall time), relative to '{}')",
        s.baseline
    );
    println!(
        "  {:<16} {:<28} {:>8} {:>8} {:>11} {:>11} {:>8}",
        "scene", "method", "budget", "wall", "relMSE", "RMSE", "vs base"
    );
    for r in &report.summary {
        println!(
            "  {:<16} {:<28} {:>8.2} {:>8.3} {:>11.4e} {:>11.4e} {:>8.2}",
            r.scene, r.method, r.budget, r.wall, r.relmse, r.rmse, r.relative_efficiency
        );
    }
    for f in &report.files {
        println!("  wrote           {}", f.display());
    }
    if !report.refused.is_empty() {
        return Err(anyhow!(
            "{} comparison(s) refused:\n{}",
            report.refused.len(),
            report.refused.join("\n")
        ));
    }
    Ok(())
}
