//! Output: renders of the face (and, later, tables and figures). Never touches specs or the
//! cache.

pub mod compose;
pub mod figures;
pub mod head;
pub mod render;
pub mod table;

use std::path::Path;

/// Writes `image` as PNG atomically (temp file in the same folder, then rename), so an
/// interrupted run never leaves a half-written image.
pub fn save_png(image: &image::RgbImage, path: &Path) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    }
    let tmp = path.with_extension("png.tmp");
    image
        .save_with_format(&tmp, image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot write PNG", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("{}: cannot rename into place", path.display()))?;
    Ok(())
}
