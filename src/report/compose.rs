//! Composite images: labelled grids of renders (the paper's Fig. 5 and video frames) and
//! animated GIFs, as bytes so the harness can cache and write them atomically.

use anyhow::Result;
use image::{Rgb, RgbImage};
use plotters::prelude::*;

/// PNG bytes of an image.
pub fn png_bytes(image: &RgbImage) -> Result<Vec<u8>> {
    let mut out = std::io::Cursor::new(Vec::new());
    image.write_to(&mut out, image::ImageFormat::Png)?;
    Ok(out.into_inner())
}

/// An animated GIF (looping) of equally sized frames, `delay_ms` each: each frame's palette
/// (NeuQuant at speed 10) is made side by side with the others, then the frames are written
/// in order, as `image`'s GIF encoder writes them frame after frame (the same bytes).
pub fn gif_bytes(frames: &[RgbImage], delay_ms: u32) -> Result<Vec<u8>> {
    use rayon::prelude::*;
    let Some(first) = frames.first() else {
        return Ok(Vec::new());
    };
    let side = |v: u32| {
        u16::try_from(v).map_err(|_| anyhow::anyhow!("a GIF frame is at most 65,535 pixels a side"))
    };
    let (width, height) = (side(first.width())?, side(first.height())?);
    let delay = u16::try_from(delay_ms / 10).unwrap_or(u16::MAX);
    let quantized: Vec<gif::Frame<'static>> = frames
        .par_iter()
        .map(|f| {
            let mut rgba: Vec<u8> = f.pixels().flat_map(|p| [p[0], p[1], p[2], 255]).collect();
            let mut frame =
                gif::Frame::from_rgba_speed(side(f.width())?, side(f.height())?, &mut rgba, 10);
            frame.delay = delay;
            frame.dispose = gif::DisposalMethod::Background;
            Ok(frame)
        })
        .collect::<Result<_>>()?;
    let mut out = Vec::new();
    {
        let mut encoder = gif::Encoder::new(&mut out, width, height, &[])?;
        encoder.set_repeat(gif::Repeat::Infinite)?;
        for frame in &quantized {
            encoder.write_frame(frame)?;
        }
    }
    Ok(out)
}

/// A grid of equally sized cells with a title, column labels on top and row labels on the
/// left (no left margin when they are all empty), text in the embedded font.
pub fn labelled_grid(
    title: &str,
    cells: &[Vec<RgbImage>],
    row_labels: &[String],
    column_labels: &[String],
) -> Result<RgbImage> {
    super::figures::register_font();
    let (cw, ch) = cells
        .first()
        .and_then(|r| r.first())
        .map(|c| (c.width(), c.height()))
        .unwrap_or((1, 1));
    let columns = cells.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let left = if row_labels.iter().all(String::is_empty) {
        0
    } else {
        190u32
    };
    let top = 70u32;
    let (w, h) = (left + columns * cw, top + cells.len() as u32 * ch);
    let mut canvas = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    for (r, row) in cells.iter().enumerate() {
        for (c, cell) in row.iter().enumerate() {
            let (x, y) = (left + c as u32 * cw, top + r as u32 * ch);
            image::imageops::replace(&mut canvas, cell, x as i64, y as i64);
        }
    }
    {
        let root = BitMapBackend::with_buffer(canvas.as_mut(), (w, h)).into_drawing_area();
        let title_style = ("sans-serif", 26).into_font().color(&BLACK);
        root.draw_text(title, &title_style, (12, 8))?;
        let label = ("sans-serif", 20).into_font().color(&BLACK);
        for (c, text) in column_labels.iter().enumerate() {
            let x = (left + c as u32 * cw + cw / 2) as i32 - 5 * text.len() as i32;
            root.draw_text(text, &label, (x, top as i32 - 28))?;
        }
        for (r, text) in row_labels.iter().enumerate() {
            let y = (top + r as u32 * ch + ch / 2) as i32;
            for (i, line) in text.lines().enumerate() {
                root.draw_text(line, &label, (10, y - 12 + 24 * i as i32))?;
            }
        }
        root.present()?;
    }
    Ok(canvas)
}

/// A contact sheet: equally sized cells in rows of `columns`, each with its label printed
/// under it, and a title.
pub fn contact_sheet(
    title: &str,
    cells: &[(String, RgbImage)],
    columns: usize,
) -> Result<RgbImage> {
    super::figures::register_font();
    let (cw, ch) = cells
        .first()
        .map(|(_, c)| (c.width(), c.height()))
        .unwrap_or((1, 1));
    let columns = columns.max(1);
    let rows = cells.len().div_ceil(columns) as u32;
    let (top, caption) = (56u32, 30u32);
    let (w, h) = (columns as u32 * cw, top + rows * (ch + caption));
    let mut canvas = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    for (i, (_, cell)) in cells.iter().enumerate() {
        let (c, r) = ((i % columns) as u32, (i / columns) as u32);
        let (x, y) = (c * cw, top + r * (ch + caption));
        image::imageops::replace(&mut canvas, cell, x as i64, y as i64);
    }
    {
        let root = BitMapBackend::with_buffer(canvas.as_mut(), (w, h)).into_drawing_area();
        let title_style = ("sans-serif", 26).into_font().color(&BLACK);
        root.draw_text(title, &title_style, (12, 12))?;
        let label = ("sans-serif", 19).into_font().color(&BLACK);
        for (i, (text, _)) in cells.iter().enumerate() {
            let (c, r) = ((i % columns) as u32, (i / columns) as u32);
            let (tw, _) = root.estimate_text_size(text, &label)?;
            let x = (c * cw + cw / 2) as i32 - tw as i32 / 2;
            let y = (top + r * (ch + caption) + ch + 4) as i32;
            root.draw_text(text, &label, (x, y))?;
        }
        root.present()?;
    }
    Ok(canvas)
}

/// A photo frame with landmarks drawn as small green dots.
pub fn annotate(width: usize, height: usize, rgb: &[u8], points: Option<&[[f64; 3]]>) -> RgbImage {
    let mut img = RgbImage::from_raw(width as u32, height as u32, rgb.to_vec())
        .expect("frame size matches its pixels");
    if let Some(points) = points {
        let r = (width.max(height) / 1000).max(1) as i64;
        for p in points {
            let (cx, cy) = (p[0].round() as i64, p[1].round() as i64);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (cx + dx, cy + dy);
                    if dx * dx + dy * dy <= r * r
                        && (0..width as i64).contains(&x)
                        && (0..height as i64).contains(&y)
                    {
                        img.put_pixel(x as u32, y as u32, Rgb([40, 230, 90]));
                    }
                }
            }
        }
    }
    img
}

/// `left` scaled to `right`'s height, then `right` beside it.
pub fn side_by_side(left: &RgbImage, right: &RgbImage) -> RgbImage {
    let h = right.height();
    let w = ((left.width() as f64) * h as f64 / left.height() as f64)
        .round()
        .max(1.0) as u32;
    let scaled = image::imageops::resize(left, w, h, image::imageops::FilterType::Triangle);
    let mut out = RgbImage::new(w + right.width(), h);
    image::imageops::replace(&mut out, &scaled, 0, 0);
    image::imageops::replace(&mut out, right, w as i64, 0);
    out
}
