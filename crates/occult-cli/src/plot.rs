//! PNG plots (plotters): lines (frame time per frame, time against scene size) and grouped
//! bars (a ratio per case and renderer, `occult suite`).
//!
//! Text uses Noto Sans Regular embedded in the binary (crate `ttf-noto-sans`, Apache-2.0),
//! registered with plotters' `ab_glyph` backend at first use: no system font is assumed.
//!
//! Ticks are chosen here, not by plotters: its log axis labels only powers of ten, so a range
//! within one decade got no label at all, and its linear axis puts ticks at fractions where
//! x counts frames. A log axis is labelled at 1, 10, 100…, or 1-2-5, or 1…9 per decade,
//! whichever gives at least three ticks, or else at evenly spaced round numbers
//! ([`log_ticks`]); a linear axis at round steps, whole numbers where x counts
//! ([`linear_ticks`]).

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{anyhow, bail, Result};
use plotters::coord::combinators::LogCoord;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
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
    /// X values are counts (frame numbers): ticks at whole numbers only.
    pub integer_x: bool,
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
    let panel_height = 480u32;
    let size = (1100u32, panel_height * panels.len().max(1) as u32);
    draw_stacked(path, size, panels, draw_panel)
}

/// Draws `panels` stacked vertically, one `draw_one` each, into a PNG of `size` at `path`.
///
/// # Errors
/// Drawing and file errors, naming the file.
fn draw_stacked<P>(
    path: &Path,
    size: (u32, u32),
    panels: &[P],
    draw_one: for<'a> fn(&Area<'a>, &P) -> DrawResult<'a>,
) -> Result<()> {
    if !crate::ranks::is_root() {
        return Ok(());
    }
    register_font()?;
    let fail = |e: &dyn std::fmt::Display| anyhow!("cannot draw plot '{}': {e}", path.display());
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (panel, area) in panels.iter().zip(&areas) {
        draw_one(area, panel).map_err(|e| fail(&e))?;
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

    let y_ticks = log_ticks(y0, y1);
    let x_ticks = if log_x {
        log_ticks(x0, x1)
    } else {
        linear_ticks(x0, x1, panel.integer_x)
    };

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
                .x_label_formatter(&|x: &f64| tick_label(*x))
                .y_label_formatter(&|y: &f64| tick_label(*y))
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
    let y_axis = Ticked {
        inner: LogCoord::from((y0..y1).log_scale()),
        ticks: y_ticks,
    };
    if log_x {
        let x_axis = Ticked {
            inner: LogCoord::from((x0..x1).log_scale()),
            ticks: x_ticks,
        };
        finish!(builder.build_cartesian_2d(x_axis, y_axis)?);
    } else {
        let x_axis = Ticked {
            inner: RangedCoordf64::from(x0..x1),
            ticks: x_ticks,
        };
        finish!(builder.build_cartesian_2d(x_axis, y_axis)?);
    }
    Ok(())
}

/// One group of bars (a case of the suite): a value per series, `None` where there is none.
pub struct BarGroup {
    /// Label under the group.
    pub label: String,
    /// One value per series of the panel, in its order.
    pub values: Vec<Option<f64>>,
}

/// A chart of grouped bars on a log y axis, with a horizontal line marking a reference value.
pub struct BarPanel {
    /// Title above the chart.
    pub title: String,
    /// Y axis label.
    pub y_label: String,
    /// Legend text of each series (a bar of each group).
    pub series: Vec<String>,
    /// The groups, left to right.
    pub groups: Vec<BarGroup>,
    /// Where the reference line is drawn (1 for ratios).
    pub reference: f64,
}

/// Width of the legend column of a bar chart, pixels.
const LEGEND_WIDTH: u32 = 130;

/// Draws `panels` stacked vertically into a PNG at `path`; the width grows with the number of
/// groups so that their labels do not overlap.
///
/// # Errors
/// Drawing and file errors, naming the file.
pub fn draw_bars(path: &Path, panels: &[BarPanel]) -> Result<()> {
    let groups = panels.iter().map(|p| p.groups.len()).max().unwrap_or(1) as u32;
    let size = (
        1100u32.max(140 * groups + 160 + LEGEND_WIDTH),
        520 * panels.len().max(1) as u32,
    );
    draw_stacked(path, size, panels, draw_bar_panel)
}

fn draw_bar_panel<'a>(area: &Area<'a>, panel: &BarPanel) -> DrawResult<'a> {
    let values = || {
        panel
            .groups
            .iter()
            .flat_map(|g| g.values.iter().flatten().copied())
            .chain([panel.reference])
            .filter(|v| *v > 0.0 && v.is_finite())
    };
    let y0 = values().fold(f64::INFINITY, f64::min) / 1.5;
    let y1 = values().fold(f64::NEG_INFINITY, f64::max) * 1.5;
    // The legend goes in a column of its own at the right, clear of every bar.
    let (area, legend) = area.split_horizontally(area.dim_in_pixel().0.saturating_sub(LEGEND_WIDTH));
    for (i, name) in panel.series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let y = 50 + 22 * i as i32;
        legend.draw(&Rectangle::new([(8, y - 6), (22, y + 6)], color.filled()))?;
        legend.draw(&Text::new(name.as_str(), (28, y - 8), (FONT, 14)))?;
    }
    let count = panel.groups.len().max(1);
    let x_axis = Ticked {
        inner: RangedCoordf64::from(0.0..count as f64),
        ticks: (0..panel.groups.len()).map(|g| g as f64 + 0.5).collect(),
    };
    let y_axis = Ticked {
        inner: LogCoord::from((y0..y1).log_scale()),
        ticks: log_ticks(y0, y1),
    };
    let mut chart = ChartBuilder::on(&area)
        .caption(&panel.title, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x_axis, y_axis)?;
    let group_label = |x: &f64| {
        panel
            .groups
            .get(x.floor().max(0.0) as usize)
            .map_or_else(String::new, |g| g.label.clone())
    };
    chart
        .configure_mesh()
        .x_label_formatter(&group_label)
        .y_label_formatter(&|y: &f64| format!("{}x", tick_label(*y)))
        .y_desc(&panel.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .disable_x_mesh()
        .draw()?;
    let width = 0.8 / panel.series.len().max(1) as f64;
    for i in 0..panel.series.len() {
        let color = PALETTE[i % PALETTE.len()];
        let bars = panel.groups.iter().enumerate().filter_map(|(g, group)| {
            let v = group
                .values
                .get(i)
                .copied()
                .flatten()
                .filter(|v| *v > 0.0 && v.is_finite())?;
            let x = g as f64 + 0.1 + i as f64 * width;
            Some(Rectangle::new([(x, y0), (x + width * 0.9, v)], color.filled()))
        });
        chart.draw_series(bars)?;
    }
    let line = [(0.0, panel.reference), (count as f64, panel.reference)];
    chart.draw_series(DashedLineSeries::new(line, 8, 5, BLACK.stroke_width(2)))?;
    Ok(())
}

/// An axis with the ticks chosen here (module doc); `inner` maps values to pixels. The grid
/// has lines at the ticks only.
struct Ticked<R> {
    inner: R,
    ticks: Vec<f64>,
}

impl<R: Ranged<ValueType = f64>> Ranged for Ticked<R> {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// Most ticks an axis gets.
const MAX_TICKS: usize = 12;

/// Ticks of a log axis over `[lo, hi]`, `0 < lo < hi`: powers of ten, else 1-2-5, else 1…9
/// per decade, the first of these to give three ticks or more (thinned to at most
/// [`MAX_TICKS`]); a range too narrow for that (within one decade) gets round linear steps.
/// At least two ticks for any range that is not a point.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return linear_ticks(lo, hi, false);
    }
    let per_decade: [&[f64]; 3] = [&[1.0], &[1.0, 2.0, 5.0], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]];
    for mantissas in per_decade {
        let mut ticks = Vec::new();
        let mut decade = 10f64.powi(lo.log10().floor() as i32);
        while decade <= hi {
            for &m in mantissas {
                let t = m * decade;
                if t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9) {
                    ticks.push(t);
                }
            }
            decade *= 10.0;
        }
        if ticks.len() >= 3 {
            let every = ticks.len().div_ceil(MAX_TICKS);
            return ticks.into_iter().step_by(every).collect();
        }
    }
    linear_ticks(lo, hi, false)
}

/// Ticks of a linear axis over `[lo, hi]` at a round step (1, 2 or 5 times a power of ten)
/// giving about six; with `integer`, steps of at least 1 and whole-number ticks only.
fn linear_ticks(lo: f64, hi: f64, integer: bool) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return if lo.is_finite() { vec![lo] } else { Vec::new() };
    }
    let raw = (hi - lo) / 6.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let mut step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * magnitude);
    if integer {
        step = step.max(1.0).round();
    }
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).take(4 * MAX_TICKS).collect()
}

/// A tick's label: the number with a k/M/G suffix from 10^4 on, written with the fewest
/// decimals (up to six) that state it exactly, so round ticks read `0.25`, `40k`, `1.25M`.
fn tick_label(v: f64) -> String {
    let a = v.abs();
    let (unit, suffix) = if a >= 1e9 {
        (1e9, "G")
    } else if a >= 1e6 {
        (1e6, "M")
    } else if a >= 1e4 {
        (1e3, "k")
    } else {
        (1.0, "")
    };
    let x = v / unit;
    let decimals = (0..=6)
        .find(|&d| {
            let shown: f64 = format!("{x:.d$}").parse().unwrap_or(f64::NAN);
            (shown - x).abs() <= 1e-9 * x.abs().max(1e-12)
        })
        .unwrap_or(6);
    format!("{x:.decimals$}{suffix}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_state_round_numbers_exactly() {
        assert_eq!(tick_label(3.0), "3");
        assert_eq!(tick_label(2.5), "2.5");
        assert_eq!(tick_label(0.125), "0.125");
        assert_eq!(tick_label(3.0 * 0.1), "0.3");
        assert_eq!(tick_label(1e-4), "0.0001");
        assert_eq!(tick_label(2_500_000.0), "2.5M");
        assert_eq!(tick_label(1_250_000.0), "1.25M");
        assert_eq!(tick_label(40_000.0), "40k");
        assert_eq!(tick_label(0.0), "0");
    }

    #[test]
    fn log_axes_are_labelled_even_within_one_decade() {
        // Frame times of 40..46 ms, padded as the plot pads them: within one decade, where
        // labelling only powers of ten left the axis bare.
        for (lo, hi) in [
            (30.8, 69.0),
            (2.3, 4.1),
            (41.0, 42.0),
            (0.011, 0.013),
            (1.0, 1e6),
            (0.5, 30.0),
            (1e-3, 1e12),
        ] {
            let ticks = log_ticks(lo, hi);
            assert!(ticks.len() >= 2 && ticks.len() <= MAX_TICKS, "{lo}..{hi}: {ticks:?}");
            assert!(
                ticks.iter().all(|&t| t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9)),
                "{ticks:?}"
            );
            let labels: Vec<String> = ticks.iter().map(|&t| tick_label(t)).collect();
            let mut distinct = labels.clone();
            distinct.dedup();
            assert_eq!(distinct, labels, "{lo}..{hi}: labels repeat");
        }
        assert_eq!(log_ticks(30.8, 69.0), [40.0, 50.0, 60.0]);
        assert_eq!(log_ticks(1.0, 1000.0), [1.0, 10.0, 100.0, 1000.0]);
    }

    #[test]
    fn frame_axes_tick_whole_frames() {
        for (lo, hi) in [(0.0, 1.0), (0.0, 3.0), (0.0, 15.0), (0.0, 119.0), (0.0, 999.0)] {
            let ticks = linear_ticks(lo, hi, true);
            assert!(ticks.len() >= 2, "{lo}..{hi}: {ticks:?}");
            assert!(ticks.iter().all(|t| t.fract() == 0.0), "{lo}..{hi}: {ticks:?}");
        }
        assert_eq!(linear_ticks(0.0, 1.0, true), [0.0, 1.0]);
        assert_eq!(linear_ticks(0.0, 3.0, true), [0.0, 1.0, 2.0, 3.0]);
        // Without the constraint, the same range is cut at fractions.
        assert!(linear_ticks(0.0, 1.0, false).iter().any(|t| t.fract() != 0.0));
    }

    #[test]
    fn plots_render_text_with_the_embedded_font() {
        let dir = std::env::temp_dir().join(format!("occult-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("the temporary directory is writable");
        let path = dir.join("p.png");
        let panel = Panel {
            title: "title".into(),
            x_label: "frame".into(),
            y_label: "ms".into(),
            log_x: false,
            integer_x: true,
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
        draw(&path, &[panel]).expect("a plot with an empty series draws");
        let img = image::open(&path).expect("the plot just drawn is a PNG");
        assert_eq!((img.width(), img.height()), (1100, 480));
        std::fs::remove_dir_all(&dir).expect("the test's scratch directory can be removed");
    }

    #[test]
    fn bar_charts_draw_groups_with_missing_and_extreme_values() {
        let dir = std::env::temp_dir().join(format!("occult-bars-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("the temporary directory is writable");
        let path = dir.join("b.png");
        let panel = |groups: Vec<BarGroup>| BarPanel {
            title: "speedup".into(),
            y_label: "x zbuffer".into(),
            series: vec!["zbuffer".into(), "hzb".into()],
            groups,
            reference: 1.0,
        };
        let groups = (0..12)
            .map(|g| BarGroup {
                label: format!("case-{g}"),
                values: vec![Some(1.0), if g == 3 { None } else { Some(0.01 + g as f64 * 3.0) }],
            })
            .collect();
        draw_bars(&path, &[panel(groups), panel(Vec::new())])
            .expect("bar charts with a missing value and an empty panel draw");
        let img = image::open(&path).expect("the chart just drawn is a PNG");
        assert_eq!((img.width(), img.height()), (140 * 12 + 160 + LEGEND_WIDTH, 1040));
        std::fs::remove_dir_all(&dir).expect("the test's scratch directory can be removed");
    }
}
