//! Plotting helpers: the embedded font and a common error type.
//!
//! Text is drawn with plotters' `ab_glyph` backend and the DejaVu Sans font committed
//! in `host-sim/assets/` (licence alongside), so plots need no system font.

use std::sync::OnceLock;

use plotters::style::FontStyle;

/// Font family name under which the embedded font is registered; use it in
/// text styles (`(FONT, 16).into_font()`).
pub const FONT: &str = "sans-serif";

static FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
static REGISTERED: OnceLock<bool> = OnceLock::new();

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The embedded font could not be loaded (a corrupted build).
    #[error("the embedded plot font could not be loaded")]
    Font,
    /// Drawing or writing the image failed.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The image file.
        path: String,
        /// The backend's message.
        message: String,
    },
}

/// Registers the embedded font for every style under [`FONT`] (idempotent).
pub fn register_font() -> Result<(), PlotError> {
    let ok = *REGISTERED.get_or_init(|| {
        [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ]
        .into_iter()
        .all(|style| plotters::style::register_font(FONT, style, FONT_BYTES).is_ok())
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// Wraps a plotters error with the image path.
pub fn draw_error(path: &std::path::Path, e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Draws the legend of `chart` (every labelled series), boxed in its upper right
/// corner, the way every figure of the simulator shows it.
pub fn draw_legend<'a, DB, CT>(
    chart: &mut plotters::chart::ChartContext<'a, DB, CT>,
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: plotters::prelude::DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    use plotters::prelude::{SeriesLabelPosition, BLACK, WHITE};
    use plotters::style::Color;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 16))
        .draw()
}
