//! The inversion table: its CSV and Markdown, and the timings' (kept apart from the results).

use super::{InversionParams, Summary};
use crate::cohort::CohortKind;
use crate::io::rows::{self, num, CsvRow};

/// A line of `inversion.csv` (the deterministic part): the stop measure, converged share and
/// input noise are empty for the network.
#[derive(serde::Serialize, serde::Deserialize)]
struct InversionLine {
    cohort: CohortKind,
    method: String,
    frames: usize,
    #[serde(serialize_with = "num::sci::<6, _>")]
    au_mse: f64,
    #[serde(serialize_with = "num::sci::<6, _>")]
    landmark_rms_iod: f64,
    #[serde(serialize_with = "num::fixed::<2, _>")]
    iterations: f64,
    #[serde(serialize_with = "num::sci_or_empty::<3, _>")]
    stop_measure: Option<f64>,
    #[serde(serialize_with = "num::fixed_or_empty::<3, _>")]
    converged_share: Option<f64>,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    input_au_noise: f64,
}

impl CsvRow for InversionLine {}

/// `cohort,method,frames,au_mse,landmark_rms_iod,iterations,stop_measure,converged_share,
/// input_au_noise`.
pub fn csv(rows: &[Summary]) -> String {
    let lines: Vec<InversionLine> = rows
        .iter()
        .map(|r| InversionLine {
            cohort: r.cohort,
            method: r.method.to_string(),
            frames: r.frames,
            au_mse: r.au_mse,
            landmark_rms_iod: r.landmark_rms,
            iterations: r.iterations,
            stop_measure: r.stop.map(|(m, _)| m),
            converged_share: r.stop.map(|(_, c)| c),
            input_au_noise: r.input_noise,
        })
        .collect();
    rows::to_csv(&lines)
}

/// A line of the timings (they vary from run to run).
#[derive(serde::Serialize, serde::Deserialize)]
struct TimingLine {
    cohort: CohortKind,
    method: String,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    ms_per_frame: f64,
    #[serde(serialize_with = "num::fixed::<4, _>")]
    ms_per_frame_with_solve: f64,
}

impl CsvRow for TimingLine {}

/// Timings: `cohort,method,ms_per_frame,ms_per_frame_with_solve`.
pub fn timing_csv(rows: &[Summary]) -> String {
    let lines: Vec<TimingLine> = rows
        .iter()
        .map(|r| TimingLine {
            cohort: r.cohort,
            method: r.method.to_string(),
            ms_per_frame: r.ms,
            ms_per_frame_with_solve: r.ms_with_solve,
        })
        .collect();
    rows::to_csv(&lines)
}

/// "1st", "2nd", "3rd", "4th", ..., "11th", "12th", "13th", "21st".
pub(super) fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

pub fn markdown(rows: &[Summary], p: &InversionParams, seed: u64) -> String {
    let mut out = String::from("# Inversion: network vs optimization (Choe et al. 2001)\n\n");
    let noise: Vec<String> = CohortKind::ALL
        .iter()
        .filter_map(|&k| rows.iter().find(|r| r.cohort == k))
        .map(|r| format!("{} {:.3}", r.cohort.name().replace('_', " "), r.input_noise))
        .collect();
    out.push_str(&format!(
        "Table 2's cohorts (every image, every {} video frame), network of seed {seed}. Every \
         method reads one detection of each frame: the subject's 68 landmarks with Gaussian \
         noise of {} IOD on every coordinate; the landmark methods take its displacements, the \
         network and the AU fits the observer's reading of it (RMS AU noise this makes, over \
         the frames and AUs: {}). Each method's activations drive the base model (nonlinear \
         solve from the basis prediction), scored against the clean face: AU MSE is over 17 \
         AUs of (clean reading - transferred) / 5, landmark RMS the distance of the solved \
         face's 68 landmarks from the subject's without noise (IOD units, head motion \
         removed). `landmarks_pg` holds the activations in the box by projection; \
         `landmarks_penalty` is Choe et al.'s eq. 10 as published, the linear penalty c D(a) \
         with c = {}, both solved by accelerated proximal gradient to a proximal-gradient norm \
         of 1e-6 relative to |M^T d| (at most 20,000 iterations). Stop: that norm for the \
         landmark fits, the last step's largest activation change for the AU fits (test \
         1e-4, at most 30 Gauss-Newton iterations each); converged: the share of frames that \
         met the test. `aus_refined` adds {} nonlinear corrections. Time per frame is a \
         measurement of the machine, not a result: the run folder's \
         `timings/inversion.md`.\n\n",
        ordinal(p.frame_stride),
        p.landmark_noise_sd,
        noise.join(", "),
        p.penalty,
        p.refinements
    ));
    out.push_str(
        "| cohort | method | frames | AU MSE | landmark RMS (IOD) | iterations | stop | converged |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let (measure, share) = r.stop.map_or(("".to_string(), "".to_string()), |(m, c)| {
            (format!("{m:.1e}"), format!("{:.0}%", 100.0 * c))
        });
        out.push_str(&format!(
            "| {} | {} | {} | {:.4} | {:.4} | {:.1} | {measure} | {share} |\n",
            r.cohort.name().replace('_', " "),
            r.method,
            r.frames,
            r.au_mse,
            r.landmark_rms,
            r.iterations,
        ));
    }
    out
}

/// The time each method took (varies from run to run and machine to machine, so it is kept
/// apart from the results, in the run folder's `timings/`).
pub fn timing_markdown(rows: &[Summary]) -> String {
    let mut out = String::from(
        "# Inversion: time per frame\n\nOne worker; the method alone, then with the nonlinear \
         solve that scores it (release build).\n\n| cohort | method | ms / frame | ms / frame \
         with solve |\n|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {:.3} | {:.1} |\n",
            r.cohort.name().replace('_', " "),
            r.method,
            r.ms,
            r.ms_with_solve
        ));
    }
    out
}
