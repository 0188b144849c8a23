//! Charts of numbers: [`histogram`], [`scatter`], [`scatter_series`] and [`line_chart`] (with ± bands).

use std::path::Path;

use plotters::prelude::*;

use crate::canvas::{PlotError, bounds, draw_png};

/// A histogram of `values` with `bins` equal-width bins (paper Fig. 3 style).
pub fn histogram(values: &[f64], bins: usize, x_label: &str, path: &Path) -> Result<(), PlotError> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let (lo, hi) = finite
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if finite.is_empty() {
        (-1.0, 1.0)
    } else if hi - lo < 1e-9 {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    };
    let bins = bins.max(1);
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for v in &finite {
        counts[(((v - lo) / width) as usize).min(bins - 1)] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1);
    draw_png(path, (800, 500), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{} values", finite.len()), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(lo..hi, 0usize..top + top / 10 + 1)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc("count")
            .label_style(("sans-serif", 12))
            .draw()?;
        chart.draw_series(counts.iter().enumerate().map(|(i, &c)| {
            let x0 = lo + i as f64 * width;
            Rectangle::new([(x0, 0), (x0 + width, c)], RGBColor(40, 90, 200).filled())
        }))?;
        root.present()?;
        Ok(())
    })
}

/// A scatter of the finite (x, y) points, e.g. predicted vs labelled courtesy.
pub fn scatter(
    points: &[(f64, f64)],
    x_label: &str,
    y_label: &str,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    let one = Series {
        label: String::new(),
        points: points.to_vec(),
        band: None,
    };
    scatter_series(std::slice::from_ref(&one), x_label, y_label, title, path)
}

/// A scatter of several groups of points, one colour each, with a legend of the labelled
/// groups (e.g. learned vs true courtesy by scene family). Non-finite points are left out;
/// bands are ignored.
pub fn scatter_series(
    series: &[Series],
    x_label: &str,
    y_label: &str,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    let finite = |s: &Series| -> Vec<(f64, f64)> {
        s.points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect()
    };
    let groups: Vec<Vec<(f64, f64)>> = series.iter().map(finite).collect();
    let ((x0, x1), (y0, y1)) = bounds(groups.iter().flatten().copied());
    draw_png(path, (800, 600), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style(("sans-serif", 12))
            .draw()?;
        for (k, (s, points)) in series.iter().zip(&groups).enumerate() {
            let c = PALETTE[k % PALETTE.len()];
            let drawn = chart.draw_series(
                points
                    .iter()
                    .map(move |&(x, y)| Circle::new((x, y), 2, c.mix(0.5).filled())),
            )?;
            if !s.label.is_empty() {
                drawn
                    .label(s.label.clone())
                    .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
            }
        }
        if series.iter().any(|s| !s.label.is_empty()) {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .draw()?;
        }
        root.present()?;
        Ok(())
    })
}

/// One line of a [`line_chart`]: points and an optional ± band (same length).
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) points, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// Half-width of the band at each point (e.g. one standard deviation), drawn `y ± band`.
    pub band: Option<Vec<f64>>,
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(40, 90, 200),
    RGBColor(240, 120, 0),
    RGBColor(0, 150, 80),
    RGBColor(200, 30, 60),
    RGBColor(120, 60, 200),
    RGBColor(0, 160, 160),
];

/// Lines with optional ± bands and a legend, e.g. input quantile → achieved courtesy (paper
/// Fig. 4) or → A's expected speed (Fig. 5b).
pub fn line_chart(
    series: &[Series],
    x_label: &str,
    y_label: &str,
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    let all = series.iter().flat_map(|s| {
        s.points.iter().enumerate().flat_map(move |(i, &(x, y))| {
            let b = s
                .band
                .as_ref()
                .and_then(|b| b.get(i))
                .copied()
                .unwrap_or(0.0);
            [(x, y - b), (x, y + b)]
        })
    });
    let ((x0, x1), (y0, y1)) = bounds(all);
    draw_png(path, (800, 600), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style(("sans-serif", 12))
            .draw()?;
        for (k, s) in series.iter().enumerate() {
            let c = PALETTE[k % PALETTE.len()];
            if let Some(band) = &s.band {
                let upper = s.points.iter().zip(band).map(|(&(x, y), b)| (x, y + b));
                let lower = s
                    .points
                    .iter()
                    .zip(band)
                    .rev()
                    .map(|(&(x, y), b)| (x, y - b));
                let poly: Vec<(f64, f64)> = upper.chain(lower).collect();
                chart.draw_series(std::iter::once(Polygon::new(poly, c.mix(0.15).filled())))?;
            }
            chart
                .draw_series(LineSeries::new(s.points.clone(), c.stroke_width(2)))?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2))
                });
            chart.draw_series(
                s.points
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, c.filled())),
            )?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()?;
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_and_scatter_png() {
        let dir = tempfile::tempdir().unwrap();
        let values: Vec<f64> = (0..200)
            .map(|i| ((i * 37) % 100) as f64 / 10.0 - 5.0)
            .collect();
        histogram(&values, 20, "ψ (m/s)", &dir.path().join("h.png")).unwrap();
        let img = crate::read_png(&dir.path().join("h.png")).unwrap();
        assert!(img.has_rgb([40, 90, 200]));
        histogram(&[], 10, "empty", &dir.path().join("e.png")).unwrap();
        scatter(
            &[(0.1, 1.0), (0.9, 2.0)],
            "q",
            "ψ",
            "t",
            &dir.path().join("s.png"),
        )
        .unwrap();
    }

    #[test]
    fn line_chart_png() {
        let dir = tempfile::tempdir().unwrap();
        let series = vec![
            Series {
                label: "full".into(),
                points: vec![(0.1, -0.2), (0.5, 0.0), (0.9, 0.3)],
                band: Some(vec![0.1, 0.1, 0.2]),
            },
            Series {
                label: "flat".into(),
                points: vec![(0.1, 0.0), (0.9, 0.0)],
                band: None,
            },
        ];
        line_chart(&series, "q", "ψ", "t", &dir.path().join("l.png")).unwrap();
        let img = crate::read_png(&dir.path().join("l.png")).unwrap();
        assert!(img.has_rgb([40, 90, 200]));
        assert!(img.has_rgb([240, 120, 0]));
        // Empty input draws axes instead of failing.
        line_chart(&[], "q", "ψ", "empty", &dir.path().join("e.png")).unwrap();
    }
}
