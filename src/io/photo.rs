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
