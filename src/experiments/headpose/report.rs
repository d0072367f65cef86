//! The head-neck experiment's CSV rows: its trajectories, still targets and sequences.

use super::{SequenceRow, StaticRow};
use crate::io::rows::{self, num, CsvRow};

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
