//! PNG line plots (plotters): frame time per frame, and time against scene size.
//!
//! Text uses Noto Sans Regular embedded in the binary (crate `ttf-noto-sans`, Apache-2.0),
//! registered with plotters' `ab_glyph` backend at first use: no system font is assumed.

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;

/// Plot font family name under which the embedded font is registered.
const FONT: &str = "sans-serif";

/// One line of a plot.
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points (x, y); y must be positive for a log axis (others are left out).
    pub points: Vec<(f64, f64)>,
    /// Drawn dashed and grey (the oracle).
    pub dashed: bool,
}

/// One chart of a figure.
pub struct Panel {
    /// Title above the chart.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// The lines.
    pub series: Vec<Series>,
}

/// Colors of successive series (colorblind-friendly Okabe–Ito order).
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(240, 228, 66),
];

fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FONT, FontStyle::Normal, ttf_noto_sans::REGULAR).is_ok());
    if !ok {
        bail!("the embedded plot font cannot be loaded");
    }
    Ok(())
}

/// Draws `panels` stacked vertically into a PNG at `path`, each with a log y axis.
///
/// # Errors
/// Drawing and file errors, naming the file.
pub fn draw(path: &Path, panels: &[Panel]) -> Result<()> {
    register_font()?;
    let panel_height = 480u32;
    let size = (1100u32, panel_height * panels.len().max(1) as u32);
    let fail = |e: &dyn std::fmt::Display| anyhow!("cannot draw plot '{}': {e}", path.display());
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (panel, area) in panels.iter().zip(&areas) {
        draw_panel(area, panel).map_err(|e| fail(&e))?;
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type DrawResult<'a> = std::result::Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

fn draw_panel<'a>(area: &Area<'a>, panel: &Panel) -> DrawResult<'a> {
    let points = || {
        panel
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.1 > 0.0 && p.1.is_finite())
    };
    let (mut x0, mut x1) = points().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (mut y0, mut y1) = points().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    if !(x0.is_finite() && x1.is_finite()) {
        (x0, x1) = (0.0, 1.0);
    }
    if !(y0.is_finite() && y1.is_finite()) {
        (y0, y1) = (0.1, 1.0);
    }
    // A log axis over less than a decade gets no labelled ticks: linear there.
    let log_x = panel.log_x && x0 > 0.0 && x1 / x0 >= 10.0;
    if log_x {
        x0 = x0.max(1e-9);
        (x0, x1) = (x0 / 1.5, x1.max(x0) * 1.5);
    } else if panel.log_x {
        let pad = (x1 - x0).max(x1.abs() * 0.1).max(1e-9) * 0.1;
        (x0, x1) = (x0 - pad, x1 + pad);
    } else if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    // Room below, and above for the legend (about 22 px a line of a ~370 px high plot), on
    // the log axis.
    let (y0, y1) = (y0 / 1.3, y1.max(y0) * 1.3);
    let legend_share = ((panel.series.len() as f64 + 1.0) * 22.0 / 370.0).min(0.6);
    let y1 = (y0.ln() + (y1.ln() - y0.ln()) / (1.0 - legend_share)).exp();

    let mut builder = ChartBuilder::on(area);
    builder
        .caption(&panel.title, (FONT, 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70);
    let y_desc = &panel.y_label;
    let x_desc = &panel.x_label;
    macro_rules! finish {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_label_formatter(&|x: &f64| axis_number(*x))
                .y_label_formatter(&|y: &f64| axis_number(*y))
                .x_desc(x_desc)
                .y_desc(y_desc)
                .label_style((FONT, 14))
                .axis_desc_style((FONT, 16))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()?;
            for (i, s) in panel.series.iter().enumerate() {
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.1 > 0.0 && p.1.is_finite() && p.0.is_finite())
                    .collect();
                let color = if s.dashed {
                    RGBColor(90, 90, 90)
                } else {
                    PALETTE[i % PALETTE.len()]
                };
                let style = color.stroke_width(2);
                if s.dashed {
                    chart.draw_series(DashedLineSeries::new(pts.clone(), 8, 5, style))?;
                } else {
                    chart.draw_series(LineSeries::new(pts.clone(), style))?;
                }
                let marker = pts.len() <= 40;
                if marker {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
                }
                // An empty series carries the legend entry.
                chart
                    .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
                    .label(&s.name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font((FONT, 14))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(160, 160, 160))
                .draw()?;
        }};
    }
    if log_x {
        finish!(builder.build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?);
    } else {
        finish!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale())?);
    }
    Ok(())
}

/// An axis label: integers plainly (with a k/M/G suffix when large), small values with the
/// digits they need.
fn axis_number(v: f64) -> String {
    let a = v.abs();
    if a >= 1e9 {
        format!("{}G", trim(v / 1e9))
    } else if a >= 1e6 {
        format!("{}M", trim(v / 1e6))
    } else if a >= 1e4 {
        format!("{}k", trim(v / 1e3))
    } else {
        trim(v)
    }
}

fn trim(v: f64) -> String {
    let s = if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    };
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_numbers() {
        assert_eq!(axis_number(3.0), "3");
        assert_eq!(axis_number(2.5), "2.5");
        assert_eq!(axis_number(0.125), "0.125");
        assert_eq!(axis_number(1_048_352.0), "1M");
        assert_eq!(axis_number(2_500_000.0), "2.5M");
        assert_eq!(axis_number(40_000.0), "40k");
    }

    #[test]
    fn plots_render_text_with_the_embedded_font() {
        let dir = std::env::temp_dir().join(format!("occult-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.png");
        let panel = Panel {
            title: "title".into(),
            x_label: "frame".into(),
            y_label: "ms".into(),
            log_x: false,
            series: vec![
                Series {
                    name: "a".into(),
                    points: vec![(0.0, 1.0), (1.0, 2.0)],
                    dashed: false,
                },
                Series {
                    name: "oracle".into(),
                    points: vec![(0.0, 0.5), (1.0, 0.0)],
                    dashed: true,
                },
                Series {
                    name: "empty".into(),
                    points: vec![],
                    dashed: false,
                },
            ],
        };
        draw(&path, &[panel]).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (1100, 480));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
