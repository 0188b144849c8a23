//! What every figure shares: the bundled font, the error type, drawing into memory and
//! writing PNG files, and axis bounds.

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
    let io = |error: std::io::Error| PlotError::Io {
        path: path.to_path_buf(),
        error,
    };
    // Encoded in memory (a figure is a few hundred kB), then written in one piece.
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut writer| {
            writer.write_image_data(rgb)?;
            writer.finish()
        })
        .map_err(|e| io(e.into()))?;
    scbg_base::atomic::write(path, &bytes).map_err(|e| io(e.into()))
}

/// A decoded image: `width · height` pixels, row-major from the top left, 4 bytes (RGBA) each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rgba8 {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pixels, RGBA, 8 bits per channel.
    pub rgba: Vec<u8>,
}

impl Rgba8 {
    /// Every pixel, row by row.
    pub fn pixels(&self) -> impl Iterator<Item = [u8; 4]> + '_ {
        self.rgba.chunks_exact(4).map(|p| [p[0], p[1], p[2], p[3]])
    }

    /// Whether some pixel has this colour (alpha ignored).
    pub fn has_rgb(&self, rgb: [u8; 3]) -> bool {
        self.pixels().any(|p| p[..3] == rgb)
    }
}

/// Reads a PNG of any colour type and bit depth (ours, a browser's screenshot) as 8-bit RGBA.
pub fn read_png(path: &Path) -> Result<Rgba8, PlotError> {
    let io = |error: std::io::Error| PlotError::Io {
        path: path.to_path_buf(),
        error,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().map_err(|e| io(e.into()))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| io(std::io::Error::other("image too large")))?;
    let mut buf = vec![0; size];
    let frame = reader.next_frame(&mut buf).map_err(|e| io(e.into()))?;
    buf.truncate(frame.buffer_size());
    let rgba = match frame.color_type {
        png::ColorType::Rgba => buf,
        png::ColorType::Rgb => buf
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect(),
        png::ColorType::GrayscaleAlpha => buf
            .chunks_exact(2)
            .flat_map(|p| [p[0], p[0], p[0], p[1]])
            .collect(),
        // Indexed is expanded to RGB(A) by `normalize_to_color8`.
        png::ColorType::Grayscale | png::ColorType::Indexed => {
            buf.iter().flat_map(|&g| [g, g, g, 255]).collect()
        }
    };
    Ok(Rgba8 {
        width: frame.width,
        height: frame.height,
        rgba,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_and_a_corrupt_file_names_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let rgb: Vec<u8> = (0..2 * 3 * 3).map(|i| (i * 13) as u8).collect();
        write_png(&path, &rgb, 3, 2).unwrap();
        let img = read_png(&path).unwrap();
        assert_eq!((img.width, img.height), (3, 2));
        let back: Vec<u8> = img.pixels().flat_map(|p| [p[0], p[1], p[2]]).collect();
        assert_eq!(back, rgb);
        assert!(img.pixels().all(|p| p[3] == 255));

        std::fs::write(&path, b"\x89PNG\r\n\x1a\nnot a png").unwrap();
        let err = read_png(&path).unwrap_err().to_string();
        assert!(err.contains("p.png"), "{err}");
        // A buffer of the wrong size is an error, and the earlier file stays as it was.
        assert!(write_png(&path, &rgb[..5], 3, 2).is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"\x89PNG\r\n\x1a\nnot a png");
    }
}
