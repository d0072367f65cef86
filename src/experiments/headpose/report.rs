//! The head-neck experiment's report (`paper-tables/headpose.md`) and CSV rows: its trajectories, still targets and sequences, and
//! the tracking runs as the cache keeps them.

use anyhow::{bail, Result};

use super::{Output, SequenceRow, StaticRow};
use crate::cache::Entry;
use crate::headneck::{INPUTS, OUTPUTS, STRAIN_SCALE};
use crate::io::rows::{self, num, CsvRow};
use crate::report::table::{Table, TableRow};
use crate::run::stage::{text, Artifact};
use crate::sim::geom::V3;
use crate::sim::neck::{HeadPose, Trajectory};

/// A line of `headpose_trajectories.csv`: one controller's head at one time of one case
/// (degrees).
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct TrajectoryLine {
    pub(super) controller: String,
    pub(super) case: String,
    #[serde(serialize_with = "num::fixed::<3, _>")]
    pub(super) time: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) target_pitch: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) target_yaw: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) target_roll: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) pose_pitch: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) pose_yaw: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    pub(super) pose_roll: f64,
}

impl CsvRow for TrajectoryLine {}

/// A line of `headpose_static.csv`: one controller reaching one still target (degrees; the
/// settling time empty where the head never settled).
#[derive(serde::Serialize, serde::Deserialize)]
struct StaticLine {
    controller: String,
    #[serde(serialize_with = "num::fixed::<0, _>")]
    target_pitch: f64,
    #[serde(serialize_with = "num::fixed::<0, _>")]
    target_yaw: f64,
    #[serde(serialize_with = "num::fixed::<0, _>")]
    target_roll: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    final_error_deg: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    late_max_error_deg: f64,
    #[serde(serialize_with = "num::fixed_or_empty::<3, _>")]
    settling_time_s: Option<f64>,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    final_pitch: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    final_yaw: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    final_roll: f64,
}

impl CsvRow for StaticLine {}

pub fn static_csv(rows: &[StaticRow]) -> String {
    let lines: Vec<StaticLine> = rows
        .iter()
        .map(|r| {
            let (t, f) = (r.target.degrees(), r.final_pose.degrees());
            StaticLine {
                controller: r.controller.to_string(),
                target_pitch: t[0],
                target_yaw: t[1],
                target_roll: t[2],
                final_error_deg: r.final_error,
                late_max_error_deg: r.late_max_error,
                settling_time_s: r.settling_time,
                final_pitch: f[0],
                final_yaw: f[1],
                final_roll: f[2],
            }
        })
        .collect();
    rows::to_csv(&lines)
}

/// A line of `headpose_sequences.csv`.
#[derive(serde::Serialize, serde::Deserialize)]
struct SequenceLine {
    controller: String,
    sequence: String,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    rms_error_deg: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    max_error_deg: f64,
}

impl CsvRow for SequenceLine {}

pub fn sequences_csv(rows: &[SequenceRow]) -> String {
    let lines: Vec<SequenceLine> = rows
        .iter()
        .map(|r| SequenceLine {
            controller: r.controller.to_string(),
            sequence: r.name.clone(),
            rms_error_deg: r.rms_error,
            max_error_deg: r.max_error,
        })
        .collect();
    rows::to_csv(&lines)
}

/// What the experiment keeps of a simulated run: each sample's time, target, head pose and
/// the skull joint's offset from rest (the figure's face rides on it).
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    pub time: Vec<f64>,
    pub target: Vec<HeadPose>,
    pub pose: Vec<HeadPose>,
    pub skull_offset: Vec<V3>,
}

impl Track {
    pub fn of(t: Trajectory) -> Track {
        Track {
            time: t.time,
            target: t.target,
            pose: t.pose,
            skull_offset: t.skull_offset,
        }
    }
}

/// The tracking runs (controller, case, track), cached as `tracks.csv` with every number in
/// its shortest round-trip form, so the tables and figures made from a cached copy have the
/// same bytes.
pub(super) struct Tracks(pub(super) Vec<(&'static str, String, Track)>);

/// A line of `tracks.csv`: one sample of one run.
#[derive(serde::Serialize, serde::Deserialize)]
struct TrackLine {
    run: usize,
    controller: String,
    case: String,
    #[serde(serialize_with = "num::shortest")]
    time: f64,
    #[serde(with = "num::all")]
    target: [f64; 3],
    #[serde(with = "num::all")]
    pose: [f64; 3],
    #[serde(with = "num::all")]
    skull_offset: [f64; 3],
}

impl CsvRow for TrackLine {
    fn header() -> Vec<String> {
        [
            "run",
            "controller",
            "case",
            "time",
            "target_pitch",
            "target_yaw",
            "target_roll",
            "pose_pitch",
            "pose_yaw",
            "pose_roll",
            "skull_x",
            "skull_y",
            "skull_z",
        ]
        .map(String::from)
        .into()
    }
}

/// The controllers' names as the experiment spells them.
const CONTROLLERS: [&str; 2] = ["teacher", "learned"];

impl Artifact for Tracks {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        let mut lines = Vec::new();
        for (run, (controller, case, t)) in self.0.iter().enumerate() {
            for k in 0..t.time.len() {
                lines.push(TrackLine {
                    run,
                    controller: controller.to_string(),
                    case: case.clone(),
                    time: t.time[k],
                    target: t.target[k].to_array(),
                    pose: t.pose[k].to_array(),
                    skull_offset: t.skull_offset[k],
                });
            }
        }
        Ok(vec![(
            "tracks.csv".into(),
            rows::to_csv(&lines).into_bytes(),
        )])
    }

    fn decode(entry: &Entry) -> Result<Self> {
        let name = entry.path("tracks.csv").display().to_string();
        let mut out: Vec<(usize, &'static str, String, Track)> = Vec::new();
        for l in rows::from_csv::<TrackLine>(&text(entry, "tracks.csv")?, &name)? {
            if out.last().is_none_or(|r| r.0 != l.run) {
                let Some(controller) = CONTROLLERS.into_iter().find(|c| *c == l.controller) else {
                    bail!("{name}: unknown controller `{}`", l.controller);
                };
                let empty = Track {
                    time: Vec::new(),
                    target: Vec::new(),
                    pose: Vec::new(),
                    skull_offset: Vec::new(),
                };
                out.push((l.run, controller, l.case.clone(), empty));
            }
            let t = &mut out.last_mut().expect("pushed above").3;
            t.time.push(l.time);
            t.target.push(HeadPose::from_array(l.target));
            t.pose.push(HeadPose::from_array(l.pose));
            t.skull_offset.push(l.skull_offset);
        }
        Ok(Tracks(
            out.into_iter()
                .map(|(_, c, case, t)| (c, case, t))
                .collect(),
        ))
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or("never".into(), |v| format!("{v:.2}"))
}

/// `paper-tables/headpose.md`.
pub fn markdown(out: &Output, spec: &crate::spec::Spec) -> String {
    let p = &spec.headpose;
    let mut md = String::from("# Head pose control (paper 3.1, 5.3)\n\n");
    md.push_str(&format!(
        "Static targets: every combination of pitch {{-{0}, 0, {0}}}, yaw {{-{1}, 0, {1}}}, roll \
         {{-{2}, 0, {2}}} degrees, each simulated {3} s from the upright rest posture at 4 kHz with \
         the voluntary controller at 25 Hz and the reflex at every step. Final error: mean angle \
         between achieved and target skull orientation over the last 0.25 s. Settling time: when the \
         error last entered the {4}-degree band.\n\n",
        p.range_degrees[0], p.range_degrees[1], p.range_degrees[2], p.duration, p.settle_degrees
    ));
    let mut t = Table::labelled(&[
        "controller",
        "targets",
        "within band at the end",
        "mean final error (deg)",
        "max final error (deg)",
        "mean settling time (s)",
        "max settling time (s)",
    ]);
    for c in ["teacher", "learned"] {
        let rows: Vec<&StaticRow> = out
            .static_rows
            .iter()
            .filter(|r| r.controller == c)
            .collect();
        let n = rows.len().max(1) as f64;
        let within = rows
            .iter()
            .filter(|r| r.late_max_error < p.settle_degrees)
            .count();
        let settled: Vec<f64> = rows.iter().filter_map(|r| r.settling_time).collect();
        let all_settled = settled.len() == rows.len();
        t.push(TableRow::new(vec![
            c.to_string(),
            rows.len().to_string(),
            within.to_string(),
            format!("{:.2}", rows.iter().map(|r| r.final_error).sum::<f64>() / n),
            format!(
                "{:.2}",
                rows.iter().map(|r| r.final_error).fold(0.0, f64::max)
            ),
            format!("{:.2}", crate::stats::mean_or_zero(&settled)),
            if all_settled {
                format!("{:.2}", settled.iter().copied().fold(0.0, f64::max))
            } else {
                "never (some)".into()
            },
        ]));
    }
    md.push_str(&t.markdown());
    md.push_str("\nPer target (learned controller):\n\n");
    let mut t = Table::labelled(&[
        "pitch",
        "yaw",
        "roll",
        "final error (deg)",
        "settling time (s)",
    ]);
    for r in out.static_rows.iter().filter(|r| r.controller == "learned") {
        let d = r.target.degrees();
        t.push(TableRow::new(vec![
            format!("{:.0}", d[0]),
            format!("{:.0}", d[1]),
            format!("{:.0}", d[2]),
            format!("{:.2}", r.final_error),
            opt(r.settling_time),
        ]));
    }
    md.push_str(&t.markdown());
    md.push_str(
        "\nPose sequences (30 fps targets, learned controller; errors after the first 0.5 s):\n\n",
    );
    let mut t = Table::labelled(&["sequence", "RMS error (deg)", "max error (deg)"]);
    for r in &out.sequence_rows {
        t.push(TableRow::new(vec![
            r.name.clone(),
            format!("{:.2}", r.rms_error),
            format!("{:.2}", r.max_error),
        ]));
    }
    md.push_str(&t.markdown());
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    md.push_str(&format!(
        "\nVoluntary network: {} inputs (pose, angular velocity, target) -> {} x {} ReLU -> {} \
         outputs (72 activations, 72 strains x {}, 72 strain rates), Adam lr {}, {} epochs; \
         {} training and {} test pairs from {} equilibrium fits ({} missed by more than 0.5 deg); \
         final train MSE {:.2e}, test MSE {:.2e}.\n",
        INPUTS,
        p.model.layers,
        p.model.width,
        OUTPUTS,
        STRAIN_SCALE,
        p.train.learning_rate,
        p.train.epochs,
        out.pairs.0,
        out.pairs.1,
        p.fit_targets,
        out.missed_fits,
        last(&out.curves.train),
        last(&out.curves.test),
    ));
    md.push_str(&format!(
        "\nSeeds: headpose.seed = {}. Reproduce: `cargo run --release -- run experiments/headpose.toml`.\n",
        p.seed
    ));
    md
}
