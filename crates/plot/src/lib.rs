//! Figures for scbg: bird's-eye views of scenes ([`render_scene`]) and simple charts.
//!
//! Text uses DejaVu Sans Mono, bundled into the binary and registered with plotters'
//! `ab_glyph` backend, so no system font is needed. Images are drawn into memory and written
//! as PNG through a temporary file renamed into place.
//!
//! **Architecture invariant:** takes plain values ([`Scene`], numbers); knows nothing about
//! file formats, features or models.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};
use scbg_scene::{ObjectType, Scene};

static FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSansMono.ttf");
static REGISTER: Once = Once::new();

fn ensure_font() {
    REGISTER.call_once(|| {
        // The bundled font is known-good; failure here would be a build defect.
        if register_font("sans-serif", FontStyle::Normal, FONT).is_err() {
            panic!("bundled font failed to load");
        }
    });
}

/// An error drawing or writing a figure; names the output file.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("drawing failed: {message} ({})", path.display())]
    Draw { path: PathBuf, message: String },
    #[error("{error}: {}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
}

/// What to draw over the scene.
#[derive(Debug, Clone, Default)]
pub struct RenderOptions {
    /// Image width and height, pixels.
    pub size_px: u32,
    /// Track indices of an interacting pair (A, B) to highlight.
    pub pair: Option<(usize, usize)>,
    /// Extra trajectories in the world frame, with labels (e.g. generated futures).
    pub overlays: Vec<(String, Vec<(f64, f64)>)>,
    /// Title; the scenario id when empty.
    pub title: String,
}

fn type_color(t: ObjectType) -> RGBColor {
    match t {
        ObjectType::Vehicle => RGBColor(40, 90, 200),
        ObjectType::Pedestrian => RGBColor(30, 150, 60),
        ObjectType::Cyclist => RGBColor(230, 130, 20),
        ObjectType::Other | ObjectType::Unset => RGBColor(120, 120, 120),
    }
}

/// Writes an RGB buffer as PNG via a temp file and rename.
pub fn write_png(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<(), PlotError> {
    let io = |error| PlotError::Io {
        path: path.to_path_buf(),
        error,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    image::write_buffer_with_format(
        &mut std::io::BufWriter::new(tmp.as_file_mut()),
        rgb,
        width,
        height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| io(std::io::Error::other(e)))?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// Draws with plotters into an RGB buffer, then writes it as PNG.
pub fn draw_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(
        DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error + '_>>,
) -> Result<(), PlotError> {
    ensure_font();
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        draw(root).map_err(|e| PlotError::Draw {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    }
    write_png(path, &buf, w, h)
}

/// Renders a bird's-eye view: map (lanes grey, road lines, edges black, crosswalks),
/// every track's valid positions coloured by type with its box at the current step, the
/// interacting pair highlighted (A red, B magenta), and overlays.
pub fn render_scene(scene: &Scene, path: &Path, options: &RenderOptions) -> Result<(), PlotError> {
    let size = options.size_px.max(200);
    let now = scene.current_step;
    // View: centred on the pair (or the SDC, or the first valid track) at the current step.
    let centre_tracks: Vec<usize> = match options.pair {
        Some((a, b)) => vec![a, b],
        None => scene.sdc_track_index.into_iter().collect(),
    };
    let mut pts: Vec<(f64, f64)> = centre_tracks
        .iter()
        .filter_map(|&i| scene.tracks.get(i))
        .flat_map(|t| t.states.iter().filter(|s| s.valid).map(|s| (s.x_m, s.y_m)))
        .collect();
    if pts.is_empty() {
        pts = scene
            .tracks
            .iter()
            .filter_map(|t| t.states.get(now).filter(|s| s.valid))
            .map(|s| (s.x_m, s.y_m))
            .collect();
    }
    if pts.is_empty() {
        pts = scene
            .map
            .all_points()
            .map(|p| (p.x_m, p.y_m))
            .take(1)
            .collect();
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if pts.is_empty() {
        (x0, x1, y0, y1) = (-50.0, 50.0, -50.0, 50.0);
    }
    let half = ((x1 - x0).max(y1 - y0) / 2.0 + 20.0).max(40.0);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let title = if options.title.is_empty() {
        format!("scenario {}", scene.scenario_id)
    } else {
        options.title.clone()
    };

    draw_png(path, (size, size), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(40)
            .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style(("sans-serif", 11))
            .draw()?;
        let m = &scene.map;
        let line =
            |pts: &[scbg_scene::MapPoint]| pts.iter().map(|p| (p.x_m, p.y_m)).collect::<Vec<_>>();
        for c in m
            .crosswalks
            .iter()
            .map(|c| &c.polygon)
            .chain(m.speed_bumps.iter().map(|c| &c.polygon))
            .chain(m.driveways.iter().map(|c| &c.polygon))
        {
            chart.draw_series(std::iter::once(Polygon::new(
                line(c),
                RGBColor(225, 225, 200).filled(),
            )))?;
        }
        for l in &m.lanes {
            chart.draw_series(std::iter::once(PathElement::new(
                line(&l.polyline),
                RGBColor(190, 190, 190).stroke_width(1),
            )))?;
        }
        for l in &m.road_lines {
            chart.draw_series(std::iter::once(PathElement::new(
                line(&l.polyline),
                RGBColor(200, 170, 60).stroke_width(1),
            )))?;
        }
        for e in &m.road_edges {
            chart.draw_series(std::iter::once(PathElement::new(
                line(&e.polyline),
                BLACK.stroke_width(2),
            )))?;
        }
        for s in &m.stop_signs {
            chart.draw_series(std::iter::once(Circle::new(
                (s.position.x_m, s.position.y_m),
                4,
                RED.filled(),
            )))?;
        }
        let pair_color = |i: usize| match options.pair {
            Some((a, _)) if a == i => Some(RGBColor(220, 20, 30)),
            Some((_, b)) if b == i => Some(RGBColor(200, 0, 200)),
            _ => None,
        };
        for (i, t) in scene.tracks.iter().enumerate() {
            let highlight = pair_color(i);
            let color = highlight.unwrap_or_else(|| type_color(t.object_type));
            let width = if highlight.is_some() { 3 } else { 1 };
            let hist: Vec<(f64, f64)> = t.states[..=now.min(t.states.len() - 1)]
                .iter()
                .filter(|s| s.valid)
                .map(|s| (s.x_m, s.y_m))
                .collect();
            let fut: Vec<(f64, f64)> = t
                .states
                .iter()
                .skip(now + 1)
                .filter(|s| s.valid)
                .map(|s| (s.x_m, s.y_m))
                .collect();
            if hist.len() > 1 {
                chart.draw_series(std::iter::once(PathElement::new(
                    hist,
                    color.stroke_width(width),
                )))?;
            }
            if fut.len() > 1 {
                chart.draw_series(std::iter::once(PathElement::new(
                    fut,
                    color.mix(0.45).stroke_width(width),
                )))?;
            }
            if let Some(s) = t.states.get(now).filter(|s| s.valid) {
                let (sin, cos) = f64::from(s.heading_rad).sin_cos();
                let (hl, hw) = (f64::from(s.length_m) / 2.0, f64::from(s.width_m) / 2.0);
                let corner = |a: f64, b: f64| {
                    (
                        s.x_m + a * hl * cos - b * hw * sin,
                        s.y_m + a * hl * sin + b * hw * cos,
                    )
                };
                let poly = vec![
                    corner(1.0, 1.0),
                    corner(1.0, -1.0),
                    corner(-1.0, -1.0),
                    corner(-1.0, 1.0),
                ];
                chart.draw_series(std::iter::once(Polygon::new(poly, color.filled())))?;
            }
        }
        let palette = [
            RGBColor(0, 160, 160),
            RGBColor(120, 60, 200),
            RGBColor(240, 120, 0),
            RGBColor(0, 120, 0),
            RGBColor(160, 0, 60),
        ];
        for (k, (label, traj)) in options.overlays.iter().enumerate() {
            let c = palette[k % palette.len()];
            chart
                .draw_series(std::iter::once(PathElement::new(
                    traj.clone(),
                    c.stroke_width(2),
                )))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2))
                });
        }
        if !options.overlays.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .draw()?;
        }
        let legend = "vehicle blue · pedestrian green · cyclist orange · A red · B magenta";
        root.draw(&Text::new(
            legend,
            (50, size as i32 - 14),
            ("sans-serif", 11).into_font().color(&BLACK),
        ))?;
        root.present()?;
        Ok(())
    })
}

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
    let fin: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let ((x0, x1), (y0, y1)) = bounds(fin.iter().copied());
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
        chart.draw_series(
            fin.iter()
                .map(|&(x, y)| Circle::new((x, y), 2, RGBColor(40, 90, 200).mix(0.5).filled())),
        )?;
        root.present()?;
        Ok(())
    })
}

/// One line of a [`line_chart`]: points and an optional ± band (same length).
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
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

fn bounds(points: impl Iterator<Item = (f64, f64)>) -> ((f64, f64), (f64, f64)) {
    let (x0, x1, y0, y1) = points.filter(|(x, y)| x.is_finite() && y.is_finite()).fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), (x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    let pad = |a: f64, b: f64| {
        if !a.is_finite() || !b.is_finite() {
            (-1.0, 1.0)
        } else if b - a < 1e-9 {
            (a - 1.0, b + 1.0)
        } else {
            (a - 0.05 * (b - a), b + 0.05 * (b - a))
        }
    };
    (pad(x0, x1), pad(y0, y1))
}

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
    pub label: String,
    pub rgb: (u8, u8, u8),
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
    use scbg_scene::{AgentState, Lane, MapPoint, Track};

    #[test]
    fn renders_a_png_with_the_bundled_font() {
        let st = |x: f64| AgentState {
            x_m: x,
            valid: true,
            length_m: 4.5,
            width_m: 2.0,
            ..Default::default()
        };
        let scene = Scene {
            scenario_id: "plot-test".into(),
            timestamps_secs: vec![0.0, 0.1, 0.2],
            current_step: 1,
            tracks: vec![
                Track {
                    id: 1,
                    object_type: ObjectType::Vehicle,
                    states: vec![st(0.0), st(1.0), st(2.0)],
                },
                Track {
                    id: 2,
                    object_type: ObjectType::Vehicle,
                    states: vec![st(10.0), st(11.0), st(12.0)],
                },
            ],
            map: scbg_scene::Map {
                lanes: vec![Lane {
                    id: 1,
                    polyline: vec![
                        MapPoint::default(),
                        MapPoint {
                            x_m: 20.0,
                            ..Default::default()
                        },
                    ],
                    ..Default::default()
                }],
                ..Default::default()
            },
            ..Default::default()
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.png");
        render_scene(
            &scene,
            &path,
            &RenderOptions {
                size_px: 300,
                pair: Some((0, 1)),
                ..Default::default()
            },
        )
        .unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (300, 300));
        // Something besides the white background was drawn.
        assert!(img.to_rgb8().pixels().any(|p| p.0 == [220, 20, 30]));
    }

    #[test]
    fn histogram_and_scatter_png() {
        let dir = tempfile::tempdir().unwrap();
        let values: Vec<f64> = (0..200)
            .map(|i| ((i * 37) % 100) as f64 / 10.0 - 5.0)
            .collect();
        histogram(&values, 20, "ψ (m/s)", &dir.path().join("h.png")).unwrap();
        let img = image::open(dir.path().join("h.png")).unwrap().to_rgb8();
        assert!(img.pixels().any(|p| p.0 == [40, 90, 200]));
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
    fn line_chart_and_trajectories_png() {
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
        let img = image::open(dir.path().join("l.png")).unwrap().to_rgb8();
        assert!(img.pixels().any(|p| p.0 == [40, 90, 200]));
        assert!(img.pixels().any(|p| p.0 == [240, 120, 0]));
        // Empty input draws axes instead of failing.
        line_chart(&[], "q", "ψ", "empty", &dir.path().join("e.png")).unwrap();
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
        let img = image::open(dir.path().join("t.png")).unwrap().to_rgb8();
        assert!(img.pixels().any(|p| p.0 == [220, 20, 30]));
        assert!(img.pixels().any(|p| p.0 == [190, 190, 190]));
    }
}
