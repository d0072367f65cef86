//! Plots with plotters, drawn into memory and saved as PNG atomically. Text uses DejaVu Sans
//! embedded in the binary (`assets/fonts/`), so no system font is needed.

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

pub(super) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// A log axis label: only 1, 2 and 5 times a power of ten, so labels never crowd.
fn log_label(v: &f64) -> String {
    let mantissa = v / 10f64.powf(v.log10().floor());
    let nice = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .any(|m| (mantissa - m).abs() < 1e-6 * m);
    if nice {
        format!("{v:.0e}")
    } else {
        String::new()
    }
}

/// Draws one curve, solid or dashed, with a legend entry drawn the same way: a 24 px line,
/// broken in the middle when dashed.
fn draw_curve<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    dashed: bool,
    label: &str,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    CT: CoordTranslate<From = (f64, f64)>,
{
    let style = ShapeStyle::from(&color).stroke_width(2);
    let drawn = if dashed {
        chart.draw_series(DashedLineSeries::new(points, 8, 5, style))?
    } else {
        chart.draw_series(LineSeries::new(points, style))?
    };
    let (gap_from, gap_to) = if dashed { (9, 15) } else { (12, 12) };
    let style = color.stroke_width(3);
    drawn.label(label).legend(move |(x, y)| {
        EmptyElement::at((x, y))
            + PathElement::new([(0, 0), (gap_from, 0)], style)
            + PathElement::new([(gap_to, 0), (24, 0)], style)
    });
    Ok(())
}

/// A named curve.
pub struct Series {
    pub label: String,
    pub values: Vec<f64>,
    pub color: RGBColor,
    pub dashed: bool,
}

pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 0, 0),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 158, 115),
    RGBColor(213, 94, 0),
    RGBColor(0, 114, 178),
    RGBColor(204, 121, 167),
];

fn save(buffer: Vec<u8>, (w, h): (u32, u32), path: &Path) -> Result<()> {
    let image = image::RgbImage::from_raw(w, h, buffer).ok_or_else(|| anyhow!("bad buffer"))?;
    super::save_png(&image, path)
}

/// Curves over epochs on a log-scaled y axis.
pub fn log_curves(path: &Path, title: &str, y_label: &str, series: &[Series]) -> Result<()> {
    register_font();
    let size = (960u32, 640u32);
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let epochs = series
            .iter()
            .map(|s| s.values.len())
            .max()
            .unwrap_or(1)
            .max(2);
        let positive = series
            .iter()
            .flat_map(|s| s.values.iter().copied())
            .filter(|v| *v > 0.0 && v.is_finite());
        let lo = positive.clone().fold(f64::INFINITY, f64::min).max(1e-12);
        let hi = positive.fold(0.0f64, f64::max).max(lo * 10.0);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 26))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(90)
            .build_cartesian_2d(1f64..epochs as f64, (lo * 0.8..hi * 1.25).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("epoch")
            // At most one label per epoch: short runs otherwise repeat rounded labels.
            .x_labels(epochs.min(11))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_desc(y_label)
            .label_style(("sans-serif", 18))
            .axis_desc_style(("sans-serif", 20))
            .y_label_formatter(&log_label)
            .y_max_light_lines(1)
            .draw()?;
        for s in series {
            let points: Vec<(f64, f64)> = s
                .values
                .iter()
                .enumerate()
                .filter(|(_, v)| **v > 0.0)
                .map(|(i, v)| ((i + 1) as f64, *v))
                .collect();
            draw_curve(&mut chart, points, s.color, s.dashed, &s.label)?;
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 17))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
    }
    save(buffer, size, path)
}

/// Grouped bars: for each category, one bar per group (e.g. paper vs facelab), log y axis.
pub fn grouped_bars(
    path: &Path,
    title: &str,
    y_label: &str,
    categories: &[String],
    groups: &[(String, RGBColor, Vec<f64>)],
) -> Result<()> {
    register_font();
    let size = ((70 * categories.len() as u32).max(960), 600u32);
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let values = groups
            .iter()
            .flat_map(|g| g.2.iter().copied())
            .filter(|v| *v > 0.0);
        let lo = values.clone().fold(f64::INFINITY, f64::min).max(1e-12);
        let hi = values.fold(0.0f64, f64::max).max(lo * 10.0);
        let n = categories.len();
        // Headroom above the bars for the legend (about 24 px per entry of a ~480 px plot),
        // so it never covers a bar.
        let legend = ((groups.len() as f64 * 24.0 + 16.0) / 480.0).min(0.6);
        let top = hi * 2.0 * (4.0 * hi / lo).powf(legend / (1.0 - legend));
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 26))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(90)
            .build_cartesian_2d(0f64..n as f64, (lo * 0.5..top).log_scale())?;
        let cats = categories.to_vec();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n * 2 + 1)
            .x_label_formatter(&move |x| {
                let i = x.floor() as usize;
                if (x - x.floor() - 0.5).abs() < 1e-6 && i < cats.len() {
                    cats[i].clone()
                } else {
                    String::new()
                }
            })
            .y_desc(y_label)
            .y_label_formatter(&log_label)
            .y_max_light_lines(1)
            .label_style(("sans-serif", 18))
            .axis_desc_style(("sans-serif", 20))
            .draw()?;
        let width = 0.8 / groups.len() as f64;
        for (g, (label, color, vals)) in groups.iter().enumerate() {
            let color = *color;
            chart
                .draw_series(
                    vals.iter()
                        .enumerate()
                        .filter(|(_, v)| **v > 0.0)
                        .map(|(i, v)| {
                            let x0 = i as f64 + 0.1 + g as f64 * width;
                            Rectangle::new(
                                [(x0, lo * 0.5), (x0 + width * 0.95, *v)],
                                color.filled(),
                            )
                        }),
                )?
                .label(label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 16, y + 6)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 17))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
    }
    save(buffer, size, path)
}

/// One row of the editing figure: a knot spacing's displacement map and edited curve.
pub struct EditRow {
    pub label: String,
    pub displacement: Vec<f64>,
    pub edited: Vec<f64>,
}

/// Choe et al.'s Fig. 7: per knot spacing (rows), the original curve with its keys, the
/// displacement map, and the edited curve with the keys.
pub fn edit_figure(
    path: &Path,
    title: &str,
    frames: &[f64],
    original: &[f64],
    keys: &[(f64, f64)],
    rows: &[EditRow],
) -> Result<()> {
    register_font();
    let size = (1500u32, 60 + 330 * rows.len() as u32);
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 26))?;
        let cells = root.split_evenly((rows.len(), 3));
        let (x0, x1) = (
            frames.first().copied().unwrap_or(0.0),
            frames.last().copied().unwrap_or(1.0).max(frames[0] + 1.0),
        );
        let dmax = rows
            .iter()
            .flat_map(|r| r.displacement.iter().map(|v| v.abs()))
            .fold(0.05f64, f64::max)
            * 1.15;
        for (r, row) in rows.iter().enumerate() {
            // (panel, values, draw the keys, y range)
            type Panel<'a> = (&'a str, &'a [f64], bool, (f64, f64));
            let panels: [Panel; 3] = [
                ("original and keys", original, true, (0.0, 1.0)),
                ("displacement map", &row.displacement, false, (-dmax, dmax)),
                ("edited", &row.edited, true, (0.0, 1.0)),
            ];
            for (c, (name, values, show_keys, (lo, hi))) in panels.into_iter().enumerate() {
                let mut chart = ChartBuilder::on(&cells[r * 3 + c])
                    .caption(format!("{name} ({})", row.label), ("sans-serif", 18))
                    .margin(10)
                    .x_label_area_size(36)
                    .y_label_area_size(50)
                    .build_cartesian_2d(x0..x1, lo..hi)?;
                chart
                    .configure_mesh()
                    .x_desc("frame")
                    .x_label_formatter(&|v| format!("{v:.0}"))
                    .y_label_formatter(&|v| format!("{:.1}", if v.abs() < 1e-9 { 0.0 } else { *v }))
                    .label_style(("sans-serif", 14))
                    .axis_desc_style(("sans-serif", 15))
                    .draw()?;
                chart.draw_series(LineSeries::new(
                    frames.iter().copied().zip(values.iter().copied()),
                    ShapeStyle::from(&PALETTE[1]).stroke_width(2),
                ))?;
                if show_keys {
                    chart.draw_series(
                        keys.iter()
                            .map(|&(x, y)| Circle::new((x, y), 6, PALETTE[5].filled())),
                    )?;
                }
            }
        }
        root.present()?;
    }
    save(buffer, size, path)
}

/// A curve with its own x values.
pub struct XySeries {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub color: RGBColor,
    pub dashed: bool,
}

/// One panel of `line_panels`.
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<XySeries>,
}

/// Panels side by side (linear axes, each fitted to its data with 8 % headroom for the
/// legend), saved as one PNG.
pub fn line_panels(path: &Path, title: &str, panels: &[Panel]) -> Result<()> {
    register_font();
    let size = (520 * panels.len().max(1) as u32, 520u32);
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 26))?;
        let areas = root.split_evenly((1, panels.len().max(1)));
        for (panel, area) in panels.iter().zip(&areas) {
            let all = panel.series.iter().flat_map(|s| s.points.iter().copied());
            let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            for (x, y) in all.filter(|(x, y)| x.is_finite() && y.is_finite()) {
                (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
            }
            if x0 > x1 {
                (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
            }
            // Headroom above the curves for the legend (about 19 px per entry of a ~370 px
            // plot), so it never covers one.
            let pad = ((y1 - y0) * 0.08).max(1e-9);
            let legend = ((panel.series.len() as f64 * 19.0 + 20.0) / 370.0).min(0.6);
            let (y0, y1) = (y0 - pad, y0 - pad + (y1 - y0 + 2.0 * pad) / (1.0 - legend));
            let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, ("sans-serif", 21))
                .margin(14)
                .x_label_area_size(48)
                .y_label_area_size(64)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            chart
                .configure_mesh()
                .x_desc(panel.x_label.as_str())
                .y_desc(panel.y_label.as_str())
                .label_style(("sans-serif", 16))
                .axis_desc_style(("sans-serif", 18))
                .draw()?;
            for s in &panel.series {
                draw_curve(&mut chart, s.points.clone(), s.color, s.dashed, &s.label)?;
            }
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 15))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperLeft)
                .draw()?;
        }
        root.present()?;
    }
    save(buffer, size, path)
}

/// A heat map of values in `[0, max]`: one row per `rows` label, one column per `columns`
/// label, each cell coloured from white (0) to dark red (`max`) and printed to one decimal.
pub fn heat_map(
    path: &Path,
    title: &str,
    rows: &[String],
    columns: &[String],
    values: &[Vec<f64>],
    max: f64,
) -> Result<()> {
    heat_map_with(path, title, rows, columns, values, max, 1)
}

/// [`heat_map`] with values printed to `decimals` places (cells widen to fit).
pub fn heat_map_with(
    path: &Path,
    title: &str,
    rows: &[String],
    columns: &[String],
    values: &[Vec<f64>],
    max: f64,
    decimals: usize,
) -> Result<()> {
    register_font();
    let (cell_w, cell_h) = (46u32 + 8 * decimals as u32, 26u32);
    let (left, top, right, bottom) = (330u32, 90u32, 30u32, 30u32);
    let size = (
        left + cell_w * columns.len() as u32 + right,
        top + cell_h * rows.len() as u32 + bottom,
    );
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let text = |size: u32| TextStyle::from(("sans-serif", size).into_font()).color(&BLACK);
        root.draw(&Text::new(title, (16, 14), text(24)))?;
        for (j, c) in columns.iter().enumerate() {
            let x = (left + cell_w * j as u32 + 8) as i32;
            root.draw(&Text::new(c.clone(), (x, top as i32 - 26), text(16)))?;
        }
        for (i, (label, row)) in rows.iter().zip(values).enumerate() {
            let y = (top + cell_h * i as u32) as i32;
            root.draw(&Text::new(label.clone(), (12, y + 5), text(16)))?;
            for (j, &v) in row.iter().enumerate() {
                let x = (left + cell_w * j as u32) as i32;
                let t = (v / max).clamp(0.0, 1.0);
                // White -> orange -> dark red, readable in grey scale too.
                let (r, g, b) = if t < 0.5 {
                    let s = t / 0.5;
                    (255.0, 255.0 - 105.0 * s, 255.0 - 215.0 * s)
                } else {
                    let s = (t - 0.5) / 0.5;
                    (255.0 - 115.0 * s, 150.0 - 140.0 * s, 40.0 - 20.0 * s)
                };
                let fill = RGBColor(r as u8, g as u8, b as u8);
                root.draw(&Rectangle::new(
                    [(x, y), (x + cell_w as i32, y + cell_h as i32)],
                    fill.filled(),
                ))?;
                root.draw(&Rectangle::new(
                    [(x, y), (x + cell_w as i32, y + cell_h as i32)],
                    RGBColor(200, 200, 200),
                ))?;
                let ink = if t > 0.6 { WHITE } else { BLACK };
                let style = TextStyle::from(("sans-serif", 15).into_font()).color(&ink);
                root.draw(&Text::new(
                    format!("{v:.decimals$}"),
                    (x + 10, y + 5),
                    style,
                ))?;
            }
        }
        root.present()?;
    }
    save(buffer, size, path)
}

/// Scores in [0, 1] over time (seconds), one curve per `(label, values)`, broken where a
/// value is `None` (a frame without a face): e.g. MediaPipe's blendshapes of a clip.
pub fn score_curves(
    title: &str,
    times: &[f64],
    curves: &[(String, Vec<Option<f64>>)],
) -> Result<image::RgbImage> {
    register_font();
    let size = (1100u32, 480u32);
    let mut buffer = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 24))?;
        let x1 = times.last().copied().unwrap_or(1.0).max(1e-3);
        let mut chart = ChartBuilder::on(&root)
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..x1, 0.0..1.35)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc("score")
            .y_labels(8)
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 18))
            .draw()?;
        for (k, (label, values)) in curves.iter().enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            let style = ShapeStyle::from(&color).stroke_width(2);
            let mut segment: Vec<(f64, f64)> = Vec::new();
            let mut first = true;
            let mut flush = |segment: &mut Vec<(f64, f64)>,
                             chart: &mut ChartContext<
                '_,
                BitMapBackend<'_>,
                Cartesian2d<
                    plotters::coord::types::RangedCoordf64,
                    plotters::coord::types::RangedCoordf64,
                >,
            >|
             -> Result<()> {
                if segment.is_empty() {
                    return Ok(());
                }
                let drawn = chart.draw_series(LineSeries::new(segment.drain(..), style))?;
                if first {
                    drawn
                        .label(label.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
                    first = false;
                }
                Ok(())
            };
            for (t, v) in times.iter().zip(values) {
                match v {
                    Some(v) => segment.push((*t, *v)),
                    None => flush(&mut segment, &mut chart)?,
                }
            }
            flush(&mut segment, &mut chart)?;
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 16))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
    }
    image::RgbImage::from_raw(size.0, size.1, buffer).ok_or_else(|| anyhow!("bad buffer"))
}
