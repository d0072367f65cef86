//! Photos and videos in: any input `facelab observe` and `facelab transfer` take, told apart
//! by content (an OpenFace CSV, a PNG/JPEG/GIF image, a folder of frames, or a video that
//! `ffmpeg` decodes), through the built-in landmarker (`crate::landmark`) to OpenFace-layout
//! rows: the 68 iBUG landmarks in 2D (pixels) and 3D (OpenFace's camera frame, mm), the head
//! pose, and the 17 AUs read by our observer from the face fitted into the model's frame.
//!
//! The observer reads each frame exactly as it reads the simulated face: the 468 points are
//! fitted onto the model's rest surface (`landmark::metric`), the 68 landmarks taken through
//! the iBUG map, and measured against a neutral face. For one photo that neutral is the
//! model's own rest face (a single picture has no neutral of its own); for a clip or folder
//! it is the person's: the per-landmark median over the frames with a face, as OpenFace
//! files are read (`--neutral` chooses).

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{bail, Context, Result};

use crate::io::blendshapes::blendshapes_csv;
use crate::io::openface::{FaceRow, OpenFaceFile};
use crate::io::photo::decode_rgb;
use crate::io::rows::{self, num, CsvRow};
use crate::landmark::{metric, Blendshapes, FaceMesh, Landmarker, RgbFrame, MESH_POINTS};
use crate::observe::{landmarks, Calibration, Observer, AU_COUNT, LANDMARK_COUNT};
use crate::sim::geom::V3;
use crate::sim::FaceModel;

/// Millimetres per model unit (the model is in centimetres).
const MM: f64 = 10.0;

/// What a path holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    OpenFace,
    Image,
    Gif,
    Folder,
    Video,
}

/// Tells an input's kind from its content: a folder; an image by its signature (PNG, JPEG,
/// GIF); an OpenFace CSV by its header (a first line naming `AU` or `frame` columns); anything
/// else is offered to `ffmpeg` as a video.
pub fn input_kind(path: &Path) -> Result<InputKind> {
    let meta =
        std::fs::metadata(path).with_context(|| format!("{}: cannot read", path.display()))?;
    if meta.is_dir() {
        return Ok(InputKind::Folder);
    }
    if meta.len() == 0 {
        bail!("{}: empty file (0 bytes)", path.display());
    }
    let mut head = vec![0u8; 4096];
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .with_context(|| format!("{}: cannot read", path.display()))?;
    head.truncate(n);
    if let Ok(format) = image::guess_format(&head) {
        return Ok(match format {
            image::ImageFormat::Gif => InputKind::Gif,
            _ => InputKind::Image,
        });
    }
    let first = head.split(|b| *b == b'\n').next().unwrap_or(&[]);
    if let Ok(line) = std::str::from_utf8(first) {
        if line.contains(',')
            && (line.contains("AU") || line.contains("frame") || line.contains("face"))
        {
            return Ok(InputKind::OpenFace);
        }
    }
    Ok(InputKind::Video)
}

/// Which neutral face the AUs are measured against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PhotoNeutral {
    /// The model's rest face.
    Model,
    /// The per-landmark median of the input's frames with a face.
    Median,
    /// One frame (0-based index into the input).
    Frame(usize),
}

/// One input frame through the landmarker.
#[derive(Clone, Debug)]
pub struct LandmarkedFrame {
    /// The 468 points in image pixels (z scaled like x), `None` when no face was found.
    pub mesh: Option<FaceMesh>,
    /// The fit into the model's frame.
    pub metric: Option<metric::MetricFace>,
    /// MediaPipe's 52 blendshape scores of the face (Face Mesh v2 landmarks only).
    pub blendshapes: Option<Blendshapes>,
    /// Faces found by the detector in this frame (when it ran).
    pub faces_found: usize,
}

/// The frames of an input and what the landmarker found in each.
pub struct Landmarked {
    pub kind: InputKind,
    pub width: usize,
    pub height: usize,
    /// Frames per second (videos and GIFs; 30 for folders, 0 for a photo).
    pub fps: f64,
    pub frames: Vec<RgbFrame>,
    pub found: Vec<LandmarkedFrame>,
    /// Warnings to show the user (frames without a face, several faces).
    pub warnings: Vec<String>,
}

/// Reads every frame of an image input (not an OpenFace file).
pub fn read_frames(path: &Path, kind: InputKind) -> Result<(Vec<RgbFrame>, f64)> {
    match kind {
        InputKind::Image => {
            let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
            let frame = decode_rgb(&bytes).map_err(|m| anyhow::anyhow!("{}: {m}", path.display()))?;
            Ok((vec![frame], 0.0))
        }
        InputKind::Gif => Ok(crate::io::photo::read_gif(path)?),
        InputKind::Folder => read_folder(path),
        InputKind::Video => read_video(path),
        InputKind::OpenFace => bail!(
            "{}: an OpenFace CSV, not a picture (`facelab observe --openface FILE` reads its landmarks)",
            path.display()
        ),
    }
}

/// The images of a folder in name order (PNG, JPEG, GIF by content; other files ignored).
fn read_folder(path: &Path) -> Result<(Vec<RgbFrame>, f64)> {
    let mut names: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("{}: cannot list", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    names.sort();
    let mut frames = Vec::new();
    for p in names {
        let bytes = std::fs::read(&p).with_context(|| format!("{}: cannot read", p.display()))?;
        if image::guess_format(&bytes).is_err() {
            continue;
        }
        let frame = decode_rgb(&bytes).map_err(|m| anyhow::anyhow!("{}: {m}", p.display()))?;
        if let Some(first) = frames.first() {
            let first: &RgbFrame = first;
            if (first.width, first.height) != (frame.width, frame.height) {
                bail!(
                    "{}: {}x{} pixels, the folder's first image is {}x{}",
                    p.display(),
                    frame.width,
                    frame.height,
                    first.width,
                    first.height
                );
            }
        }
        frames.push(frame);
    }
    if frames.is_empty() {
        bail!(
            "{}: a folder with no images (PNG, JPEG or GIF)",
            path.display()
        );
    }
    Ok((frames, 30.0))
}

fn ffmpeg_missing(path: &Path, tool: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: not an image or OpenFace CSV, so read as a video, which needs `{tool}` on PATH \
         (Debian/Ubuntu: `apt-get install ffmpeg`)",
        path.display()
    )
}

/// Decodes a video with ffmpeg (size and frame rate from ffprobe), frames as RGB.
fn read_video(path: &Path) -> Result<(Vec<RgbFrame>, f64)> {
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=width,height,r_frame_rate",
            "-of",
            "csv=p=0",
        ])
        .arg(path)
        .output()
        .map_err(|_| ffmpeg_missing(path, "ffprobe"))?;
    let text = String::from_utf8_lossy(&probe.stdout);
    let line = text.lines().next().unwrap_or("").trim();
    if !probe.status.success() || line.is_empty() {
        bail!(
            "{}: not an image, OpenFace CSV or video with a video stream{}",
            path.display(),
            match String::from_utf8_lossy(&probe.stderr).lines().next() {
                Some(e) if !e.is_empty() => format!(" (ffprobe: {e})"),
                _ => String::new(),
            }
        );
    }
    let cells: Vec<&str> = line.split(',').collect();
    let parse = |s: &str| s.trim().parse::<usize>().ok();
    let (w, h) = match (
        cells.first().and_then(|s| parse(s)),
        cells.get(1).and_then(|s| parse(s)),
    ) {
        (Some(w), Some(h)) if w >= 2 && h >= 2 => (w, h),
        _ => bail!("{}: ffprobe gave no frame size (`{line}`)", path.display()),
    };
    let fps = cells
        .get(2)
        .and_then(|r| {
            let (a, b) = r.split_once('/')?;
            let (a, b) = (a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?);
            (b > 0.0 && a > 0.0).then_some(a / b)
        })
        .unwrap_or(30.0);
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-i"])
        .arg(path)
        .args(["-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .map_err(|_| ffmpeg_missing(path, "ffmpeg"))?;
    if !out.status.success() {
        bail!(
            "{}: ffmpeg cannot decode it: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let size = w * h * 3;
    let frames: Vec<RgbFrame> = out
        .stdout
        .chunks_exact(size)
        .map(|c| RgbFrame::new(w, h, c.to_vec()))
        .collect();
    if frames.is_empty() {
        bail!("{}: the video stream has no frames", path.display());
    }
    Ok((frames, fps))
}

/// Runs the landmarker over every frame: for a video or GIF, detection on the first frame and
/// whenever the face is lost, tracking from the previous frame's landmarks otherwise
/// (MediaPipe's video mode); a folder's pictures are each detected. A frame with several
/// faces takes the largest.
pub fn landmark_frames(
    landmarker: &Landmarker,
    model: &FaceModel,
    kind: InputKind,
    frames: Vec<RgbFrame>,
    fps: f64,
    name: &str,
) -> Result<Landmarked> {
    use rayon::prelude::*;
    let rest = model.rest_state();
    let rest = rest.surface(model.vertex_count());
    let mut warnings = Vec::new();
    // A frame's mesh found by detection: the largest face, and how many there were.
    let detect = |frame: &RgbFrame| -> Result<(Option<FaceMesh>, usize)> {
        let faces = landmarker.faces(frame)?;
        let n = faces.len();
        Ok((faces.into_iter().next().map(|f| f.mesh), n))
    };
    let meshes: Vec<(Option<FaceMesh>, usize)> = if kind == InputKind::Folder {
        // A folder holds separate pictures: each is detected (MediaPipe's static mode), side
        // by side.
        let detected: Vec<Result<_>> = frames.par_iter().map(detect).collect();
        detected.into_iter().collect::<Result<_>>()?
    } else {
        let mut meshes = Vec::with_capacity(frames.len());
        let mut previous: Option<FaceMesh> = None;
        for frame in &frames {
            let tracked = match &previous {
                Some(p) => landmarker.track(frame, p)?,
                None => None,
            };
            let found = match tracked {
                Some(m) => (Some(m), 1),
                None => detect(frame)?,
            };
            previous = found.0.clone();
            meshes.push(found);
        }
        meshes
    };
    let mut missing = Vec::new();
    for (i, (mesh, faces_found)) in meshes.iter().enumerate() {
        if *faces_found > 1 {
            warnings.push(format!(
                "{name}: frame {i}: {faces_found} faces, took the largest"
            ));
        }
        if mesh.is_none() {
            missing.push(i);
        }
    }
    // Each found mesh's metric face and blendshapes are its own: made side by side.
    let found: Vec<Result<LandmarkedFrame>> = meshes
        .into_par_iter()
        .map(|(mesh, faces_found)| -> Result<LandmarkedFrame> {
            let metric = mesh.as_ref().map(|m| metric::fit(&m.points, rest));
            let blendshapes = match &mesh {
                Some(m) => landmarker.blendshapes(m)?,
                None => None,
            };
            Ok(LandmarkedFrame {
                mesh,
                metric,
                blendshapes,
                faces_found,
            })
        })
        .collect();
    // The first error in frame order, whatever the threads.
    let found = found.into_iter().collect::<Result<Vec<_>>>()?;
    if !missing.is_empty() {
        let list: Vec<String> = missing.iter().take(10).map(|i| i.to_string()).collect();
        warnings.push(format!(
            "{name}: no face in {} of {} frames (success = 0): {}{}",
            missing.len(),
            frames.len(),
            list.join(", "),
            if missing.len() > 10 { ", ..." } else { "" }
        ));
    }
    let (width, height) = (frames[0].width, frames[0].height);
    Ok(Landmarked {
        kind,
        width,
        height,
        fps,
        frames,
        found,
        warnings,
    })
}

/// The 68 iBUG landmarks of a fitted face, in the model's frame.
fn model_landmarks(face: &metric::MetricFace) -> [V3; LANDMARK_COUNT] {
    landmarks(&face.points)
}

/// The observer for these frames' AUs (see the module notes for the neutral face).
pub fn observer_for(
    model: &FaceModel,
    found: &[LandmarkedFrame],
    neutral: PhotoNeutral,
    calibration: Calibration,
) -> Result<Observer> {
    let faces: Vec<[V3; LANDMARK_COUNT]> = found
        .iter()
        .filter_map(|f| f.metric.as_ref().map(model_landmarks))
        .collect();
    let neutral_face = match neutral {
        PhotoNeutral::Model => {
            let rest = model.rest_state();
            landmarks(rest.surface(model.vertex_count()))
        }
        PhotoNeutral::Median => {
            if faces.is_empty() {
                bail!("no frame with a face to take the neutral from");
            }
            crate::observe::median_face(&faces)
        }
        PhotoNeutral::Frame(i) => match found.get(i).and_then(|f| f.metric.as_ref()) {
            Some(m) => model_landmarks(m),
            None => bail!("--neutral-frame {i}: no such frame with a face"),
        },
    };
    Ok(Observer::new(&neutral_face, calibration)?)
}

/// OpenFace-layout rows: one per frame, `success = 0` where no face was found.
pub fn openface_rows(l: &Landmarked, observer: &Observer) -> Result<Vec<FaceRow>> {
    let map = crate::observe::landmarks::landmark_vertices();
    let mut rows = Vec::with_capacity(l.found.len());
    for (i, f) in l.found.iter().enumerate() {
        let timestamp = if l.fps > 0.0 { i as f64 / l.fps } else { 0.0 };
        let base = FaceRow {
            line: i + 2,
            frame: i as i64 + 1,
            face_id: Some(0),
            timestamp: Some(timestamp),
            confidence: 0.0,
            success: false,
            aus: [0.0; AU_COUNT],
            pose: None,
            landmarks_2d: None,
            landmarks_3d: None,
        };
        let (Some(mesh), Some(m)) = (&f.mesh, &f.metric) else {
            rows.push(FaceRow {
                pose: Some([0.0; 6]),
                landmarks_2d: Some(Box::new([[0.0; 2]; LANDMARK_COUNT])),
                landmarks_3d: Some(Box::new([[0.0; 3]; LANDMARK_COUNT])),
                ..base
            });
            continue;
        };
        let model68 = model_landmarks(m);
        let o = observer
            .observe(&model68)
            .with_context(|| format!("frame {i}"))?;
        let pixels: [[f64; 2]; LANDMARK_COUNT] = std::array::from_fn(|k| {
            let vs = &map[k];
            let mut p = [0.0; 2];
            for &v in vs {
                p[0] += mesh.points[v][0] / vs.len() as f64;
                p[1] += mesh.points[v][1] / vs.len() as f64;
            }
            p
        });
        // OpenFace's camera frame (mm, +y down, +z away): the model-frame landmarks turned by
        // the head pose, placed where the face is in the image at the fitted scale (x, y from
        // the image centre; weak perspective, so no depth: Tz is 0).
        let turn = m.pose.rotation();
        let mm = MM * m.scale;
        let center = mesh.rect.center;
        let t = [
            (center[0] - l.width as f64 / 2.0) * mm,
            (center[1] - l.height as f64 / 2.0) * mm,
            0.0,
        ];
        let camera: [V3; LANDMARK_COUNT] = std::array::from_fn(|k| {
            let q = turn.apply(model68[k]);
            [q[0] * MM + t[0], -q[1] * MM + t[1], -q[2] * MM + t[2]]
        });
        let p = m.pose;
        rows.push(FaceRow {
            confidence: mesh.score,
            success: true,
            aus: o.aus,
            pose: Some([t[0], t[1], t[2], p.pitch, p.yaw, p.roll]),
            landmarks_2d: Some(Box::new(pixels)),
            landmarks_3d: Some(Box::new(camera)),
            ..base
        });
    }
    Ok(rows)
}

/// A line of `landmarks.csv`.
#[derive(serde::Serialize, serde::Deserialize)]
struct LandmarkLine {
    frame: usize,
    vertex: usize,
    #[serde(serialize_with = "num::fixed::<2, _>")]
    x: f64,
    #[serde(serialize_with = "num::fixed::<2, _>")]
    y: f64,
    #[serde(serialize_with = "num::fixed::<2, _>")]
    z: f64,
}

impl CsvRow for LandmarkLine {}

/// `landmarks.csv`: `frame,vertex,x,y,z` for every frame with a face (x, y in pixels, z scaled
/// like x, as MediaPipe gives them).
pub fn landmarks_csv(l: &Landmarked) -> String {
    let mut lines = Vec::new();
    for (i, f) in l.found.iter().enumerate() {
        if let Some(m) = &f.mesh {
            for (vertex, p) in m.points.iter().take(MESH_POINTS).enumerate() {
                lines.push(LandmarkLine {
                    frame: i + 1,
                    vertex,
                    x: p[0],
                    y: p[1],
                    z: p[2],
                });
            }
        }
    }
    rows::to_csv(&lines)
}

/// What `landmark_input` wrote (or [`landmark_files`] made) and found.
pub struct LandmarkOutput {
    pub kind: InputKind,
    /// `DIR/openface.csv`.
    pub openface: PathBuf,
    /// The frames as `openface.csv` records them (each value at OpenFace's decimals), what a
    /// transfer of the input works from.
    pub frames: OpenFaceFile,
    /// Files written, or to write, under `DIR`: `openface.csv` first, `landmarks.csv`,
    /// `blendshapes.csv` and the picture.
    pub files: Vec<(&'static str, Vec<u8>)>,
    pub written: Vec<PathBuf>,
    /// Frames with a face, and without.
    pub faces: usize,
    pub missing: usize,
    pub warnings: Vec<String>,
    /// Each input frame with its landmarks drawn, cut to one window around the face.
    pub pictures: Vec<image::RgbImage>,
    /// MediaPipe's blendshapes per input frame (`None`: no face).
    pub blendshapes: Vec<Option<Blendshapes>>,
    /// The 68 landmarks' displacements from the neutral face per input frame (model frame,
    /// IOD units, flattened x, y, z), what the landmark-space fit matches.
    pub displacements: Vec<Option<Vec<f64>>>,
}

/// Photo/video -> landmarks -> `DIR/openface.csv` (OpenFace layout, our AUs under
/// `calibration`), `DIR/landmarks.csv` and the input with its landmarks drawn
/// (`landmarks.png` for a photo, `landmarks.gif` for several frames). `neutral` `None`: the
/// model's face for one frame, the median for several. Nothing is written when reading or
/// landmarking fails.
pub fn landmark_input(
    input: &Path,
    out: &Path,
    model: &FaceModel,
    calibration: Calibration,
    neutral: Option<PhotoNeutral>,
) -> Result<LandmarkOutput> {
    let mut made = landmark_files(input, out, model, calibration, neutral)?;
    made.written = write_files(out, &made.files)?;
    Ok(made)
}

/// Writes `files` into `out` (created if missing), each atomically; returns their paths.
pub fn write_files(out: &Path, files: &[(&'static str, Vec<u8>)]) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let mut written = Vec::new();
    for (file, data) in files {
        let path = out.join(file);
        crate::io::atomic::write_atomic(&path, data)?;
        written.push(path);
    }
    Ok(written)
}

/// What [`landmark_input`] writes, made but not written (`written` is empty), so that
/// `transfer` writes it only when the whole transfer succeeds.
pub fn landmark_files(
    input: &Path,
    out: &Path,
    model: &FaceModel,
    calibration: Calibration,
    neutral: Option<PhotoNeutral>,
) -> Result<LandmarkOutput> {
    use crate::report::compose::{annotate, gif_bytes, png_bytes};
    let kind = input_kind(input)?;
    let (frames, fps) = read_frames(input, kind)?;
    let landmarker = Landmarker::new().context("the built-in landmarker's networks")?;
    let name = input.display().to_string();
    let l = landmark_frames(&landmarker, model, kind, frames, fps, &name)?;
    let faces = l.found.iter().filter(|f| f.mesh.is_some()).count();
    if faces == 0 {
        bail!("{name}: no face found in {} frame(s)", l.found.len());
    }
    let neutral = neutral.unwrap_or(if l.found.len() == 1 {
        PhotoNeutral::Model
    } else {
        PhotoNeutral::Median
    });
    let observer = observer_for(model, &l.found, neutral, calibration)
        .with_context(|| format!("{name}: the neutral face"))?;
    let rows = openface_rows(&l, &observer).with_context(|| name.clone())?;
    let displacements = l
        .found
        .iter()
        .map(|f| {
            let Some(m) = &f.metric else { return Ok(None) };
            let d = observer.displacements(&model_landmarks(m))?;
            Ok(Some(super::inverter::flat(&d)))
        })
        .collect::<Result<Vec<_>>>()?;
    let pictures: Vec<image::RgbImage> = l
        .frames
        .iter()
        .zip(&l.found)
        .map(|(f, found)| {
            annotate(
                f.width,
                f.height,
                &f.data,
                found.mesh.as_ref().map(|m| m.points.as_slice()),
            )
        })
        .collect();
    let crop = face_window(&l);
    let faces_only: Vec<image::RgbImage> = pictures
        .iter()
        .map(|p| image::imageops::crop_imm(p, crop[0], crop[1], crop[2], crop[3]).to_image())
        .collect();
    let bytes = crate::io::openface::openface_bytes(&rows);
    let preview = if pictures.len() == 1 {
        ("landmarks.png", png_bytes(&pictures[0])?)
    } else {
        let every = pictures.len().div_ceil(300).max(1);
        let small: Vec<image::RgbImage> = pictures
            .iter()
            .step_by(every)
            .map(|p| {
                let w = 320.min(p.width());
                let h = ((p.height() as f64) * w as f64 / p.width() as f64)
                    .round()
                    .max(1.0) as u32;
                image::imageops::resize(p, w, h, image::imageops::FilterType::Triangle)
            })
            .collect();
        let delay = if l.fps > 0.0 {
            (1000.0 * every as f64 / l.fps).round().max(20.0) as u32
        } else {
            100
        };
        ("landmarks.gif", gif_bytes(&small, delay)?)
    };
    let blendshapes: Vec<Option<Blendshapes>> = l.found.iter().map(|f| f.blendshapes).collect();
    let mut files = vec![
        ("openface.csv", bytes),
        ("landmarks.csv", landmarks_csv(&l).into_bytes()),
        (
            "blendshapes.csv",
            blendshapes_csv(&blendshapes, l.fps).into_bytes(),
        ),
        preview,
    ];
    if blendshapes.len() > 1 {
        let file = input
            .file_name()
            .map_or(name.clone(), |f| f.to_string_lossy().into());
        let figure = super::fidelity::blendshape_figure(&blendshapes, l.fps, &file)?;
        files.push(("blendshapes.png", figure));
    }
    Ok(LandmarkOutput {
        kind,
        openface: out.join("openface.csv"),
        frames: OpenFaceFile::from_rows(&out.join("openface.csv"), &rows),
        files,
        written: Vec::new(),
        faces,
        missing: l.found.len() - faces,
        warnings: l.warnings,
        pictures: faces_only,
        blendshapes,
        displacements,
    })
}

/// One window around the face for every frame (so a clip does not jitter): a square about
/// the median centre of the landmark crops, as large as the largest, clamped to the image;
/// `[x, y, width, height]` in pixels.
pub(crate) fn face_window(l: &Landmarked) -> [u32; 4] {
    let rects: Vec<_> = l
        .found
        .iter()
        .filter_map(|f| f.mesh.as_ref().map(|m| m.rect))
        .collect();
    let mut xs: Vec<f64> = rects.iter().map(|r| r.center[0]).collect();
    let mut ys: Vec<f64> = rects.iter().map(|r| r.center[1]).collect();
    let (cx, cy) = (crate::stats::median(&mut xs), crate::stats::median(&mut ys));
    let side = rects.iter().map(|r| r.width).fold(0.0, f64::max) * 1.1;
    let (w, h) = (l.width as f64, l.height as f64);
    let side = side.min(w).min(h).max(2.0);
    let x0 = (cx - side / 2.0).clamp(0.0, w - side);
    let y0 = (cy - side / 2.0).clamp(0.0, h - side);
    [x0 as u32, y0 as u32, side as u32, side as u32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_come_from_content_not_the_extension() {
        let dir = std::env::temp_dir().join(format!("facelab-kind-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let png = dir.join("photo.csv");
        image::RgbImage::new(4, 4)
            .save_with_format(&png, image::ImageFormat::Png)
            .unwrap();
        assert_eq!(input_kind(&png).unwrap(), InputKind::Image);
        let csv = dir.join("clip.png");
        std::fs::write(&csv, "frame, face_id, timestamp, AU01_r\n1, 0, 0.0, 0.5\n").unwrap();
        assert_eq!(input_kind(&csv).unwrap(), InputKind::OpenFace);
        assert_eq!(input_kind(&dir).unwrap(), InputKind::Folder);
        let empty = dir.join("empty.jpg");
        std::fs::write(&empty, "").unwrap();
        assert!(input_kind(&empty)
            .unwrap_err()
            .to_string()
            .contains("0 bytes"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
