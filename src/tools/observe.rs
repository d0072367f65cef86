//! `facelab observe`: the AUs of the simulated face, the AU calibration, and our observer run
//! on a real OpenFace file's 3D landmarks, compared with OpenFace's own AU columns.

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};

use super::face::pose;
use crate::io::calibration::{read_calibration, CalibrationTable};
use crate::io::face::FaceSource;
use crate::io::observer_fit::{read_readout_inputs, read_realdata};
use crate::io::openface::{camera_faces, read_observable, write_openface, FaceRow, OpenFaceFile};
use crate::observe::au::{Calibration, FittedReadout, Observation, Observer};
use crate::observe::features::inputs;
use crate::observe::fit::{fit_readout, leave_one_person_out, PersonFrames};
use crate::observe::{landmarks, median_face, model_observer, AU_COUNT, AU_NAMES, LANDMARK_COUNT};
use crate::sim::geom::V3;
use crate::sim::{Activations, FaceModel, State, Workspace};
use crate::stats::{mean_abs_diff, pearson};

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
    let unit = Calibration::Gains([1.0; AU_COUNT]);
    let observer = model_observer(&model, unit)?;
    let mut ws = Workspace::new(&model)?;
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
    let mut ws = Workspace::new(model)?;
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

/// The neutral face of a file's `faces`.
fn neutral_of(
    file: &OpenFaceFile,
    faces: &[[V3; LANDMARK_COUNT]],
    neutral: Neutral,
) -> Result<[V3; LANDMARK_COUNT]> {
    Ok(match neutral {
        Neutral::Median => median_face(faces),
        Neutral::Frame(frame) => {
            let row = file
                .rows
                .iter()
                .position(|r| r.frame == frame)
                .with_context(|| {
                    format!("{}: no used row with frame {frame}", file.path.display())
                })?;
            faces[row]
        }
    })
}

/// `facelab observe --openface IN --out OUT`.
pub fn observe_openface(
    input: &Path,
    out: &Path,
    neutral: Neutral,
    calibration: Calibration,
) -> Result<Agreement> {
    let file = read_observable(input)?;
    let faces = camera_faces(&file);
    let neutral_face = neutral_of(&file, &faces, neutral)?;
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
        mad[k] = mean_abs_diff(&ours, &theirs);
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

/// One row of the validation report: how well an observer reproduces OpenFace's AU on the
/// frames of `scope` (a held-out person, or `pooled` over all held-out frames).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AgreementRow {
    pub observer: String,
    pub scope: String,
    pub au: String,
    pub frames: usize,
    pub pearson_r: f64,
    pub mae: f64,
}

impl crate::io::rows::CsvRow for AgreementRow {}

/// What `observe --fit` produces.
pub struct ObserverFit {
    /// Fitted on every listed file.
    pub readout: FittedReadout,
    /// Provenance: the files, people, licences and SHA-256 the readout was fitted on.
    pub provenance: Vec<String>,
    /// Leave-one-person-out agreement of the fitted readout, beside that of the gains.
    pub report: Vec<AgreementRow>,
}

fn round4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// Per-AU agreement rows (and a `mean` row over the AUs with a defined r) of `ours` against
/// `theirs`.
fn agreement_rows(
    observer: &str,
    scope: &str,
    ours: &[[f64; AU_COUNT]],
    theirs: &[[f64; AU_COUNT]],
) -> Vec<AgreementRow> {
    let mut rows = Vec::new();
    for (k, au) in AU_NAMES.iter().enumerate() {
        let a: Vec<f64> = ours.iter().map(|r| r[k]).collect();
        let b: Vec<f64> = theirs.iter().map(|r| r[k]).collect();
        rows.push(AgreementRow {
            observer: observer.into(),
            scope: scope.into(),
            au: au.to_string(),
            frames: a.len(),
            pearson_r: round4(pearson(&a, &b)),
            mae: round4(mean_abs_diff(&a, &b)),
        });
    }
    let rs: Vec<f64> = rows
        .iter()
        .map(|r| r.pearson_r)
        .filter(|r| r.is_finite())
        .collect();
    let maes: Vec<f64> = rows.iter().map(|r| r.mae).collect();
    let mae = crate::stats::mean(&maes);
    rows.push(AgreementRow {
        observer: observer.into(),
        scope: scope.into(),
        au: "mean".into(),
        frames: ours.len(),
        pearson_r: round4(crate::stats::mean_or_zero(&rs)),
        mae: round4(mae),
    });
    rows
}

/// `facelab observe --fit`: fits the readout on the real OpenFace files of `list` (paths
/// relative to `root`), each file's neutral face its per-landmark median, and validates it
/// leave-one-person-out against the model-anchored `gains`.
pub fn fit_observer(
    list: &Path,
    root: &Path,
    inputs_path: &Path,
    gains: &Calibration,
) -> Result<ObserverFit> {
    let files = read_realdata(list)?;
    let allowed = read_readout_inputs(inputs_path)?;
    if !root.is_dir() {
        bail!(
            "{}: the real OpenFace files {} lists are not here; pass --data DIR with the \
             folder that holds them (the project's ../shared/realdata)",
            root.display(),
            list.display()
        );
    }
    let mut people: Vec<PersonFrames> = Vec::new();
    let mut before: Vec<Vec<[f64; AU_COUNT]>> = Vec::new();
    let mut provenance = vec![format!(
        "Fitted by `facelab observe --fit` on the real OpenFace files of {} (each file's \
         neutral face is its per-landmark median):",
        list.display()
    )];
    for f in &files {
        let path = root.join(&f.file);
        let bytes =
            std::fs::read(&path).with_context(|| format!("{}: cannot read", path.display()))?;
        let file = read_observable(&path)?;
        let faces = camera_faces(&file);
        let neutral = neutral_of(&file, &faces, Neutral::Median)?;
        let observer = Observer::new(&neutral, gains.clone())
            .with_context(|| format!("{}: neutral face", path.display()))?;
        let k = match people.iter().position(|p| p.person == f.person) {
            Some(k) => k,
            None => {
                people.push(PersonFrames {
                    person: f.person.clone(),
                    inputs: Vec::new(),
                    aus: Vec::new(),
                });
                before.push(Vec::new());
                people.len() - 1
            }
        };
        for (row, face) in file.rows.iter().zip(&faces) {
            let at = || format!("{}:{}", path.display(), row.line);
            let (features, _) = observer.features(face).with_context(at)?;
            people[k].inputs.push(inputs(&features));
            people[k].aus.push(row.aus);
            before[k].push(observer.observe(face).with_context(at)?.aus);
        }
        provenance.push(format!(
            "  {} (person {}, {}, {} frames, {} skipped, sha256 {})",
            f.file.display(),
            f.person,
            f.licence,
            file.rows.len(),
            file.skipped,
            crate::cache::sha256(&bytes)
        ));
    }
    let held_out = leave_one_person_out(&people, &allowed)
        .with_context(|| format!("{}: leave-one-person-out fit", list.display()))?;
    let mut report = Vec::new();
    let all_theirs: Vec<[f64; AU_COUNT]> =
        people.iter().flat_map(|p| p.aus.iter().copied()).collect();
    for (name, ours) in [("gains", &before), ("fitted", &held_out)] {
        let pooled: Vec<[f64; AU_COUNT]> = ours.iter().flatten().copied().collect();
        report.extend(agreement_rows(name, "pooled", &pooled, &all_theirs));
        for (p, o) in people.iter().zip(ours.iter()) {
            report.extend(agreement_rows(name, &p.person, o, &p.aus));
        }
    }
    let x: Vec<_> = people
        .iter()
        .flat_map(|p| p.inputs.iter().copied())
        .collect();
    let readout = fit_readout(&x, &all_theirs, &allowed)
        .with_context(|| format!("{}: fit on every file", list.display()))?;
    let inputs_bytes = std::fs::read(inputs_path)
        .with_context(|| format!("{}: cannot read", inputs_path.display()))?;
    provenance.push(format!(
        "{} frames of {} people; per AU a nonnegative least-squares fit (src/observe/fit.rs, \
         ridge {:e} of the Gram matrix's mean diagonal) on the inputs {} allows it (sha256 \
         {}), stretched so its readings spread like OpenFace's.",
        x.len(),
        people.len(),
        crate::observe::fit::RIDGE,
        inputs_path.display(),
        crate::cache::sha256(&inputs_bytes)
    ));
    Ok(ObserverFit {
        readout,
        provenance,
        report,
    })
}

/// Writes the report as CSV (`observer,scope,au,frames,pearson_r,mae`).
pub fn report_csv(rows: &[AgreementRow]) -> Vec<u8> {
    crate::io::rows::to_csv(rows).into_bytes()
}

/// Prints, per AU, the pooled held-out r and MAE of the gains and of the fitted readout.
pub fn print_fit_summary(rows: &[AgreementRow], out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "leave-one-person-out, pooled over held-out people: pearson r and MAE"
    )?;
    writeln!(out, "au gains_r fitted_r gains_mae fitted_mae")?;
    let pooled = |observer: &str, au: &str| {
        rows.iter()
            .find(|r| r.observer == observer && r.scope == "pooled" && r.au == au)
            .map(|r| (r.pearson_r, r.mae))
            .unwrap_or((f64::NAN, f64::NAN))
    };
    for au in AU_NAMES.iter().copied().chain(["mean"]) {
        let (gr, gm) = pooled("gains", au);
        let (fr, fm) = pooled("fitted", au);
        writeln!(out, "{au} {gr:.3} {fr:.3} {gm:.3} {fm:.3}")?;
    }
    Ok(())
}
