//! Two stacked panels sharing one x axis (plotters SVG): the figures of `nanopush sweep` and
//! `nanopush simulate --plot`.

use std::path::Path;

use plotters::prelude::*;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// A line.
    Line,
    /// Circles, the paper's 'o'.
    Circle,
    /// Crosses, the paper's 'x'.
    Cross,
}

/// One series of a panel.
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Points `(x, y)`, in the panel's units.
    pub points: Vec<(f64, f64)>,
    /// How it is drawn.
    pub mark: Mark,
    /// Palette index.
    pub color: usize,
    /// Vertical bars `(x, lo, hi)` drawn with the series (e.g. the min–max of a periodic push).
    pub bars: Vec<(f64, f64, f64)>,
}

/// One panel.
pub struct Panel {
    /// y-axis label.
    pub y_desc: String,
    /// Its series.
    pub series: Vec<Series>,
}

fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = if hi > lo {
        0.06 * (hi - lo)
    } else {
        0.05 * lo.abs().max(1e-3)
    };
    (lo - pad, hi + pad)
}

/// Draws `panels` stacked top to bottom into an SVG at `path`.
pub fn stacked(path: &Path, title: &str, x_desc: &str, panels: &[Panel]) -> anyhow::Result<()> {
    let xs = panels
        .iter()
        .flat_map(|p| p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)));
    let (x0, x1) = bounds(xs);
    let root = SVGBackend::new(path, (860, 340 * panels.len() as u32 + 40)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    for (area, panel) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
        let ys = panel.series.iter().flat_map(|s| {
            s.points
                .iter()
                .map(|q| q.1)
                .chain(s.bars.iter().flat_map(|b| [b.1, b.2]))
        });
        let (y0, y1) = bounds(ys);
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(panel.y_desc.as_str())
            .y_label_formatter(&|v| format!("{v:.3}"))
            .draw()?;
        for s in &panel.series {
            let color = Palette99::pick(s.color).to_rgba();
            let pts = s.points.clone();
            let drawn = match s.mark {
                Mark::Line => chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?,
                Mark::Circle => chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 4, color.stroke_width(2))))?,
                Mark::Cross => chart.draw_series(pts.into_iter().map(|p| Cross::new(p, 4, color.stroke_width(2))))?,
            };
            let mark = s.mark;
            drawn
                .label(s.label.clone())
                .legend(move |(x, y)| -> DynElement<'static, SVGBackend, (i32, i32)> {
                    match mark {
                        Mark::Line => PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)).into_dyn(),
                        Mark::Circle => Circle::new((x + 10, y), 4, color.stroke_width(2)).into_dyn(),
                        Mark::Cross => Cross::new((x + 10, y), 4, color.stroke_width(2)).into_dyn(),
                    }
                });
            chart.draw_series(
                s.bars
                    .iter()
                    .map(|&(x, lo, hi)| PathElement::new(vec![(x, lo), (x, hi)], color.stroke_width(1))),
            )?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
