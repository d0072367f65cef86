//! `facelab observe`: the AUs of the simulated face, the AU calibration, and our observer run
//! on a real OpenFace file's 3D landmarks, compared with OpenFace's own AU columns.

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};

use super::face::{pose, FaceSource};
use crate::io::calibration::{read_calibration, CalibrationTable};
use crate::io::openface::{read_openface, write_openface, FaceRow};
use crate::observe::au::{Calibration, Observation, Observer};
use crate::observe::{landmarks, AU_COUNT, AU_NAMES, LANDMARK_COUNT};
use crate::sim::geom::V3;
use crate::sim::{Activations, FaceModel, State, Workspace};

/// The observer of the base model: its rest landmarks are the neutral face.
pub fn model_observer(model: &FaceModel, calibration: Calibration) -> Result<Observer> {
    let rest = model.rest_state();
    Ok(Observer::new(
        &landmarks(rest.surface(model.vertex_count())),
        calibration,
    )?)
}

/// Observes a solved state of `model`.
pub fn observe_state(model: &FaceModel, observer: &Observer, state: &State) -> Result<Observation> {
    Ok(observer.observe(&landmarks(state.surface(model.vertex_count())))?)
}

pub fn load_calibration(path: &Path) -> Result<CalibrationTable> {
    Ok(read_calibration(path)?)
}

/// Recomputes `raw` and `gain` of every row from the model, so each AU's calibration
/// activations read its target; returns the new table (the caller writes it).
pub fn calibrate(source: &FaceSource, table: &CalibrationTable) -> Result<CalibrationTable> {
    let model = source.model()?;
    let unit = Calibration {
        gains: [1.0; AU_COUNT],
    };
    let observer = model_observer(&model, unit)?;
    let mut ws = Workspace::new(&model);
    let mut out = table.clone();
    for k in 0..AU_COUNT {
        let a = table
            .activations(k)
            .map_err(|e| anyhow::anyhow!("{}: {e}", AU_NAMES[k]))?;
        let state = pose(&model, &a, &mut ws)?;
        let (raw, _) = observer.measure(&landmarks(state.surface(model.vertex_count())))?;
        let row = &mut out.rows[k];
        if raw[k].is_nan() || raw[k] <= 1e-6 {
            bail!(
                "{}: its calibration activations move the face by {:.2e} IOD in the wrong \
                 direction or not at all; choose other controls",
                AU_NAMES[k],
                raw[k]
            );
        }
        row.raw = raw[k];
        row.gain = row.target / raw[k];
    }
    Ok(out)
}

/// The AUs and pose of the face for `a`.
pub fn observe_activations(
    model: &FaceModel,
    observer: &Observer,
    a: &Activations,
) -> Result<Observation> {
    let mut ws = Workspace::new(model);
    let state = pose(model, a, &mut ws)?;
    observe_state(model, observer, &state)
}

/// Prints `AUxx value` lines and the pose.
pub fn print_observation(o: &Observation, out: &mut impl Write) -> Result<()> {
    for (name, v) in AU_NAMES.iter().zip(&o.aus) {
        writeln!(out, "{name}_r {v:.2}")?;
    }
    writeln!(out, "pose_Rx {:.3}", o.pose.pitch)?;
    writeln!(out, "pose_Ry {:.3}", o.pose.yaw)?;
    writeln!(out, "pose_Rz {:.3}", o.pose.roll)?;
    Ok(())
}

/// OpenFace's camera frame (+y down, +z away from the camera) to ours (+y up, +z toward it).
pub fn from_camera(p: &[V3; LANDMARK_COUNT]) -> [V3; LANDMARK_COUNT] {
    p.map(|q| [q[0], -q[1], -q[2]])
}

/// Which neutral face `observe --openface` measures against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Neutral {
    /// The per-landmark, per-coordinate median over the file's used rows.
    Median,
    /// The row with this `frame` (or `face`) value.
    Frame(i64),
}

/// Per-AU agreement between our observer and the file's own AU columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Agreement {
    pub rows: usize,
    pub skipped: usize,
    /// Pearson r per AU (NaN where either side is constant).
    pub pearson: [f64; AU_COUNT],
    pub mean_abs_diff: [f64; AU_COUNT],
}

/// The median (NaN for no values); sorts `values`.
pub(crate) fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa == 0.0 || sbb == 0.0 {
        f64::NAN
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// `facelab observe --openface IN --out OUT`.
pub fn observe_openface(
    input: &Path,
    out: &Path,
    neutral: Neutral,
    calibration: Calibration,
) -> Result<Agreement> {
    let file = read_openface(input)?;
    if !file.layout.landmarks_3d {
        bail!(
            "{}: no 3D landmarks (X_0..Z_67): our observer measures AUs from 3D landmarks; \
             rerun OpenFace with -3Dfp (or without -no3Dfp)",
            input.display()
        );
    }
    if file.rows.is_empty() {
        bail!(
            "{}: no row with success = 1 ({} skipped)",
            input.display(),
            file.skipped
        );
    }
    let faces: Vec<[V3; LANDMARK_COUNT]> = file
        .rows
        .iter()
        .map(|r| from_camera(r.landmarks_3d.as_ref().expect("3D layout checked")))
        .collect();
    let neutral_face = match neutral {
        Neutral::Median => std::array::from_fn(|i| {
            std::array::from_fn(|k| {
                let mut v: Vec<f64> = faces.iter().map(|f| f[i][k]).collect();
                median(&mut v)
            })
        }),
        Neutral::Frame(frame) => {
            let row = file
                .rows
                .iter()
                .position(|r| r.frame == frame)
                .with_context(|| format!("{}: no used row with frame {frame}", input.display()))?;
            faces[row]
        }
    };
    let observer = Observer::new(&neutral_face, calibration)
        .with_context(|| format!("{}: neutral face", input.display()))?;
    let mut rows = Vec::with_capacity(file.rows.len());
    for (row, face) in file.rows.iter().zip(&faces) {
        let o = observer
            .observe(face)
            .with_context(|| format!("{}:{}", input.display(), row.line))?;
        rows.push(FaceRow {
            aus: o.aus,
            pose: None,
            landmarks_2d: None,
            landmarks_3d: None,
            ..row.clone()
        });
    }
    write_openface(out, &rows)?;
    let mut pearson_r = [0.0; AU_COUNT];
    let mut mad = [0.0; AU_COUNT];
    for k in 0..AU_COUNT {
        let ours: Vec<f64> = rows.iter().map(|r| r.aus[k]).collect();
        let theirs: Vec<f64> = file.rows.iter().map(|r| r.aus[k]).collect();
        pearson_r[k] = pearson(&ours, &theirs);
        mad[k] = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / ours.len() as f64;
    }
    Ok(Agreement {
        rows: rows.len(),
        skipped: file.skipped,
        pearson: pearson_r,
        mean_abs_diff: mad,
    })
}

pub fn print_agreement(a: &Agreement, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "{} rows observed, {} skipped (success = 0)",
        a.rows, a.skipped
    )?;
    writeln!(out, "au pearson_r mean_abs_diff")?;
    for k in 0..AU_COUNT {
        writeln!(
            out,
            "{} {:.3} {:.3}",
            AU_NAMES[k], a.pearson[k], a.mean_abs_diff[k]
        )?;
    }
    Ok(())
}
