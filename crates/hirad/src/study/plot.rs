//! Plots of the study (`plotters`), written as SVG and PNG side by side, atomically.
//!
//! One colour per strategy, the same in every plot ([`strategy_color`]); log axes where the paper
//! uses them (time and error in Fig. 2, ε in Fig. 3).

use crate::cluster::Strategy;
use crate::io::{write_atomic, write_bytes_atomic};
use crate::{Error, Result};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
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
    pub name: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
}

/// A line plot with optional log axes.
#[derive(Clone, Debug)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
}

/// A bar chart with one bar per category.
#[derive(Clone, Debug)]
pub struct BarPlot {
    pub title: String,
    pub y_label: String,
    pub bars: Vec<(String, RGBColor, f64)>,
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
    match (p.log_x, p.log_y) {
        (true, true) => draw_lines(root, p, (x0..x1).log_scale(), (y0..y1).log_scale()),
        (true, false) => draw_lines(root, p, (x0..x1).log_scale(), y0..y1),
        (false, true) => draw_lines(root, p, x0..x1, (y0..y1).log_scale()),
        (false, false) => draw_lines(root, p, x0..x1, y0..y1),
    }
}

fn draw_bars<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    p: &BarPlot,
) -> std::result::Result<(), String> {
    let e = |e: &dyn std::fmt::Debug| format!("{e:?}");
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let n = p.bars.len().max(1);
    let ymax = p
        .bars
        .iter()
        .map(|b| b.2)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let ymax = if ymax > 0.0 { ymax * 1.1 } else { 1.0 };
    let names: Vec<String> = p.bars.iter().map(|b| b.0.clone()).collect();
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(72)
        .build_cartesian_2d((0..n).into_segmented(), 0.0..ymax)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .y_desc(&p.y_label)
        .x_labels(n)
        .x_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                names.get(*i).cloned().unwrap_or_default()
            }
            SegmentValue::Last => String::new(),
        })
        .draw()
        .map_err(|x| e(&x))?;
    for (i, (_, color, v)) in p.bars.iter().enumerate() {
        let v = if v.is_finite() { *v } else { 0.0 };
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [
                    (SegmentValue::Exact(i), 0.0),
                    (SegmentValue::Exact(i + 1), v),
                ],
                color.filled(),
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
            bars: vec![
                ("kdt".into(), PALETTE[0], 10.0),
                ("proxi".into(), PALETTE[5], 3.0),
            ],
        };
        let files = b.write(&dir.path().join("fig6")).unwrap();
        assert!(std::fs::read_to_string(&files[0])
            .unwrap()
            .contains("proxi"));
        // Distinct colours for every strategy.
        let mut c: Vec<_> = Strategy::ALL.iter().map(|&s| strategy_color(s)).collect();
        c.dedup();
        assert_eq!(c.len(), Strategy::ALL.len());
    }
}
