//! Plots of the study (`plotters`), written as SVG and PNG side by side, atomically.
//!
//! One colour per strategy, the same in every plot ([`strategy_color`]); log axes where the paper
//! uses them (time and error in Fig. 2, ε in Fig. 3).

use hirad_accel::cluster::Strategy;
use hirad_core::io::{write_atomic, write_bytes_atomic};
use hirad_core::{Error, Result};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// Colour-blind-friendly palette (Okabe–Ito), one entry per strategy of [`Strategy::ALL`].
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(213, 94, 0),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
    RGBColor(240, 228, 66),
];

/// The colour of a strategy in every plot.
pub fn strategy_color(s: Strategy) -> RGBColor {
    let i = Strategy::ALL.iter().position(|&x| x == s).unwrap_or(0);
    PALETTE[i % PALETTE.len()]
}

/// One curve.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Line and marker colour.
    pub color: RGBColor,
    /// Points (x, y), in drawing order.
    pub points: Vec<(f64, f64)>,
}

/// A line plot with optional log axes.
#[derive(Clone, Debug)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The curves.
    pub series: Vec<Series>,
}

/// A bar chart with one bar per category, its value written above it.
#[derive(Clone, Debug)]
pub struct BarPlot {
    /// Title above the plot.
    pub title: String,
    /// Label of the value axis.
    pub y_label: String,
    /// Logarithmic value axis (for values spanning orders of magnitude).
    pub log_y: bool,
    /// Bars in order: label, colour, value.
    pub bars: Vec<(String, RGBColor, f64)>,
}

/// A tick or bar label: at most 3 significant digits, no float noise (0.30000000000000004),
/// scientific notation outside [1e-3, 1e5).
pub fn fmt_num(v: f64) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.2e}");
        // Trim the mantissa's trailing zeros: 2.50e-4 → 2.5e-4, 1.00e6 → 1e6.
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = m.trim_end_matches('0').trim_end_matches('.');
        return format!("{m}e{e}");
    }
    let digits = (2 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The corner of the plot with the fewest points (in the plot's own, possibly log,
/// coordinates), where the legend hides the least.
fn legend_corner(p: &LinePlot) -> SeriesLabelPosition {
    let tf = |v: f64, log: bool| if log { v.max(1e-300).ln() } else { v };
    let pts: Vec<(f64, f64)> = p
        .series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|&(x, y)| (tf(x, p.log_x), tf(y, p.log_y)))
        .collect();
    if pts.is_empty() {
        return SeriesLabelPosition::UpperRight;
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &pts {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let count = |right: bool, upper: bool| {
        pts.iter()
            .filter(|&&(x, y)| {
                let fx = (x - x0) / (x1 - x0).max(1e-300);
                let fy = (y - y0) / (y1 - y0).max(1e-300);
                (if right { fx > 0.6 } else { fx < 0.4 })
                    && (if upper { fy > 0.6 } else { fy < 0.4 })
            })
            .count()
    };
    [
        (SeriesLabelPosition::UpperRight, count(true, true)),
        (SeriesLabelPosition::UpperLeft, count(false, true)),
        (SeriesLabelPosition::LowerRight, count(true, false)),
        (SeriesLabelPosition::LowerLeft, count(false, false)),
    ]
    .into_iter()
    .min_by_key(|c| c.1)
    .map(|c| c.0)
    .unwrap_or(SeriesLabelPosition::UpperRight)
}

const SIZE: (u32, u32) = (900, 600);

fn perr<E: std::fmt::Display>(what: &Path) -> impl Fn(E) -> Error + '_ {
    move |e| Error::Config(format!("plot {}: {e}", what.display()))
}

/// Range of the values, padded, positive when `log`.
fn range(vals: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let v: Vec<f64> = vals
        .filter(|x| x.is_finite() && (!log || *x > 0.0))
        .collect();
    if v.is_empty() {
        return if log { (0.1, 10.0) } else { (0.0, 1.0) };
    }
    let lo = v.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if log {
        let (lo, hi) = if hi / lo < 1.01 {
            (lo / 2.0, hi * 2.0)
        } else {
            (lo, hi)
        };
        (lo / 1.25, hi * 1.25)
    } else {
        let pad = if hi > lo {
            (hi - lo) * 0.05
        } else {
            hi.abs().max(1.0) * 0.1
        };
        (lo - pad, hi + pad)
    }
}

fn draw_lines<DB, XS, YS>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    p: &LinePlot,
    xs: XS,
    ys: YS,
) -> std::result::Result<(), String>
where
    DB: DrawingBackend,
    XS: AsRangedCoord<Value = f64>,
    YS: AsRangedCoord<Value = f64>,
    XS::CoordDescType: ValueFormatter<f64>,
    YS::CoordDescType: ValueFormatter<f64>,
{
    let e = |e: &dyn std::fmt::Debug| format!("{e:?}");
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(xs, ys)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        .x_labels(8)
        .y_labels(8)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .x_label_formatter(&|v| fmt_num(*v))
        .y_label_formatter(&|v| fmt_num(*v))
        .draw()
        .map_err(|x| e(&x))?;
    for s in &p.series {
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .cloned()
            .filter(|(x, y)| {
                x.is_finite() && y.is_finite() && (!p.log_x || *x > 0.0) && (!p.log_y || *y > 0.0)
            })
            .collect();
        let color = s.color;
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(|x| e(&x))?
            .label(&s.name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&pt| Circle::new(pt, 3, color.filled())))
            .map_err(|x| e(&x))?;
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 15))
        .position(legend_corner(p))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

fn draw_line_any<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    p: &LinePlot,
) -> std::result::Result<(), String> {
    let (x0, x1) = range(
        p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)),
        p.log_x,
    );
    let (y0, y1) = range(
        p.series.iter().flat_map(|s| s.points.iter().map(|q| q.1)),
        p.log_y,
    );
    let lx = || (x0..x1).log_scale().with_key_points(log_ticks(x0, x1));
    let ly = || (y0..y1).log_scale().with_key_points(log_ticks(y0, y1));
    match (p.log_x, p.log_y) {
        (true, true) => draw_lines(root, p, lx(), ly()),
        (true, false) => draw_lines(root, p, lx(), y0..y1),
        (false, true) => draw_lines(root, p, x0..x1, ly()),
        (false, false) => draw_lines(root, p, x0..x1, y0..y1),
    }
}

/// Labelled ticks of a log axis over `[lo, hi]`: the 1-2-5 series of each decade, or a finer
/// series (1, 1.2, …, 2, 2.5, 3, …, 9) when the range is too narrow for three of those.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let series = |mults: &[f64]| -> Vec<f64> {
        let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (d0..=d1)
            .flat_map(|d| mults.iter().map(move |m| m * 10f64.powi(d)))
            .filter(|v| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9))
            .collect()
    };
    let t = series(&[1.0, 2.0, 5.0]);
    if t.len() >= 3 {
        t
    } else {
        series(&[
            1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0,
        ])
    }
}

fn draw_bars<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    p: &BarPlot,
) -> std::result::Result<(), String> {
    let e = |e: &dyn std::fmt::Debug| format!("{e:?}");
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let n = p.bars.len().max(1);
    let pos: Vec<f64> = p
        .bars
        .iter()
        .map(|b| b.2)
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let ymax = pos.iter().cloned().fold(0.0, f64::max);
    let ymin = pos.iter().cloned().fold(f64::INFINITY, f64::min);
    let names: Vec<String> = p.bars.iter().map(|b| b.0.clone()).collect();
    // Values in axis space: log10 of the value on a log axis (from below the smallest bar).
    let log = p.log_y && ymin.is_finite() && ymax > ymin;
    let (lo, hi) = if log {
        ((ymin / 2.0).log10(), (ymax * 2.0).log10())
    } else if ymax > 0.0 {
        (0.0, ymax * 1.12)
    } else {
        (0.0, 1.0)
    };
    let t = |v: f64| if log { v.max(1e-300).log10() } else { v };
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(72)
        .build_cartesian_2d((0..n as i32 - 1).into_segmented(), lo..hi)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .y_desc(if log {
            format!("{} (log scale)", p.y_label)
        } else {
            p.y_label.clone()
        })
        .y_labels(10)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .y_label_formatter(&|v| fmt_num(if log { 10f64.powf(*v) } else { *v }))
        .x_labels(n)
        .x_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                names.get(*i as usize).cloned().unwrap_or_default()
            }
            SegmentValue::Last => String::new(),
        })
        .draw()
        .map_err(|x| e(&x))?;
    let gap = (700 / n as u32 / 8).max(2);
    for (i, (_, color, v)) in p.bars.iter().enumerate() {
        let i = i as i32;
        let top = if v.is_finite() {
            t(*v).clamp(lo, hi)
        } else {
            lo
        };
        let mut r = Rectangle::new(
            [
                (SegmentValue::Exact(i), lo),
                (SegmentValue::Exact(i + 1), top),
            ],
            color.filled(),
        );
        r.set_margin(0, 0, gap, gap);
        chart.draw_series(std::iter::once(r)).map_err(|x| e(&x))?;
        chart
            .draw_series(std::iter::once(Text::new(
                fmt_num(*v),
                (SegmentValue::CenterOf(i), top),
                TextStyle::from(("sans-serif", 14).into_font())
                    .pos(Pos::new(HPos::Center, VPos::Bottom)),
            )))
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

impl LinePlot {
    /// Write `<stem>.svg` and `<stem>.png`.
    pub fn write(&self, stem: &Path) -> Result<Vec<PathBuf>> {
        let svg = stem.with_extension("svg");
        let png = stem.with_extension("png");
        let mut s = String::new();
        draw_line_any(
            SVGBackend::with_string(&mut s, SIZE).into_drawing_area(),
            self,
        )
        .map_err(perr(&svg))?;
        write_atomic(&svg, |w| w.write_all(s.as_bytes()))?;
        let mut buf = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
        draw_line_any(
            BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area(),
            self,
        )
        .map_err(perr(&png))?;
        write_png(&png, buf)?;
        Ok(vec![svg, png])
    }
}

impl BarPlot {
    /// Write `<stem>.svg` and `<stem>.png`.
    pub fn write(&self, stem: &Path) -> Result<Vec<PathBuf>> {
        let svg = stem.with_extension("svg");
        let png = stem.with_extension("png");
        let mut s = String::new();
        draw_bars(
            SVGBackend::with_string(&mut s, SIZE).into_drawing_area(),
            self,
        )
        .map_err(perr(&svg))?;
        write_atomic(&svg, |w| w.write_all(s.as_bytes()))?;
        let mut buf = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
        draw_bars(
            BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area(),
            self,
        )
        .map_err(perr(&png))?;
        write_png(&png, buf)?;
        Ok(vec![svg, png])
    }
}

fn write_png(path: &Path, rgb: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(SIZE.0, SIZE.1, rgb)
        .ok_or_else(|| Error::Config("plot buffer size".into()))?;
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::Config(format!("png {}: {e}", path.display())))?;
    write_bytes_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_log_line_plot_and_bars() {
        let dir = tempfile::tempdir().unwrap();
        let p = LinePlot {
            title: "time vs error".into(),
            x_label: "solve time (s)".into(),
            y_label: "RMS ΔE*uv".into(),
            log_x: true,
            log_y: true,
            series: Strategy::ALL
                .iter()
                .enumerate()
                .map(|(k, &s)| Series {
                    name: s.name().into(),
                    color: strategy_color(s),
                    points: (1..6)
                        .map(|i| (i as f64 * (k + 1) as f64, 10.0 / i as f64))
                        .collect(),
                })
                .collect(),
        };
        let files = p.write(&dir.path().join("fig2")).unwrap();
        assert_eq!(files.len(), 2);
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        assert!(svg.contains("<svg") && svg.contains("okdt-p"));
        let png = image::open(&files[1]).unwrap();
        assert_eq!((png.width(), png.height()), SIZE);
        let b = BarPlot {
            title: "clusters".into(),
            y_label: "clusters".into(),
            log_y: false,
            bars: vec![
                ("kdt".into(), PALETTE[0], 10.0),
                ("proxi".into(), PALETTE[5], 3.0),
            ],
        };
        let files = b.write(&dir.path().join("fig6")).unwrap();
        assert!(std::fs::read_to_string(&files[0])
            .unwrap()
            .contains("proxi"));
        let b = BarPlot {
            log_y: true,
            bars: vec![
                ("kdt".into(), PALETTE[0], 5500.0),
                ("proxi".into(), PALETTE[5], 46.6),
            ],
            ..b
        };
        let files = b.write(&dir.path().join("log")).unwrap();
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        assert!(svg.contains("(log scale)") && svg.contains("5500") && svg.contains("46.6"));
        // Distinct colours for every strategy.
        let mut c: Vec<_> = Strategy::ALL.iter().map(|&s| strategy_color(s)).collect();
        c.dedup();
        assert_eq!(c.len(), Strategy::ALL.len());
    }

    #[test]
    fn tick_labels_are_short_and_log_ticks_cover_the_range() {
        assert_eq!(fmt_num(0.30000000000000004), "0.3");
        assert_eq!(fmt_num(0.7000000000000001), "0.7");
        assert_eq!(fmt_num(5500.0), "5500");
        assert_eq!(fmt_num(46.62), "46.6");
        assert_eq!(fmt_num(1.0), "1");
        assert_eq!(fmt_num(0.0625), "0.0625");
        assert_eq!(fmt_num(2.5e-4), "2.5e-4");
        assert_eq!(fmt_num(1.0e6), "1e6");
        assert_eq!(fmt_num(0.0), "0");
        // Two decades: the 1-2-5 series.
        assert_eq!(log_ticks(0.08, 5.0), vec![0.1, 0.2, 0.5, 1.0, 2.0, 5.0]);
        // Under a decade (an error axis 6.7–17.5): the finer series.
        let t = log_ticks(6.7, 17.5);
        assert_eq!(t.len(), 7, "{t:?}");
        assert!(
            (t[0] - 7.0).abs() < 1e-12 && (t[6] - 16.0).abs() < 1e-9,
            "{t:?}"
        );
    }
}
