//! Photos and frames in: PNG, JPEG, GIF and the other formats `image` decodes, told apart by
//! their content, not their extension.

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::landmark::RgbFrame;

#[derive(Debug, Error)]
pub enum PhotoError {
    #[error("{path}: {message}")]
    Read { path: PathBuf, message: String },
}

/// Decodes an image file to RGB (alpha dropped, grey expanded).
pub fn read_rgb(path: &Path) -> Result<RgbFrame, PhotoError> {
    let err = |message: String| PhotoError::Read {
        path: path.to_path_buf(),
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    decode_rgb(&bytes).map_err(err)
}

/// Decodes image bytes to RGB; the format comes from the bytes' signature.
pub fn decode_rgb(bytes: &[u8]) -> Result<RgbFrame, String> {
    if bytes.is_empty() {
        return Err("empty file (0 bytes), not an image".into());
    }
    let format = image::guess_format(bytes)
        .map_err(|_| "not an image facelab can read (PNG, JPEG, GIF)".to_string())?;
    let img = image::load_from_memory_with_format(bytes, format)
        .map_err(|e| format!("cannot decode the {format:?} image: {e}"))?
        .to_rgb8();
    let (w, h) = img.dimensions();
    if w < 2 || h < 2 {
        return Err(format!(
            "the image is {w}x{h} pixels, too small to hold a face"
        ));
    }
    Ok(RgbFrame::new(w as usize, h as usize, img.into_raw()))
}

/// Every frame of an animated GIF as RGB, and its frame rate (from the first frame's delay;
/// 10 fps when it gives none).
pub fn read_gif(path: &Path) -> Result<(Vec<RgbFrame>, f64), PhotoError> {
    use image::AnimationDecoder;
    let err = |message: String| PhotoError::Read {
        path: path.to_path_buf(),
        message,
    };
    let file = std::fs::File::open(path).map_err(|e| err(format!("cannot read: {e}")))?;
    let decoder = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(file))
        .map_err(|e| err(format!("not a readable GIF: {e}")))?;
    let frames = decoder
        .into_frames()
        .collect_frames()
        .map_err(|e| err(format!("cannot decode the GIF's frames: {e}")))?;
    if frames.is_empty() {
        return Err(err("a GIF with no frames".into()));
    }
    let (num, den) = frames[0].delay().numer_denom_ms();
    let ms = if num == 0 {
        100.0
    } else {
        num as f64 / den as f64
    };
    let out = frames
        .into_iter()
        .map(|f| {
            let rgb = image::DynamicImage::ImageRgba8(f.into_buffer()).to_rgb8();
            let (w, h) = rgb.dimensions();
            RgbFrame::new(w as usize, h as usize, rgb.into_raw())
        })
        .collect();
    Ok((out, 1000.0 / ms))
}
