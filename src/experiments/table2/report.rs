//! Table 2's CSVs, markdown and LaTeX tables, per-AU bars and the sweep summary.

use crate::cohort::CohortKind;
use crate::experiments::realfaces::FileRow;
use crate::experiments::table2::{self, RefFrame, Row};
use crate::io::rows::{self, num, CsvRow};
use crate::observe::{AU_COUNT, AU_NAMES};
use crate::report::table::{Table, TableRow};
use crate::spec::Spec;
use crate::stats;
use crate::transfer::network::{Setting, Transferred};
use anyhow::Result;

pub(super) fn row_name(kind: CohortKind, setting: Setting) -> String {
    format!("{}-{}", kind.name().replace('_', "-"), setting.name())
}

/// Rows in table order: each cohort, unnormalized then normalized.
pub(super) fn order() -> Vec<(CohortKind, Setting)> {
    CohortKind::ALL
        .iter()
        .flat_map(|&k| Setting::ALL.iter().map(move |&s| (k, s)))
        .collect()
}

/// One table row over seeds: per AU then the mean over 17, the mean over seeds and the 95%
/// interval.
pub(super) struct Summary {
    pub(super) key: (CohortKind, Setting),
    pub(super) mean: Vec<f64>,
    pub(super) ci: Vec<f64>,
}

/// Mean and 95% interval over seeds of each of the 17 AUs' MSE and of their mean, from one
/// table row's per-seed MSEs.
pub(super) fn over_seeds(per_seed: &[&[f64; AU_COUNT]]) -> (Vec<f64>, Vec<f64>) {
    let col = |j: usize| -> Vec<f64> {
        per_seed
            .iter()
            .map(|m| {
                if j < AU_COUNT {
                    m[j]
                } else {
                    crate::stats::mean(&m[..])
                }
            })
            .collect()
    };
    (
        (0..=AU_COUNT).map(|j| stats::mean(&col(j))).collect(),
        (0..=AU_COUNT).map(|j| stats::ci95(&col(j))).collect(),
    )
}

/// Mean and 95% interval over seeds of each AU's MSE and of the mean, per table row.
pub(super) fn summary(rows: &[Row]) -> Vec<Summary> {
    order()
        .into_iter()
        .map(|(k, s)| {
            let mine: Vec<&[f64; AU_COUNT]> = rows
                .iter()
                .filter(|r| r.cohort == k && r.setting == s)
                .map(|r| &r.mse)
                .collect();
            let (mean, ci) = over_seeds(&mine);
            Summary {
                key: (k, s),
                mean,
                ci,
            }
        })
        .collect()
}

/// The real file's rows (`table2.openface`), unnormalized then normalized: (row name, mean,
/// interval) over seeds.
pub(super) fn real_summary(real: &[FileRow]) -> Vec<(String, Vec<f64>, Vec<f64>)> {
    Setting::ALL
        .iter()
        .filter_map(|&s| {
            let mine: Vec<&FileRow> = real.iter().filter(|r| r.route == s.into()).collect();
            let first = mine.first()?;
            let mses: Vec<&[f64; AU_COUNT]> = mine.iter().map(|r| &r.mse).collect();
            let (mean, ci) = over_seeds(&mses);
            Some((format!("{}-{}", first.person, s.name()), mean, ci))
        })
        .collect()
}

/// A line of `table2.csv`: a seed (or `mean`, `ci95`), a cohort and setting, the 17 AUs' MSE
/// and their mean.
#[derive(serde::Serialize, serde::Deserialize)]
struct Table2Line {
    seed: String,
    cohort: CohortKind,
    setting: Setting,
    #[serde(serialize_with = "num::sci_each::<6, _>")]
    #[serde(deserialize_with = "num::all::deserialize")]
    mse: [f64; AU_COUNT + 1],
}

impl CsvRow for Table2Line {
    fn header() -> Vec<String> {
        let head = ["seed", "cohort", "setting"].into_iter();
        head.chain(AU_NAMES)
            .chain(["mean"])
            .map(String::from)
            .collect()
    }
}

/// `seed,cohort,setting,AU01..AU45,mean`, per seed, then `mean` and `ci95` rows.
pub fn csv(rows: &[Row]) -> String {
    let line = |seed: String, cohort, setting, v: &[f64]| Table2Line {
        seed,
        cohort,
        setting,
        mse: std::array::from_fn(|k| v[k]),
    };
    let mut lines: Vec<Table2Line> = rows
        .iter()
        .map(|r| {
            let v: Vec<f64> = r.mse.iter().copied().chain([r.mean()]).collect();
            line(r.seed.to_string(), r.cohort, r.setting, &v)
        })
        .collect();
    for Summary {
        key: (k, s),
        mean,
        ci,
    } in summary(rows)
    {
        lines.push(line("mean".into(), k, s, &mean));
        lines.push(line("ci95".into(), k, s, &ci));
    }
    rows::to_csv(&lines)
}

pub(super) fn paper_aus() -> Vec<usize> {
    table2::PAPER_AUS
        .iter()
        .map(|a| AU_NAMES.iter().position(|n| n == a).expect("known AU"))
        .collect()
}

/// The paper row that plays the same role, if any.
pub(super) fn paper_row(k: CohortKind, s: Setting) -> Option<usize> {
    match (k, s) {
        (CohortKind::Images, Setting::Unnormalized) => Some(0),
        (CohortKind::Images, Setting::Normalized) => Some(1),
        (CohortKind::TalkingVideos, Setting::Normalized) => Some(2),
        (CohortKind::OnsetVideos, Setting::Normalized) => Some(3),
        _ => None,
    }
}

/// Table 2 in markdown: the cohorts' rows with the paper's under them, then the real file's
/// rows (`real`, from `table2.openface`) when the spec names one.
pub fn markdown(rows: &[Row], spec: &Spec, frames: &[RefFrame], real: &[FileRow]) -> String {
    let seeds = spec.seeds.len();
    let count = |k: CohortKind| frames.iter().filter(|f| f.cohort == k).count();
    let c = &spec.cohort;
    let mut out = String::from("# Table 2: AU MSE of transferred expressions\n\n");
    out.push_str(&format!(
        "Per-AU MSE of (reference - transferred) / 5 over all images or frames of a cohort, \
         for the paper's 8 AUs and the mean over all 17; facelab rows are the mean over {seeds} \
         seed(s) (± 95% interval), each seed a unified network trained on the same dataset. \
         Zeng et al.'s row for the same role is printed under ours. Normalized = each AU mapped \
         ({}) across the cohort onto the training data's per-AU range.\n\n",
        spec.table2_normalization.name()
    ));
    out.push_str(&format!(
        "Cohorts (seed {}): images {} subjects x (neutral + 6 emotions) = {} images; \
         onset videos {} subjects x 6 x {} frames = {}; talking videos {} subjects x 6 x {} \
         frames = {}.\n\n",
        c.seed,
        c.images.subjects,
        count(CohortKind::Images),
        c.onset_videos.subjects,
        c.onset_videos.frames,
        count(CohortKind::OnsetVideos),
        c.talking_videos.subjects,
        c.talking_videos.frames,
        count(CohortKind::TalkingVideos),
    ));
    out.push_str(&table2_table(rows, real, seeds).markdown());
    if let (Some(file), Some(first)) = (&spec.table2_openface, real.first()) {
        out.push_str(&format!(
            "\nReal file: `{file}` ({} frames; {} rows with success = 0 skipped), a real \
             person's OpenFace output transferred through each seed's unified network. Its \
             rows compare OpenFace's AUs in the file with the observer's reading of the \
             transferred face (calibration `{}`{}). Normalized = each AU mapped ({}) across the \
             file's frames onto the training range. Per seed: \
             `results/<experiment>/latest/table2_real.csv`.\n",
            first.frames,
            first.skipped,
            spec.calibration,
            if spec.reads_on_openface_scale() {
                ", the readout fitted to OpenFace: both sides are on OpenFace's scale"
            } else {
                ": the observer's own scale, not OpenFace's"
            },
            spec.table2_normalization.name()
        ));
    }
    out.push_str(
        "\nAll 17 AUs per seed, with means and intervals: `results/<experiment>/latest/table2.csv`.\n",
    );
    out
}

/// Table 2 as one table: per cohort and setting our mean (± 95% interval over seeds) with
/// the paper's row for the same role under it, then the real file's rows.
fn table2_table(rows: &[Row], real: &[FileRow], seeds: usize) -> Table {
    let aus = paper_aus();
    let header = std::iter::once("setting")
        .chain(table2::PAPER_AUS)
        .chain(["mean (17)"])
        .map(String::from)
        .collect();
    let mut t = Table::new(header);
    t.caption =
        Some("Table 2: AU MSE of transferred expressions (facelab; paper rows in italics)".into());
    let line = |name: &str, mean: &[f64], ci: &[f64]| {
        let cell = |j: usize| {
            if seeds > 1 {
                format!("{:.3} ± {:.3}", mean[j], ci[j])
            } else {
                format!("{:.3}", mean[j])
            }
        };
        let cells = aus.iter().map(|&j| cell(j)).chain([cell(AU_COUNT)]);
        TableRow::new(std::iter::once(name.to_string()).chain(cells).collect())
    };
    for Summary {
        key: (k, s),
        mean,
        ci,
    } in summary(rows)
    {
        t.push(line(&row_name(k, s), &mean, &ci));
        if let Some(p) = paper_row(k, s) {
            let (name, v, m) = &table2::PAPER[p];
            let cells = v.iter().chain([m]).map(|x| format!("{x:.3}"));
            let label = format!("Zeng et al.: {name}");
            t.push(TableRow::emphasized(
                std::iter::once(label).chain(cells).collect(),
            ));
        }
    }
    for (name, mean, ci) in real_summary(real) {
        t.push(line(&name, &mean, &ci));
    }
    t
}

pub fn tex(rows: &[Row], real: &[FileRow], seeds: usize) -> String {
    table2_table(rows, real, seeds).latex()
}

/// Per-AU MSE bars for every setting (mean over seeds), all 17 AUs and the mean.
pub fn bars(path: &std::path::Path, rows: &[Row]) -> Result<()> {
    use crate::report::figures::{grouped_bars, PALETTE};
    let categories: Vec<String> = AU_NAMES
        .iter()
        .map(|s| s.to_string())
        .chain(["mean".to_string()])
        .collect();
    let groups: Vec<_> = summary(rows)
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            (
                row_name(r.key.0, r.key.1),
                PALETTE[i % PALETTE.len()],
                r.mean,
            )
        })
        .collect();
    grouped_bars(
        path,
        "Table 2: per-AU MSE of transferred AUs",
        "MSE",
        &categories,
        &groups,
    )
}

/// A line of `table2_frames.csv`: a reference frame, its AUs and the first seed's transferred
/// AUs in each setting.
#[derive(serde::Serialize, serde::Deserialize)]
struct FrameLine {
    cohort: CohortKind,
    subject: usize,
    #[serde(with = "table2::neutral")]
    expression: Option<crate::sim::expression::Expression>,
    frame: usize,
    #[serde(serialize_with = "num::fixed_each::<4, _>")]
    #[serde(deserialize_with = "num::all::deserialize")]
    aus: [f64; 3 * AU_COUNT],
}

impl CsvRow for FrameLine {
    fn header() -> Vec<String> {
        let head = ["cohort", "subject", "expression", "frame"].map(String::from);
        let groups = std::iter::once("ref").chain(Setting::ALL.map(Setting::name));
        head.into_iter()
            .chain(groups.flat_map(|g| AU_NAMES.map(|a| format!("{g}_{a}"))))
            .collect()
    }
}

/// The transfer's per-frame data for the first seed: reference and transferred AUs in both
/// settings (`first` in `Setting::ALL` order, as the transfer stage makes it).
pub fn frames_csv(reference: &[RefFrame], first: &[(Setting, Vec<Transferred>)]) -> String {
    debug_assert!(first.iter().map(|(s, _)| *s).eq(Setting::ALL));
    let lines: Vec<FrameLine> = reference
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let transferred = first.iter().flat_map(|(_, t)| t[i].aus);
            let all: Vec<f64> = f.aus.iter().copied().chain(transferred).collect();
            FrameLine {
                cohort: f.cohort,
                subject: f.subject,
                expression: f.expression,
                frame: f.frame,
                aus: std::array::from_fn(|k| all.get(k).copied().unwrap_or(f64::NAN)),
            }
        })
        .collect();
    rows::to_csv(&lines)
}

/// The mean AU MSE over the 17 AUs and the seeds of one cohort and setting.
pub(super) fn mean_over_aus(s: &[Summary], kind: CohortKind, setting: Setting) -> f64 {
    s.iter()
        .find(|r| r.key == (kind, setting))
        .map_or(f64::NAN, |r| r.mean[AU_COUNT])
}

/// `sweep_table2.png`: each cell's mean AU MSE per cohort and setting, the figure of a sweep
/// over Table 2's keys (whose Table 1 stays the same in every cell).
pub fn sweep_figure(
    dir: &std::path::Path,
    cells: &[(String, Vec<Row>)],
    labels: &[String],
) -> Result<()> {
    use crate::report::figures::{grouped_bars, PALETTE};
    let summaries: Vec<Vec<Summary>> = cells.iter().map(|(_, rows)| summary(rows)).collect();
    let mut groups = Vec::new();
    for (i, k) in CohortKind::ALL.into_iter().enumerate() {
        for (j, setting) in Setting::ALL.into_iter().enumerate() {
            groups.push((
                format!("{}, {}", k.name().replace('_', " "), setting.name()),
                PALETTE[(2 * i + j) % PALETTE.len()],
                summaries
                    .iter()
                    .map(|s| mean_over_aus(s, k, setting))
                    .collect(),
            ));
        }
    }
    grouped_bars(
        &dir.join("sweep_table2.png"),
        "Table 2: mean AU MSE over 17 AUs",
        "AU MSE (mean over seeds)",
        labels,
        &groups,
    )
}

/// Table 2 over a sweep: per cell, each cohort's mean AU MSE (over 17 AUs, mean over seeds)
/// unnormalized and normalized.
pub fn sweep_markdown(cells: &[(String, Vec<Row>)]) -> String {
    let out = "\n## Table 2: mean AU MSE over 17 AUs (unnormalized / normalized)\n\n";
    let kinds = CohortKind::ALL.map(|k| k.name().replace('_', " "));
    let header: Vec<&str> = std::iter::once("cell")
        .chain(kinds.iter().map(String::as_str))
        .collect();
    let mut t = Table::labelled(&header);
    for (name, rows) in cells {
        let s = summary(rows);
        let mean = |k, setting| mean_over_aus(&s, k, setting);
        let means = CohortKind::ALL.map(|k| {
            format!(
                "{:.4} / {:.4}",
                mean(k, Setting::Unnormalized),
                mean(k, Setting::Normalized)
            )
        });
        t.push(TableRow::new(
            std::iter::once(name.clone()).chain(means).collect(),
        ));
    }
    out.to_string() + &t.markdown()
}
