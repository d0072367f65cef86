//! `facelab bench landmark`: detection, landmarks, fit and observer per frame, and a clip.

use crate::io::face::FaceSource;
use crate::io::Layout;
use crate::observe::landmarks;
use anyhow::{Context, Result};
use std::io::Write;
use std::time::Instant;

use super::*;

/// `facelab bench landmark`: the picture path per frame on the calling thread: detection,
/// landmarks (Face Mesh v2, the default, and v1), the blendshape head, the metric fit and the
/// observer, on a 640x360 frame
/// (the committed astronaut photo scaled into it), `frames` times each; then a `seconds`-long
/// clip at 24 fps of that frame, from frames in memory to AU rows with tracking, as
/// `observe` runs it.
pub fn bench_landmark(
    layout: &Layout,
    frames: usize,
    seconds: f64,
    out: &mut impl Write,
) -> Result<()> {
    use crate::io::calibration::read_calibration;
    use crate::landmark::{metric, Landmarker, MeshNetwork, MeshVersion, RgbFrame};
    use crate::observe::model_observer;
    use crate::transfer::pictures::{landmark_frames, openface_rows, InputKind};

    let path = layout.file("tests/data/landmarker/photos/astronaut.png");
    let photo = image::open(&path)
        .with_context(|| format!("{}: cannot read the benchmark's photo", path.display()))?
        .to_rgb8();
    let scaled = image::imageops::resize(&photo, 360, 360, image::imageops::FilterType::Triangle);
    let mut canvas = image::RgbImage::from_pixel(640, 360, image::Rgb([90, 90, 90]));
    image::imageops::replace(&mut canvas, &scaled, 140, 0);
    let frame = RgbFrame::new(640, 360, canvas.into_raw());

    let landmarker = Landmarker::new()?;
    let model = FaceSource::of(layout).model()?;
    let rest = model.rest_state();
    let rest = rest.surface(model.vertex_count()).to_vec();
    let calibration = read_calibration(&layout.calibration())?.calibration();
    let observer = model_observer(&model, calibration.clone())?;
    let time = |f: &mut dyn FnMut() -> Result<()>| -> Result<f64> {
        f()?;
        let t = Instant::now();
        for _ in 0..frames {
            f()?;
        }
        Ok(t.elapsed().as_secs_f64() / frames as f64 * 1e3)
    };
    let detection = landmarker.detector.detect(&frame)?;
    let face = anyhow::Context::context(detection.first(), "the bench photo has a face")?.clone();
    let rect = face.face_rect(landmarker.mesh.version);
    let mesh = landmarker.mesh.run(&frame, &rect)?;
    let v1 = MeshNetwork::new(MeshVersion::V1)?;
    let v1_rect = face.face_rect(MeshVersion::V1);
    let detect_ms = time(&mut || {
        std::hint::black_box(landmarker.detector.detect(&frame)?);
        Ok(())
    })?;
    let mesh_ms = time(&mut || {
        std::hint::black_box(landmarker.mesh.run(&frame, &rect)?);
        Ok(())
    })?;
    let mesh_v1_ms = time(&mut || {
        std::hint::black_box(v1.run(&frame, &v1_rect)?);
        Ok(())
    })?;
    let blendshapes_ms = time(&mut || {
        std::hint::black_box(landmarker.blendshapes.scores(&mesh.points)?);
        Ok(())
    })?;
    let fit_ms = time(&mut || {
        std::hint::black_box(metric::fit(&mesh.points, &rest));
        Ok(())
    })?;
    let fitted = metric::fit(&mesh.points, &rest);
    let observe_ms = time(&mut || {
        std::hint::black_box(observer.observe(&landmarks(&fitted.points))?);
        Ok(())
    })?;
    line(out, "landmark.detect_ms", detect_ms, "ms")?;
    line(out, "landmark.mesh_ms", mesh_ms, "ms")?;
    line(out, "landmark.mesh_v1_ms", mesh_v1_ms, "ms")?;
    line(out, "landmark.blendshapes_ms", blendshapes_ms, "ms")?;
    line(out, "landmark.metric_fit_ms", fit_ms, "ms")?;
    line(out, "landmark.observe_ms", observe_ms, "ms")?;
    line(
        out,
        "landmark.frame_detect_ms",
        detect_ms + mesh_ms + blendshapes_ms + fit_ms + observe_ms,
        "ms",
    )?;
    line(
        out,
        "landmark.frame_track_ms",
        mesh_ms + blendshapes_ms + fit_ms + observe_ms,
        "ms",
    )?;

    let n = (seconds * 24.0).round() as usize;
    let clip = vec![frame; n];
    let t = Instant::now();
    let l = landmark_frames(&landmarker, &model, InputKind::Video, clip, 24.0, "bench")?;
    let observer = model_observer(&model, calibration)?;
    let rows = openface_rows(&l, &observer)?;
    std::hint::black_box(&rows);
    line(out, "landmark.clip_frames", n as f64, "count")?;
    line(out, "landmark.clip_s", t.elapsed().as_secs_f64(), "s")?;
    out.flush()?;
    Ok(())
}
