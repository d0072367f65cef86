//! The face's range of motion (`facelab face reach`) and its validity over everything it can
//! be asked to do (`facelab face sweep`).
//!
//! Reach: each row of `experiments/au_reach.csv` is solved from rest and its landmark motion
//! measured in mm of the model's adult-sized face (the MediaPipe canonical face is life-size:
//! 63 mm between the eye centres), beside the published band and the observer's reading; the
//! muscle-group x AU matrix reads all 17 AUs for every muscle pair (both sides) and jaw input
//! at full activation. Sweep: every single group, every pair of groups and the six
//! expressions at s = 1, each solved from rest and checked by `sim::validity::defects`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde::Serialize;

use crate::io::atomic::write_atomic;
use crate::io::expressions::controls_activations;
use crate::io::face::FaceSource;
use crate::io::observer_fit::read_any_calibration;
use crate::io::reach::{read_reach, Measure, ReachLine, ReachRow};
use crate::io::rows::{self, CsvRow};
use crate::observe::au::{Observer, AU_COUNT, AU_NAMES};
use crate::observe::landmarks;
use crate::observe::model_observer;
use crate::report::figures::heat_map;
use crate::sim::controls::{JAW_ROTATION, JAW_SLIDE, JAW_TWIST};
use crate::sim::expression::Expression;
use crate::sim::geom::{norm, scale, sub, V3};
use crate::sim::muscles::{Side, MUSCLE_PAIRS};
use crate::sim::validity::{defects, Defects};
use crate::sim::{solve_from_rest, Activations, FaceModel, SolveParams, State, Workspace};

/// One measured row of the reach table.
#[derive(Clone, Debug)]
pub struct Reach {
    pub row: ReachRow,
    /// Landmark motion (mm).
    pub displacement_mm: f64,
    /// Mean observer reading of the row's AUs.
    pub observed: f64,
}

impl Reach {
    /// Inside facelab's chosen band where it gives one, else the published band.
    pub fn in_target(&self) -> bool {
        self.row
            .target()
            .is_some_and(|(lo, hi)| (lo..=hi).contains(&self.displacement_mm))
    }
}

fn mean_point(p: &[V3; crate::observe::LANDMARK_COUNT], idx: &[usize]) -> V3 {
    let mut m = [0.0; 3];
    for &i in idx {
        m = crate::sim::geom::add(m, p[i]);
    }
    scale(m, 1.0 / idx.len() as f64)
}

/// The measure of `row` between rest and `now` landmarks (mm).
fn measure_mm(
    measure: &Measure,
    rest: &[V3; crate::observe::LANDMARK_COUNT],
    now: &[V3; crate::observe::LANDMARK_COUNT],
) -> f64 {
    1e3 * match measure {
        Measure::Displacement(idx) => {
            idx.iter().map(|&i| norm(sub(now[i], rest[i]))).sum::<f64>() / idx.len() as f64
        }
        Measure::Separation(a, b) => {
            let gap = |p| norm(sub(mean_point(p, a), mean_point(p, b)));
            gap(now) - gap(rest)
        }
    }
}

/// Solves each activation set from rest, in parallel (one workspace per worker); the results
/// do not depend on the thread count, since every solve starts from rest.
fn solve_all(
    model: &FaceModel,
    cases: &[Activations],
) -> Vec<Result<(State, usize), crate::sim::SolveError>> {
    let params = SolveParams::default();
    cases
        .par_iter()
        .map_init(
            || Workspace::new(model),
            |ws, a| {
                let ws = ws.as_mut().map_err(|e| e.clone())?;
                solve_from_rest(model, a, ws, &params).map(|(s, r)| (s, r.iterations))
            },
        )
        .collect()
}

fn observe(model: &FaceModel, observer: &Observer, state: &State) -> Result<[f64; AU_COUNT]> {
    Ok(observer
        .observe(&landmarks(state.surface(model.vertex_count())))?
        .aus)
}

/// Measures every row of the reach table on `model`.
pub fn reach(model: &FaceModel, observer: &Observer, rows: &[ReachRow]) -> Result<Vec<Reach>> {
    let cases = rows
        .iter()
        .map(|r| {
            controls_activations(&r.controls).map_err(|e| anyhow::anyhow!("row {}: {e}", r.row))
        })
        .collect::<Result<Vec<_>>>()?;
    let rest = landmarks(model.rest_state().surface(model.vertex_count()));
    rows.iter()
        .zip(solve_all(model, &cases))
        .map(|(row, solved)| {
            let (state, _) = solved.with_context(|| format!("solving reach row {}", row.row))?;
            let now = landmarks(state.surface(model.vertex_count()));
            let aus = observe(model, observer, &state)?;
            let observed =
                row.observed.iter().map(|&k| aus[k]).sum::<f64>() / row.observed.len() as f64;
            Ok(Reach {
                row: row.clone(),
                displacement_mm: measure_mm(&row.measure, &rest, &now),
                observed,
            })
        })
        .collect()
}

/// The rows of the muscle-group x AU matrix: each muscle pair on both sides at 1, then the
/// jaw inputs at their extremes (rotation 1, slide 1 and 0, twist 1).
pub fn matrix_cases() -> Vec<(String, Activations)> {
    let mut cases = Vec::new();
    for (pair, def) in MUSCLE_PAIRS.iter().enumerate() {
        let mut a = Activations::neutral();
        for side in [Side::Left, Side::Right] {
            a.set_index(crate::sim::controls::muscle_index(pair, side), 1.0)
                .expect("1 is a valid activation");
        }
        cases.push((def.name.to_string(), a));
    }
    for (name, index, value) in [
        ("jaw_rotation=1", JAW_ROTATION, 1.0),
        ("jaw_slide=1", JAW_SLIDE, 1.0),
        ("jaw_slide=0", JAW_SLIDE, 0.0),
        ("jaw_twist=1", JAW_TWIST, 1.0),
    ] {
        let mut a = Activations::neutral();
        a.set_index(index, value).expect("valid jaw input");
        cases.push((name.to_string(), a));
    }
    cases
}

/// The observer's 17 AUs for every matrix row.
pub fn muscle_au_matrix(
    model: &FaceModel,
    observer: &Observer,
) -> Result<Vec<(String, [f64; AU_COUNT])>> {
    let cases = matrix_cases();
    let activations: Vec<Activations> = cases.iter().map(|(_, a)| a.clone()).collect();
    cases
        .into_iter()
        .zip(solve_all(model, &activations))
        .map(|((name, _), solved)| {
            let (state, _) =
                solved.with_context(|| format!("solving {name} at full activation"))?;
            Ok((name, observe(model, observer, &state)?))
        })
        .collect()
}

fn text(v: f64) -> String {
    format!("{v:.2}")
}

/// `facelab face reach --out DIR`: writes `au_reach.csv`, `muscle_au_matrix.csv` and
/// `muscle_au_matrix.png` into `out`; returns the measured rows and the files written.
pub fn write_reach(
    source: &FaceSource,
    table: &Path,
    calibration: &Path,
    out: &Path,
) -> Result<(Vec<Reach>, Vec<PathBuf>)> {
    let model = source.model()?;
    let rows = read_reach(table)?;
    let observer = model_observer(&model, read_any_calibration(calibration)?)?;
    let measured = reach(&model, &observer, &rows)?;
    let lines: Vec<ReachLine> = measured
        .iter()
        .map(|m| {
            let (lo, hi) = m.row.band.map_or((String::new(), String::new()), |(a, b)| {
                (format!("{a}"), format!("{b}"))
            });
            ReachLine {
                au: m.row.row.clone(),
                controls: m.row.controls_text(),
                landmark: format!("{} (iBUG {})", m.row.landmark, m.row.ibug),
                displacement_mm: text(m.displacement_mm),
                band_min_mm: lo,
                band_max_mm: hi,
                observed: text(m.observed),
            }
        })
        .collect();
    let mut written = Vec::new();
    let reach_path = out.join("au_reach.csv");
    write_atomic(&reach_path, rows::to_csv(&lines).as_bytes())?;
    written.push(reach_path);

    let matrix = muscle_au_matrix(&model, &observer)?;
    let mut csv = String::from("group");
    for au in AU_NAMES {
        csv.push(',');
        csv.push_str(au);
    }
    csv.push('\n');
    for (name, aus) in &matrix {
        csv.push_str(name);
        for v in aus {
            csv.push(',');
            csv.push_str(&text(*v));
        }
        csv.push('\n');
    }
    let matrix_path = out.join("muscle_au_matrix.csv");
    write_atomic(&matrix_path, csv.as_bytes())?;
    written.push(matrix_path);
    let figure = out.join("muscle_au_matrix.png");
    heat_map(
        &figure,
        &format!(
            "Observer AUs (0-5, {}) of each muscle group (both sides) and jaw input at full \
             activation",
            calibration
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        ),
        &matrix.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>(),
        &AU_NAMES.map(String::from),
        &matrix.iter().map(|(_, a)| a.to_vec()).collect::<Vec<_>>(),
        5.0,
    )?;
    written.push(figure);
    Ok((measured, written))
}

/// One solved case of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct SweepLine {
    pub case: String,
    pub kind: String,
    pub converged: bool,
    pub iterations: usize,
    pub inverted_prisms: usize,
    pub folded_triangles: usize,
    pub lip_crossings: usize,
    pub lid_crossings: usize,
    pub min_lip_gap_mm: String,
    pub min_lid_gap_mm: String,
    pub error: String,
}

impl CsvRow for SweepLine {}

impl SweepLine {
    pub fn is_valid(&self) -> bool {
        self.converged
            && self.inverted_prisms == 0
            && self.folded_triangles == 0
            && self.lip_crossings == 0
            && self.lid_crossings == 0
    }
}

/// The sweep's cases: every matrix group alone, every pair of groups, and the six
/// expressions at s = 1 (weights from `source`).
pub fn sweep_cases(source: &FaceSource) -> Result<Vec<(String, &'static str, Activations)>> {
    let groups = matrix_cases();
    let mut cases: Vec<(String, &'static str, Activations)> = groups
        .iter()
        .map(|(n, a)| (n.clone(), "single", a.clone()))
        .collect();
    for i in 0..groups.len() {
        for j in i + 1..groups.len() {
            // Two settings of one jaw input are not a pair.
            let input = |n: &str| n.split('=').next().unwrap_or(n).to_string();
            if input(&groups[i].0) == input(&groups[j].0) {
                continue;
            }
            let (a, b) = (groups[i].1.values(), groups[j].1.values());
            let neutral = Activations::neutral();
            let mut values = *a;
            for k in 0..values.len() {
                if b[k] != neutral.values()[k] {
                    values[k] = b[k];
                }
            }
            let combined = Activations::from_values(&values)?;
            cases.push((format!("{}+{}", groups[i].0, groups[j].0), "pair", combined));
        }
    }
    let weights = source.weights()?;
    for e in Expression::ALL {
        cases.push((e.to_string(), "expression", weights.activations(e, 1.0)));
    }
    Ok(cases)
}

/// Solves and checks every case of `sweep_cases`.
pub fn sweep(model: &FaceModel, source: &FaceSource) -> Result<Vec<SweepLine>> {
    let cases = sweep_cases(source)?;
    let activations: Vec<Activations> = cases.iter().map(|c| c.2.clone()).collect();
    Ok(cases
        .iter()
        .zip(solve_all(model, &activations))
        .map(|((name, kind, _), solved)| {
            let (converged, iterations, d, error) = match solved {
                Ok((state, iterations)) => {
                    (true, iterations, defects(model, &state), String::new())
                }
                Err(e) => (false, 0, Defects::default(), e.to_string()),
            };
            SweepLine {
                case: name.clone(),
                kind: kind.to_string(),
                converged,
                iterations,
                inverted_prisms: d.inverted_prisms,
                folded_triangles: d.folded_triangles,
                lip_crossings: d.lip_crossings,
                lid_crossings: d.lid_crossings,
                min_lip_gap_mm: text(d.min_lip_gap * 1e3),
                min_lid_gap_mm: text(d.min_lid_gap * 1e3),
                error,
            }
        })
        .collect())
}

/// `facelab face sweep --out DIR`: writes `DIR/validity.csv`, returns the lines.
pub fn write_sweep(source: &FaceSource, out: &Path) -> Result<Vec<SweepLine>> {
    let model = source.model()?;
    let lines = sweep(&model, source)?;
    let path = out.join("validity.csv");
    write_atomic(&path, rows::to_csv(&lines).as_bytes())?;
    Ok(lines)
}
