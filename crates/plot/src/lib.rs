//! Figures for scbg: bird's-eye views of scenes ([`render_scene`]) and simple charts.
//!
//! Text uses DejaVu Sans Mono, bundled into the binary and registered with plotters'
//! `ab_glyph` backend, so no system font is needed. Images are drawn into memory and written
//! as PNG through a temporary file renamed into place.
//!
//! Modules by what they draw: `scene` ([`render_scene`]), `charts` ([`histogram`],
//! [`scatter`], [`line_chart`]), `trajectories` ([`trajectories`]); `canvas` holds what they
//! share (font, [`PlotError`], [`draw_png`], [`write_png`], axis bounds).
//!
//! **Architecture invariant:** takes plain values ([`Scene`](scbg_scene::Scene), numbers);
//! knows nothing about file formats, features or models.

#![warn(missing_docs)]

mod canvas;
mod charts;
mod scene;
mod trajectories;

pub use canvas::{PlotError, Rgba8, draw_png, read_png, write_png};
pub use charts::{Series, histogram, line_chart, scatter, scatter_series};
pub use scene::{RenderOptions, render_scene};
pub use trajectories::{Line, trajectories};
