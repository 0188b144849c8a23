//! [`trajectories`]: labelled polylines over a grey background (e.g. the road).

use std::path::Path;

use plotters::prelude::*;

use crate::canvas::{PlotError, bounds, draw_png};

/// The part of segment `p`–`q` inside the box `(x0, x1, y0, y1)` (Liang–Barsky).
fn clip_segment(
    p: (f64, f64),
    q: (f64, f64),
    (x0, x1, y0, y1): (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (pk, qk) in [
        (-dx, p.0 - x0),
        (dx, x1 - p.0),
        (-dy, p.1 - y0),
        (dy, y1 - p.1),
    ] {
        if pk == 0.0 {
            if qk < 0.0 {
                return None;
            }
        } else {
            let r = qk / pk;
            if pk < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((
        (p.0 + t0 * dx, p.1 + t0 * dy),
        (p.0 + t1 * dx, p.1 + t1 * dy),
    ))
}

/// One labelled polyline of [`trajectories`]; `rgb` is its colour.
#[derive(Debug, Clone)]
pub struct Line {
    /// Legend text.
    pub label: String,
    /// Colour, (red, green, blue).
    pub rgb: (u8, u8, u8),
    /// (x, y) points (metres), in order; the first is marked with a dot.
    pub points: Vec<(f64, f64)>,
}

/// Trajectories over grey background polylines (e.g. the road), equal axis scales, with a
/// legend (paper Fig. 5a). Colours are RGB triples.
pub fn trajectories(
    background: &[Vec<(f64, f64)>],
    lines: &[Line],
    title: &str,
    path: &Path,
) -> Result<(), PlotError> {
    let ((x0, x1), (y0, y1)) = bounds(lines.iter().flat_map(|l| l.points.iter().copied()));
    // Square view around the trajectories, at least 40 m wide.
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let half = ((x1 - x0).max(y1 - y0) / 2.0 + 10.0).max(20.0);
    let size = 800u32;
    draw_png(path, (size, size), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .label_style(("sans-serif", 14))
            .draw()?;
        let bbox = (cx - half, cx + half, cy - half, cy + half);
        for poly in background {
            for seg in poly.windows(2) {
                if let Some((p, q)) = clip_segment(seg[0], seg[1], bbox) {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![p, q],
                        RGBColor(190, 190, 190).stroke_width(1),
                    )))?;
                }
            }
        }
        for Line {
            label,
            rgb: (r, g, b),
            points: pts,
        } in lines
        {
            let c = RGBColor(*r, *g, *b);
            chart
                .draw_series(std::iter::once(PathElement::new(
                    pts.clone(),
                    c.stroke_width(2),
                )))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2))
                });
            if let Some(&start) = pts.first() {
                chart.draw_series(std::iter::once(Circle::new(start, 4, c.filled())))?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trajectories_png() {
        let dir = tempfile::tempdir().unwrap();
        trajectories(
            &[vec![(-50.0, 0.0), (50.0, 0.0)]],
            &[
                Line {
                    label: "A".into(),
                    rgb: (220, 20, 30),
                    points: vec![(0.0, 0.0), (30.0, 0.0)],
                },
                Line {
                    label: "B".into(),
                    rgb: (40, 90, 200),
                    points: vec![(0.0, 5.0), (20.0, 2.0)],
                },
            ],
            "t",
            &dir.path().join("t.png"),
        )
        .unwrap();
        let img = crate::read_png(&dir.path().join("t.png")).unwrap();
        assert!(img.has_rgb([220, 20, 30]));
        assert!(img.has_rgb([190, 190, 190]));
    }
}
