//! Means over seeds, efficiency 1/(relMSE × wall time) relative to the baseline method, and
//! the tables `results.csv`, `layers.csv`, `summary.csv`, `summary.md`.

use crate::run::Run;
use crate::suite::Suite;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Mean over seeds of one (scene, method, budget).
#[derive(Clone, Debug)]
pub struct SummaryRow {
    pub scene: String,
    pub method: String,
    pub budget: f64,
    pub wall: f64,
    pub spp: f64,
    pub relmse: f64,
    pub rmse: f64,
    pub luminance_ratio: f64,
    /// 1 / (relMSE × wall time).
    pub efficiency: f64,
    /// Efficiency over the baseline method's at the same scene and budget.
    pub relative_efficiency: f64,
    pub runs: usize,
    /// The method's estimator is biased (its renders say so): the tables mark it.
    pub biased: bool,
}

/// Everything a bench produced.
pub struct BenchReport {
    pub runs: Vec<Run>,
    pub summary: Vec<SummaryRow>,
    pub files: Vec<PathBuf>,
    /// One line per refused comparison (floor rule, path depth); empty when all passed.
    pub refused: Vec<String>,
}

/// Means over seeds, efficiencies, and efficiencies relative to `baseline`.
pub fn summarise(runs: &[Run], baseline: &str) -> Vec<SummaryRow> {
    // Keep the run order (scenes, then methods as listed) with a BTreeMap on first index.
    let mut groups: BTreeMap<usize, Vec<&Run>> = BTreeMap::new();
    let mut index: Vec<(String, String, u64)> = Vec::new();
    for r in runs {
        let key = (r.scene.clone(), r.method.clone(), r.budget.to_bits());
        let i = match index.iter().position(|k| *k == key) {
            Some(i) => i,
            None => {
                index.push(key);
                index.len() - 1
            }
        };
        groups.entry(i).or_default().push(r);
    }
    let mut rows: Vec<SummaryRow> = groups
        .values()
        .map(|g| {
            let n = g.len() as f64;
            let mean = |f: &dyn Fn(&Run) -> f64| g.iter().map(|r| f(r)).sum::<f64>() / n;
            let wall = mean(&|r| r.wall);
            let relmse = mean(&|r| r.errors.relmse);
            SummaryRow {
                scene: g[0].scene.clone(),
                method: g[0].method.clone(),
                budget: g[0].budget,
                wall,
                spp: mean(&|r| r.spp),
                relmse,
                rmse: mean(&|r| r.errors.rmse),
                luminance_ratio: mean(&|r| r.errors.luminance_ratio),
                efficiency: 1.0 / (relmse * wall),
                relative_efficiency: f64::NAN,
                runs: g.len(),
                biased: g.iter().any(|r| r.biased),
            }
        })
        .collect();
    let base: Vec<(String, u64, f64)> = rows
        .iter()
        .filter(|r| r.method == baseline)
        .map(|r| (r.scene.clone(), r.budget.to_bits(), r.efficiency))
        .collect();
    for r in &mut rows {
        if let Some((_, _, e)) = base
            .iter()
            .find(|(s, b, _)| *s == r.scene && *b == r.budget.to_bits())
        {
            r.relative_efficiency = r.efficiency / e;
        }
    }
    rows
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), String> {
    flowlight_host::output::write_atomically(path, |tmp| {
        std::fs::write(tmp, text).map_err(|e| flowlight_host::output::OutputError::Io {
            path: path.to_owned(),
            source: e,
        })
    })
    .map_err(|e| e.to_string())
}

pub(crate) fn write_tables(
    suite: &Suite,
    runs: &[Run],
    summary: &[SummaryRow],
) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    let mut csv = String::from(
        "scene,method,plugin,params,budget_s,seed,wall_s,spp,relmse,rmse,luminance_ratio,reference_floor,invalid_samples,non_finite_pixels,biased\n",
    );
    for r in runs {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:.6},{:.3},{:.6e},{:.6e},{:.6},{},{},{},{}",
            csv_field(&r.scene),
            csv_field(&r.method),
            csv_field(&r.plugin),
            csv_field(&r.params),
            r.budget,
            r.seed,
            r.wall,
            r.spp,
            r.errors.relmse,
            r.errors.rmse,
            r.errors.luminance_ratio,
            r.errors
                .reference_floor
                .map(|f| format!("{f:.6e}"))
                .unwrap_or_default(),
            r.invalid_samples,
            r.errors.non_finite,
            r.biased
        );
    }
    let p = suite.out.join("results.csv");
    write_text(&p, &csv)?;
    files.push(p);

    let mut csv = String::from("scene,method,budget_s,seed,layer,relmse,rmse,luminance_ratio\n");
    for r in runs {
        for (k, e) in &r.layers {
            let _ = writeln!(
                csv,
                "{},{},{},{},{k},{:.6e},{:.6e},{:.6}",
                csv_field(&r.scene),
                csv_field(&r.method),
                r.budget,
                r.seed,
                e.relmse,
                e.rmse,
                e.luminance_ratio
            );
        }
    }
    let p = suite.out.join("layers.csv");
    write_text(&p, &csv)?;
    files.push(p);

    let mut csv = String::from(
        "scene,method,budget_s,runs,wall_s,spp,relmse,rmse,luminance_ratio,efficiency,relative_efficiency,biased\n",
    );
    let mut md = format!(
        "Efficiency = 1 / (relMSE × wall time), means over seeds {:?}; relative to `{}` at the same budget. \
         A method marked (biased) converges to the image only as it goes on (VCM's shrinking radius).\n\n\
         | scene | method | budget (s) | wall (s) | spp | relMSE | RMSE | lum. ratio | efficiency | vs `{}` |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        suite.seeds, suite.baseline, suite.baseline
    );
    for r in summary {
        let _ = writeln!(
            csv,
            "{},{},{},{},{:.6},{:.3},{:.6e},{:.6e},{:.6},{:.6e},{:.4},{}",
            csv_field(&r.scene),
            csv_field(&r.method),
            r.budget,
            r.runs,
            r.wall,
            r.spp,
            r.relmse,
            r.rmse,
            r.luminance_ratio,
            r.efficiency,
            r.relative_efficiency,
            r.biased
        );
        let _ = writeln!(
            md,
            "| {} | {}{} | {} | {:.2} | {:.1} | {:.3e} | {:.3e} | {:.3} | {:.3e} | {:.2} |",
            r.scene,
            r.method,
            if r.biased { " (biased)" } else { "" },
            r.budget,
            r.wall,
            r.spp,
            r.relmse,
            r.rmse,
            r.luminance_ratio,
            r.efficiency,
            r.relative_efficiency
        );
    }
    let p = suite.out.join("summary.csv");
    write_text(&p, &csv)?;
    files.push(p);
    let p = suite.out.join("summary.md");
    write_text(&p, &md)?;
    files.push(p);
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_host::metrics::Errors;
    #[test]
    fn summary_means_and_relative_efficiency() {
        let run = |method: &str, seed: u64, relmse: f64, wall: f64| Run {
            scene: "s".into(),
            method: method.into(),
            plugin: "p".into(),
            params: String::new(),
            budget: 1.0,
            seed,
            wall,
            spp: 1.0,
            errors: Errors {
                relmse,
                ..Default::default()
            },
            invalid_samples: 0,
            biased: method == "fast",
            layers: vec![],
        };
        let runs = vec![
            run("base", 1, 0.1, 1.0),
            run("base", 2, 0.3, 1.0),
            run("fast", 1, 0.05, 1.0),
            run("fast", 2, 0.05, 1.0),
        ];
        let s = summarise(&runs, "base");
        assert_eq!(s.len(), 2);
        assert!((s[0].relmse - 0.2).abs() < 1e-12);
        assert!((s[0].relative_efficiency - 1.0).abs() < 1e-12);
        assert!((s[1].relative_efficiency - 4.0).abs() < 1e-9);
        // A biased method's rows say so.
        assert_eq!((s[0].biased, s[1].biased), (false, true));
    }
}
