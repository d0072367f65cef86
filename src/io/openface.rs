//! OpenFace 2.x CSV files (FeatureExtraction, FaceLandmarkVidMulti, FaceLandmarkImg), read
//! and written as OpenFace writes them: no quotes, so a line's cells are the text between its
//! commas. Layout facts in `shared/facs-facts.md` (c):
//!
//! - separators `,` (2.2) or `, ` (2.0/2.1, header names then carry a leading space);
//! - sequence files start `frame[, face_id], timestamp, confidence, success`, image files
//!   `face, confidence` (no success column: every row counts);
//! - optional blocks: gaze, eye landmarks, pose (`pose_Tx..pose_Rz`), 2D landmarks
//!   (`x_0..y_67`), 3D landmarks (`X_0..Z_67`, mm), shape parameters, AU intensities
//!   (`AUxx_r`, required here) and presence (`AUxx_c`).
//!
//! Rows with `success = 0` are skipped and counted. Every error names the file, and where it
//! applies the line and column.

use std::path::{Path, PathBuf};

use crate::observe::{AU_COUNT, AU_NAMES, LANDMARK_COUNT};
use crate::sim::geom::V3;

/// The field separator of a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Separator {
    /// `,` (OpenFace 2.2).
    Comma,
    /// `, ` (OpenFace 2.0 and 2.1).
    CommaSpace,
}

/// What a file holds, as read from its header.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    pub separator: Separator,
    /// FaceLandmarkImg: rows start `face, confidence`.
    pub image_mode: bool,
    pub face_id: bool,
    pub timestamp: bool,
    pub pose: bool,
    pub landmarks_2d: bool,
    pub landmarks_3d: bool,
    /// Column names, trimmed.
    pub columns: Vec<String>,
}

/// One used row (success = 1).
#[derive(Clone, Debug, PartialEq)]
pub struct FaceRow {
    /// Line in the file (1-based, header = 1).
    pub line: usize,
    /// `frame` (sequence files) or `face` (image files).
    pub frame: i64,
    pub face_id: Option<i64>,
    pub timestamp: Option<f64>,
    pub confidence: f64,
    /// `success`: the reader keeps only rows with 1; a writer's row with `false` (a frame
    /// with no face) is written with zeros in every value column.
    pub success: bool,
    /// `AUxx_r` in `AU_NAMES` order.
    pub aus: [f64; AU_COUNT],
    /// `pose_Tx, Ty, Tz` (mm), `pose_Rx, Ry, Rz` (radians).
    pub pose: Option<[f64; 6]>,
    pub landmarks_2d: Option<Box<[[f64; 2]; LANDMARK_COUNT]>>,
    /// `X_i, Y_i, Z_i` in OpenFace's camera frame (mm; +y down, +z away from the camera).
    pub landmarks_3d: Option<Box<[V3; LANDMARK_COUNT]>>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct OpenFaceFile {
    pub path: PathBuf,
    pub layout: Layout,
    pub rows: Vec<FaceRow>,
    /// Rows with `success = 0`.
    pub skipped: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum OpenFaceError {
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{path}: the file is empty")]
    Empty { path: PathBuf },
    #[error("{path}:1: unknown separator: the header `{start}` has no commas (OpenFace writes `,` or `, `)")]
    Separator { path: PathBuf, start: String },
    #[error("{path}:1: not an OpenFace file: no `frame` or `face` column")]
    NotOpenFace { path: PathBuf },
    #[error("{path}:1: missing AU intensity columns: {missing}")]
    MissingAus { path: PathBuf, missing: String },
    #[error("{path}:1: column `{column}` appears twice")]
    Duplicate { path: PathBuf, column: String },
    #[error("{path}:{line}: column `{column}`: `{cell}` is not a number")]
    NotNumber {
        path: PathBuf,
        line: usize,
        column: String,
        cell: String,
    },
    #[error("{path}:{line}: column `{column}` is NaN")]
    NaN {
        path: PathBuf,
        line: usize,
        column: String,
    },
    #[error("{path}:{line}: {found} cells, but the header names {expected} columns")]
    Cells {
        path: PathBuf,
        line: usize,
        found: usize,
        expected: usize,
    },
}

fn pose_columns() -> [&'static str; 6] {
    [
        "pose_Tx", "pose_Ty", "pose_Tz", "pose_Rx", "pose_Ry", "pose_Rz",
    ]
}

fn au_column(k: usize) -> String {
    format!("{}_r", AU_NAMES[k])
}

/// Reads an OpenFace CSV file.
pub fn read_openface(path: &Path) -> Result<OpenFaceFile, OpenFaceError> {
    let bytes = std::fs::read(path).map_err(|cause| OpenFaceError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    parse_openface(bytes, path)
}

/// Parses the bytes of an OpenFace CSV file (`path` only names it in errors).
/// The landmark columns of `axes` (`x_0..x_67, y_0..`), in OpenFace's order.
fn landmark_names(axes: &[&str]) -> Vec<String> {
    axes.iter()
        .flat_map(|a| (0..LANDMARK_COUNT).map(move |i| format!("{a}_{i}")))
        .collect()
}

/// The layout a file's header gives, and its bytes with `, ` separators made `,`.
fn header_layout(bytes: Vec<u8>, path: &Path) -> Result<(Layout, Vec<u8>), OpenFaceError> {
    let p = || path.to_path_buf();
    let text_end = bytes
        .iter()
        .position(|&b| b == b'\n')
        .unwrap_or(bytes.len());
    let header = String::from_utf8_lossy(&bytes[..text_end])
        .trim_end_matches('\r')
        .to_string();
    if bytes.iter().all(|b| b.is_ascii_whitespace()) {
        return Err(OpenFaceError::Empty { path: p() });
    }
    if !header.contains(',') {
        return Err(OpenFaceError::Separator {
            path: p(),
            start: header.chars().take(40).collect(),
        });
    }
    let separator = if header.contains(", ") {
        Separator::CommaSpace
    } else {
        Separator::Comma
    };
    // `, ` files: drop the space after every comma so cells and names parse as in 2.2 files.
    let bytes = match separator {
        Separator::Comma => bytes,
        Separator::CommaSpace => {
            let mut out = Vec::with_capacity(bytes.len());
            let mut i = 0;
            while i < bytes.len() {
                out.push(bytes[i]);
                if bytes[i] == b',' && bytes.get(i + 1) == Some(&b' ') {
                    i += 1;
                }
                i += 1;
            }
            out
        }
    };
    let columns: Vec<String> = header.split(',').map(|c| c.trim().to_string()).collect();
    let has = |name: &str| columns.iter().any(|c| c == name);
    for (i, c) in columns.iter().enumerate() {
        if columns[..i].contains(c) {
            return Err(OpenFaceError::Duplicate {
                path: p(),
                column: c.clone(),
            });
        }
    }
    let image_mode = !has("frame") && has("face");
    if !has("frame") && !image_mode {
        return Err(OpenFaceError::NotOpenFace { path: p() });
    }
    let missing: Vec<String> = (0..AU_COUNT).map(au_column).filter(|c| !has(c)).collect();
    if !missing.is_empty() {
        return Err(OpenFaceError::MissingAus {
            path: p(),
            missing: missing.join(", "),
        });
    }
    let l2 = landmark_names(&["x", "y"]);
    let l3 = landmark_names(&["X", "Y", "Z"]);
    let layout = Layout {
        separator,
        image_mode,
        face_id: has("face_id"),
        timestamp: has("timestamp"),
        pose: pose_columns().iter().all(|c| has(c)),
        landmarks_2d: l2.iter().all(|c| has(c)),
        landmarks_3d: l3.iter().all(|c| has(c)),
        columns: columns.clone(),
    };
    Ok((layout, bytes))
}

/// The columns a parse uses, in order, and each used line's number and values.
struct Cells {
    names: Vec<String>,
    rows: Vec<(usize, Vec<f64>)>,
}

/// The columns a parse uses, each read as numbers, and each row's line in the file: a cell
/// that is not a number fails with its line, column and text, a line with more or fewer
/// cells than the header with its line. Lines are parsed side by side; the error reported
/// is the first in the file, whatever the threads.
fn read_cells(bytes: &[u8], path: &Path, layout: &Layout) -> Result<Cells, OpenFaceError> {
    use rayon::prelude::*;
    let (columns, image_mode) = (&layout.columns, layout.image_mode);
    let has = |name: &str| columns.iter().any(|c| c == name);
    let mut names: Vec<String> = vec![if image_mode { "face" } else { "frame" }.to_string()];
    for (flag, name) in [
        (layout.face_id, "face_id"),
        (layout.timestamp, "timestamp"),
        (has("confidence"), "confidence"),
        (has("success"), "success"),
    ] {
        if flag {
            names.push(name.to_string());
        }
    }
    names.extend((0..AU_COUNT).map(au_column));
    if layout.pose {
        names.extend(pose_columns().iter().map(|s| s.to_string()));
    }
    if layout.landmarks_2d {
        names.extend(landmark_names(&["x", "y"]));
    }
    if layout.landmarks_3d {
        names.extend(landmark_names(&["X", "Y", "Z"]));
    }
    // Where each of the file's columns goes among `names`.
    let mut slot: Vec<Option<usize>> = vec![None; columns.len()];
    for (k, name) in names.iter().enumerate() {
        let i = columns
            .iter()
            .position(|c| c == name)
            .expect("used columns are in the header");
        slot[i] = Some(k);
    }
    // OpenFace writes no quotes, so a line's cells are its text between commas. Lines are
    // counted from 1 (the header); empty lines are skipped.
    let lines: Vec<(usize, &[u8])> = bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .skip(1)
        .map(|(n, text)| (n + 1, text.strip_suffix(b"\r").unwrap_or(text)))
        .filter(|(_, text)| !text.is_empty())
        .collect();
    let parse_line = |&(line, text): &(usize, &[u8])| -> Result<(usize, Vec<f64>), OpenFaceError> {
        let mut values = vec![0.0; names.len()];
        let mut found = 0;
        for (i, cell) in text.split(|&b| b == b',').enumerate() {
            found += 1;
            let Some(k) = slot.get(i).copied().flatten() else {
                continue;
            };
            let text = String::from_utf8_lossy(cell);
            values[k] = text.trim().parse().map_err(|_| OpenFaceError::NotNumber {
                path: path.to_path_buf(),
                line,
                column: names[k].clone(),
                cell: text.trim().to_string(),
            })?;
        }
        if found != columns.len() {
            return Err(OpenFaceError::Cells {
                path: path.to_path_buf(),
                line,
                found,
                expected: columns.len(),
            });
        }
        Ok((line, values))
    };
    let parsed: Vec<Result<(usize, Vec<f64>), OpenFaceError>> =
        lines.par_iter().map(parse_line).collect();
    let rows = parsed.into_iter().collect::<Result<Vec<_>, _>>()?;
    Ok(Cells { names, rows })
}

pub fn parse_openface(bytes: Vec<u8>, path: &Path) -> Result<OpenFaceFile, OpenFaceError> {
    let (layout, bytes) = header_layout(bytes, path)?;
    let Cells { names, rows: cells } = read_cells(&bytes, path, &layout)?;
    let p = || path.to_path_buf();
    let index_of = |name: &str| names.iter().position(|c| c == name);
    let au_idx: Vec<usize> = (0..AU_COUNT)
        .map(|k| index_of(&au_column(k)).expect("AU columns are read"))
        .collect();
    let success_idx = index_of("success");
    let (face_id_idx, timestamp_idx, confidence_idx) = (
        index_of("face_id"),
        index_of("timestamp"),
        index_of("confidence"),
    );
    let mut rows = Vec::with_capacity(cells.len());
    let mut skipped = 0;
    for (line, data) in &cells {
        let line = *line;
        if success_idx.is_some_and(|s| data[s] == 0.0) {
            skipped += 1;
            continue;
        }
        let value = |i: usize| -> Result<f64, OpenFaceError> {
            let v = data[i];
            if v.is_nan() {
                return Err(OpenFaceError::NaN {
                    path: p(),
                    line,
                    column: names[i].clone(),
                });
            }
            Ok(v)
        };
        let mut aus = [0.0; AU_COUNT];
        for (k, &i) in au_idx.iter().enumerate() {
            aus[k] = value(i)?;
        }
        let frame = value(0)? as i64;
        let pose = if layout.pose {
            let mut out = [0.0; 6];
            for (k, name) in pose_columns().iter().enumerate() {
                out[k] = value(index_of(name).expect("pose read"))?;
            }
            Some(out)
        } else {
            None
        };
        let landmarks_2d = if layout.landmarks_2d {
            let base = index_of("x_0").expect("2D landmarks read");
            let mut out = Box::new([[0.0; 2]; LANDMARK_COUNT]);
            for i in 0..LANDMARK_COUNT {
                out[i] = [value(base + i)?, value(base + LANDMARK_COUNT + i)?];
            }
            Some(out)
        } else {
            None
        };
        let landmarks_3d = if layout.landmarks_3d {
            let base = index_of("X_0").expect("3D landmarks read");
            let mut out = Box::new([[0.0; 3]; LANDMARK_COUNT]);
            for i in 0..LANDMARK_COUNT {
                out[i] = [
                    value(base + i)?,
                    value(base + LANDMARK_COUNT + i)?,
                    value(base + 2 * LANDMARK_COUNT + i)?,
                ];
            }
            Some(out)
        } else {
            None
        };
        rows.push(FaceRow {
            line,
            frame,
            face_id: face_id_idx.map(|i| data[i] as i64),
            timestamp: timestamp_idx.map(|i| data[i]),
            confidence: confidence_idx.map_or(1.0, |i| data[i]),
            success: true,
            aus,
            pose,
            landmarks_2d,
            landmarks_3d,
        });
    }
    Ok(OpenFaceFile {
        path: path.to_path_buf(),
        layout,
        rows,
        skipped,
    })
}

/// The decimals OpenFace writes, which `write_openface` writes and `OpenFaceFile::from_rows`
/// rounds to.
const AU_DECIMALS: usize = 2;
const TIMESTAMP_DECIMALS: usize = 3;
const CONFIDENCE_DECIMALS: usize = 2;
const LANDMARK_DECIMALS: usize = 1;

/// The decimals of pose column `k` (`pose_columns` order): translation 1, rotation 3.
fn pose_decimals(k: usize) -> usize {
    if k < 3 {
        1
    } else {
        3
    }
}

impl OpenFaceFile {
    /// Frames made in memory (the landmarker's rows) as a reader of their written file
    /// (`write_openface`) sees them, without writing it: every value at OpenFace's decimals,
    /// the pose and landmark blocks only where every row has them, rows with `success = 0`
    /// counted in `skipped`, lines numbered as in the file. So a picture's transfer works from
    /// exactly the values its `openface.csv` records.
    pub fn from_rows(path: &Path, rows: &[FaceRow]) -> OpenFaceFile {
        let all = |has: fn(&FaceRow) -> bool| !rows.is_empty() && rows.iter().all(has);
        let pose = all(|r| r.pose.is_some());
        let landmarks_2d = all(|r| r.landmarks_2d.is_some());
        let landmarks_3d = all(|r| r.landmarks_3d.is_some());
        // A value as the writer's decimals leave it.
        let at = |v: f64, decimals: usize| -> f64 {
            format!("{v:.decimals$}")
                .parse()
                .expect("a formatted number reads back")
        };
        let mut columns: Vec<String> = ["frame", "face_id", "timestamp", "confidence", "success"]
            .map(String::from)
            .to_vec();
        if pose {
            columns.extend(pose_columns().map(String::from));
        }
        for (present, axes) in [
            (landmarks_2d, &["x", "y"][..]),
            (landmarks_3d, &["X", "Y", "Z"]),
        ] {
            if present {
                columns.extend(landmark_names(axes));
            }
        }
        columns.extend((0..AU_COUNT).map(au_column));
        let used: Vec<FaceRow> = rows
            .iter()
            .enumerate()
            .filter(|(_, r)| r.success)
            .map(|(i, r)| FaceRow {
                line: i + 2,
                frame: r.frame,
                face_id: Some(r.face_id.unwrap_or(0)),
                timestamp: Some(at(r.timestamp.unwrap_or(0.0), TIMESTAMP_DECIMALS)),
                confidence: at(r.confidence, CONFIDENCE_DECIMALS),
                success: true,
                aus: r.aus.map(|v| at(v, AU_DECIMALS)),
                pose: r
                    .pose
                    .filter(|_| pose)
                    .map(|p| std::array::from_fn(|k| at(p[k], pose_decimals(k)))),
                landmarks_2d: r
                    .landmarks_2d
                    .as_ref()
                    .filter(|_| landmarks_2d)
                    .map(|l| Box::new(l.map(|p| p.map(|v| at(v, LANDMARK_DECIMALS))))),
                landmarks_3d: r
                    .landmarks_3d
                    .as_ref()
                    .filter(|_| landmarks_3d)
                    .map(|l| Box::new(l.map(|p| p.map(|v| at(v, LANDMARK_DECIMALS))))),
            })
            .collect();
        OpenFaceFile {
            path: path.to_path_buf(),
            layout: Layout {
                separator: Separator::Comma,
                image_mode: false,
                face_id: true,
                timestamp: true,
                pose,
                landmarks_2d,
                landmarks_3d,
                columns,
            },
            skipped: rows.len() - used.len(),
            rows: used,
        }
    }
}

/// Writes rows as OpenFace 2.2's FeatureExtraction does (`,` separator): `frame, face_id,
/// timestamp, confidence, success`, the pose block if every row has one, the 2D and then the
/// 3D landmarks if every row has them, then the 17 `AUxx_r` columns, with OpenFace's decimals (AUs 2, pose
/// rotation 3, translation and landmarks 1, timestamp 3, confidence 2). The write is atomic.
pub fn write_openface(path: &Path, rows: &[FaceRow]) -> anyhow::Result<()> {
    Ok(crate::io::atomic::write_atomic(
        path,
        &openface_bytes(rows),
    )?)
}

/// The bytes `write_openface` writes.
pub fn openface_bytes(rows: &[FaceRow]) -> Vec<u8> {
    let mut cols: Vec<(String, Vec<String>)> = Vec::new();
    let mut text = |name: &str, f: &dyn Fn(&FaceRow) -> String| {
        cols.push((name.to_string(), rows.iter().map(f).collect()));
    };
    text("frame", &|r| r.frame.to_string());
    text("face_id", &|r| r.face_id.unwrap_or(0).to_string());
    text("timestamp", &|r| {
        format!("{:.*}", TIMESTAMP_DECIMALS, r.timestamp.unwrap_or(0.0))
    });
    text("confidence", &|r| {
        format!("{:.*}", CONFIDENCE_DECIMALS, r.confidence)
    });
    text("success", &|r| u8::from(r.success).to_string());
    if !rows.is_empty() && rows.iter().all(|r| r.pose.is_some()) {
        for (k, name) in pose_columns().iter().enumerate() {
            let decimals = pose_decimals(k);
            text(name, &|r| {
                format!("{:.*}", decimals, r.pose.expect("checked")[k])
            });
        }
    }
    if !rows.is_empty() && rows.iter().all(|r| r.landmarks_2d.is_some()) {
        for (axis, name) in ["x", "y"].iter().enumerate() {
            for i in 0..LANDMARK_COUNT {
                text(&format!("{name}_{i}"), &|r| {
                    format!(
                        "{:.*}",
                        LANDMARK_DECIMALS,
                        r.landmarks_2d.as_ref().expect("checked")[i][axis]
                    )
                });
            }
        }
    }
    if !rows.is_empty() && rows.iter().all(|r| r.landmarks_3d.is_some()) {
        for (axis, name) in ["X", "Y", "Z"].iter().enumerate() {
            for i in 0..LANDMARK_COUNT {
                text(&format!("{name}_{i}"), &|r| {
                    format!(
                        "{:.*}",
                        LANDMARK_DECIMALS,
                        r.landmarks_3d.as_ref().expect("checked")[i][axis]
                    )
                });
            }
        }
    }
    for k in 0..AU_COUNT {
        text(&au_column(k), &|r| format!("{:.*}", AU_DECIMALS, r.aus[k]));
    }
    // No cell holds a comma, a quote or a line break, so none is quoted.
    let mut out = Vec::new();
    let mut line = |cells: &mut dyn Iterator<Item = &str>| {
        for (i, cell) in cells.enumerate() {
            if i > 0 {
                out.push(b',');
            }
            out.extend_from_slice(cell.as_bytes());
        }
        out.push(b'\n');
    };
    line(&mut cols.iter().map(|(name, _)| name.as_str()));
    for r in 0..rows.len() {
        line(&mut cols.iter().map(|(_, values)| values[r].as_str()));
    }
    out
}

/// The 714 column names of a full OpenFace 2.2 FeatureExtraction file, in order.
pub fn full_header() -> Vec<String> {
    let mut h: Vec<String> = ["frame", "face_id", "timestamp", "confidence", "success"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    for e in 0..2 {
        for a in ["x", "y", "z"] {
            h.push(format!("gaze_{e}_{a}"));
        }
    }
    h.push("gaze_angle_x".into());
    h.push("gaze_angle_y".into());
    for a in ["x", "y"] {
        h.extend((0..56).map(|i| format!("eye_lmk_{a}_{i}")));
    }
    for a in ["X", "Y", "Z"] {
        h.extend((0..56).map(|i| format!("eye_lmk_{a}_{i}")));
    }
    h.extend(pose_columns().iter().map(|s| s.to_string()));
    for a in ["x", "y"] {
        h.extend((0..LANDMARK_COUNT).map(|i| format!("{a}_{i}")));
    }
    for a in ["X", "Y", "Z"] {
        h.extend((0..LANDMARK_COUNT).map(|i| format!("{a}_{i}")));
    }
    for p in ["p_scale", "p_rx", "p_ry", "p_rz", "p_tx", "p_ty"] {
        h.push(p.into());
    }
    h.extend((0..34).map(|i| format!("p_{i}")));
    h.extend((0..AU_COUNT).map(au_column));
    h.extend(AU_NAMES.iter().map(|a| format!("{a}_c")));
    h.push("AU28_c".into());
    h
}

/// An OpenFace file our observer can read: with 3D landmarks and at least one used row.
pub fn read_observable(input: &Path) -> anyhow::Result<OpenFaceFile> {
    let file = read_openface(input)?;
    observable(&file)?;
    Ok(file)
}

/// Whether our observer can read `file`: 3D landmarks and at least one used row.
pub fn observable(file: &OpenFaceFile) -> anyhow::Result<()> {
    let input = &file.path;
    if !file.layout.landmarks_3d {
        anyhow::bail!(
            "{}: no 3D landmarks (X_0..Z_67): our observer measures AUs from 3D landmarks; \
             rerun OpenFace with -3Dfp (or without -no3Dfp)",
            input.display()
        );
    }
    if file.rows.is_empty() {
        anyhow::bail!(
            "{}: no row with success = 1 ({} skipped)",
            input.display(),
            file.skipped
        );
    }
    Ok(())
}

/// The used rows' 3D landmarks in our frame (the file's layout has them).
pub fn camera_faces(file: &OpenFaceFile) -> Vec<[V3; LANDMARK_COUNT]> {
    file.rows
        .iter()
        .map(|r| crate::observe::from_camera(r.landmarks_3d.as_ref().expect("3D layout checked")))
        .collect()
}
