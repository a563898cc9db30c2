//! SVG plots of a suite's results (log-log error against wall time), drawn with `plotters`.

use crate::report::SummaryRow;
use crate::run::Run;
use std::collections::BTreeMap;
use std::path::Path;

fn log_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    // Pad by a factor so points do not sit on the frame; widen a degenerate range.
    let (lo, hi) = if hi / lo < 1.5 {
        (lo / 1.5, hi * 1.5)
    } else {
        (lo / 1.15, hi * 1.15)
    };
    Some((lo, hi))
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: cannot draw the plot: {e}", path.display())
}

/// Log-log relMSE and RMSE against wall time for one scene, one line per method.
pub fn plot_scene(path: &Path, scene: &str, summary: &[SummaryRow]) -> Result<(), String> {
    use plotters::prelude::*;
    let rows: Vec<&SummaryRow> = summary.iter().filter(|r| r.scene == scene).collect();
    let mut methods: Vec<&str> = Vec::new();
    for r in &rows {
        if !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| plot_err(path, e))?;
    }
    let root = SVGBackend::new(path, (1100, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let (left, right) = root.split_horizontally(550);
    type Metric<'a> = (&'a str, fn(&SummaryRow) -> f64);
    let metrics: [Metric; 2] = [("relMSE", |r| r.relmse), ("RMSE", |r| r.rmse)];
    for (area, (name, f)) in [left, right].iter().zip(metrics) {
        let xr = log_range(rows.iter().map(|r| r.wall));
        let yr = log_range(rows.iter().map(|r| f(r)));
        let (Some((x0, x1)), Some((y0, y1))) = (xr, yr) else {
            area.titled(&format!("{scene}: no finite {name}"), ("sans-serif", 18))
                .map_err(|e| plot_err(path, e))?;
            continue;
        };
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{scene}: {name} vs wall time"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| plot_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc("wall time (s)")
            .y_desc(name)
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .x_label_formatter(&|v| format!("{v:.2}"))
            .draw()
            .map_err(|e| plot_err(path, e))?;
        for (i, m) in methods.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.method == *m)
                .map(|r| (r.wall, f(r)))
                .filter(|(x, y)| *x > 0.0 && *y > 0.0 && y.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| plot_err(path, e))?
                .label(*m)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| plot_err(path, e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| plot_err(path, e))?;
    }
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

/// relMSE per lighting layer at the largest budget, one line per method that wrote layers.
pub fn plot_layers(path: &Path, scene: &str, runs: &[Run]) -> Result<(), String> {
    use plotters::prelude::*;
    let runs: Vec<&Run> = runs
        .iter()
        .filter(|r| r.scene == scene && !r.layers.is_empty())
        .collect();
    let budget = runs.iter().map(|r| r.budget).fold(0.0, f64::max);
    let mut methods: Vec<&str> = Vec::new();
    for r in &runs {
        if !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    // (method, layer) -> mean relMSE over seeds at the largest budget.
    let mut series: Vec<(&str, Vec<(f64, f64)>)> = Vec::new();
    for m in &methods {
        let mut per_layer: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
        for r in runs.iter().filter(|r| r.method == *m && r.budget == budget) {
            for (k, e) in &r.layers {
                let s = per_layer.entry(*k).or_default();
                s.0 += e.relmse;
                s.1 += 1;
            }
        }
        let pts = per_layer
            .into_iter()
            .map(|(k, (s, n))| (k as f64, s / n as f64))
            .filter(|(_, y)| *y > 0.0 && y.is_finite())
            .collect();
        series.push((m, pts));
    }
    let kmax = series
        .iter()
        .flat_map(|(_, p)| p.iter().map(|q| q.0))
        .fold(0.0, f64::max);
    let root = SVGBackend::new(path, (700, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let Some((y0, y1)) = log_range(series.iter().flat_map(|(_, p)| p.iter().map(|q| q.1))) else {
        root.titled(
            &format!("{scene}: no finite layer errors"),
            ("sans-serif", 18),
        )
        .map_err(|e| plot_err(path, e))?;
        root.present().map_err(|e| plot_err(path, e))?;
        return Ok(());
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{scene}: relMSE per lighting layer at {budget} s"),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..kmax + 0.5, (y0..y1).log_scale())
        .map_err(|e| plot_err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("lighting layer k (paths of virtual length k + 1)")
        .y_desc("relMSE")
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .draw()
        .map_err(|e| plot_err(path, e))?;
    for (i, (m, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
            .map_err(|e| plot_err(path, e))?
            .label(*m)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
            .map_err(|e| plot_err(path, e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_are_written() {
        let dir = std::env::temp_dir().join(format!("flowlight-plot-{}", std::process::id()));
        let row = |m: &str, wall: f64, e: f64| SummaryRow {
            scene: "s".into(),
            method: m.into(),
            budget: wall,
            wall,
            spp: 1.0,
            relmse: e,
            rmse: e.sqrt(),
            luminance_ratio: 1.0,
            efficiency: 1.0 / (e * wall),
            relative_efficiency: 1.0,
            runs: 1,
            biased: false,
        };
        let rows = vec![
            row("a", 0.5, 0.1),
            row("a", 1.0, 0.05),
            row("b", 0.5, 0.2),
            row("b", 1.0, 0.1),
        ];
        let p = dir.join("s.svg");
        plot_scene(&p, "s", &rows).unwrap();
        let svg = std::fs::read_to_string(&p).unwrap();
        assert!(svg.contains("<svg") && svg.contains("relMSE"));
        // Nothing finite to draw must not fail either.
        plot_scene(&dir.join("empty.svg"), "none", &rows).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
