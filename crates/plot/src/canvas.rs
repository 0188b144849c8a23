//! What every figure shares: the bundled font, the error type, drawing into memory and
//! writing PNG files, and axis bounds.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

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
    /// plotters failed while drawing.
    #[error("drawing failed: {message} ({})", path.display())]
    Draw {
        /// The output file.
        path: PathBuf,
        /// plotters' error message.
        message: String,
    },
    /// Encoding or writing the PNG failed.
    #[error("{error}: {}", path.display())]
    Io {
        /// The output file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
}

/// Writes an RGB buffer as PNG, atomically (temporary file + rename, by `scbg-base`).
/// `rgb` holds `width · height` pixels, row-major from the top left, 3 bytes each.
pub fn write_png(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<(), PlotError> {
    scbg_base::atomic::write_with(path, |file| {
        let mut out = BufWriter::new(file);
        image::write_buffer_with_format(
            &mut out,
            rgb,
            width,
            height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(std::io::Error::other)?;
        out.flush()
    })
    .map_err(|error| PlotError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// Draws with plotters into a white `(width, height)` pixel RGB buffer (the bundled font
/// registered), then writes it as PNG with [`write_png`]. An error from `draw` becomes
/// [`PlotError::Draw`].
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

/// Padded axis ranges ((x0, x1), (y0, y1)) around the finite points; (−1, 1) when none.
pub(crate) fn bounds(points: impl Iterator<Item = (f64, f64)>) -> ((f64, f64), (f64, f64)) {
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
