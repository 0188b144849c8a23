//! Bird's-eye renders of a [`Scene`].

use std::path::Path;

use plotters::prelude::*;
use scbg_scene::{ObjectType, Scene};

use crate::canvas::{PlotError, draw_png};

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
        let img = crate::read_png(&path).unwrap();
        assert_eq!((img.width, img.height), (300, 300));
        // Something besides the white background was drawn.
        assert!(img.has_rgb([220, 20, 30]));
    }
}
