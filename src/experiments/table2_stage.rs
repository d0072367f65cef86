//! Table 2's stages in a run (cohort -> transfer per seed -> renders) and its reports.
//!
//! Stage keys hash, besides the stage name and version:
//! - `cohort`: the face assets, expression and calibration files, `dataset.subdivisions`,
//!   `dataset.tolerance`, `cohort.*`;
//! - `transfer` (per seed): `table2.normalization` and the keys of the cohort, the seed's
//!   unified network, the dataset (its AU range) and the basis;
//! - `renders`: the first seed's transfer key.

use std::time::Instant;

use anyhow::{Context, Result};
use image::RgbImage;

use super::dataset::Sample;
use super::face::FaceSource;
use super::reader::FaceReader;
use super::realfaces::FileRow;
use super::table2::{
    self, clip_count, clip_ranges, range_map, reference, reference_csv, reference_from_csv,
    to_activations, training_range, transfer, transfers_csv, transfers_from_csv, RefFrame, Row,
    Setting, Transferred,
};
use crate::cache::{self, Cache};
use crate::cohort::{CohortKind, Subject};
use crate::learn::Mlp;
use crate::observe::{Calibration, AU_COUNT, AU_NAMES};
use crate::report::compose::{gif_bytes, labelled_grid, png_bytes};
use crate::report::render::{render, RenderOptions};
use crate::sim::basis::LinearBasis;
use crate::sim::expression::Expression;
use crate::sim::solver::solve_predicted;
use crate::sim::{solve, solve_from_rest, Activations, FaceModel, SolveParams, State, Workspace};
use crate::spec::Spec;
use crate::stats;

// 2: the expressive face and its recalibrated observer (see BASIS_VERSION in run.rs).
// 3: video heads sway about their mean pose (cohort.*.head_motion_deg, head_motion_hz).
const COHORT_VERSION: u32 = 3;
const TRANSFER_VERSION: u32 = 2;
// 3: renders show eyeballs, teeth, brows, lips and the head on a neck.
const RENDERS_VERSION: u32 = 3;

/// What Table 2 needs from the rest of the cell.
pub struct Inputs<'a> {
    pub spec: &'a Spec,
    pub source: &'a FaceSource,
    /// `face=...\ndata=...\n` (asset hashes).
    pub assets: String,
    pub dataset_key: &'a str,
    pub basis_key: Option<&'a str>,
    /// Per seed: the unified network's train key and network.
    pub unified: Vec<(u64, String, &'a Mlp)>,
    pub samples: &'a [Sample],
    pub model: &'a FaceModel,
    pub basis: Option<&'a LinearBasis>,
    pub calibration: &'a Calibration,
}

pub struct Table2Result {
    pub cohort_key: String,
    pub rows: Vec<Row>,
    pub reference: Vec<RefFrame>,
    /// The first seed's transfers, per setting, aligned with `reference`.
    pub first: Vec<(Setting, Vec<Transferred>)>,
    /// Renders: (file name, bytes).
    pub renders: Vec<(String, Vec<u8>)>,
}

type Record<'r> = &'r mut dyn FnMut(&str, &str, bool, Instant);

pub fn run(
    inp: &Inputs,
    cache: &Cache,
    record: Record,
    bar: &dyn Fn(u64, &str) -> indicatif::ProgressBar,
) -> Result<Table2Result> {
    let spec = inp.spec;
    let values = |prefixes: &[&str]| super::run::values_text(spec, prefixes);
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };

    // Cohort: the reference frames.
    let cohort_key = cache::key(
        "cohort",
        COHORT_VERSION,
        &format!(
            "{}{}",
            inp.assets,
            values(&[
                "cohort.",
                "observer.source",
                "dataset.subdivisions",
                "dataset.tolerance",
                "dataset.shear_modulus_fraction"
            ])
        ),
        &[],
    );
    let reader = FaceReader::new(spec.observer_source)?;
    let t = Instant::now();
    let reference_frames = match cache.get("cohort", &cohort_key)? {
        Some(e) => {
            let text = String::from_utf8(e.read("reference.csv")?)?;
            let r = reference_from_csv(&text, &e.path("reference.csv").display().to_string())?;
            record("cohort", &cohort_key, true, t);
            r
        }
        None => {
            let kinds = CohortKind::ALL;
            let progress = bar(clip_count(&spec.cohort, &kinds) as u64, "cohort");
            let tick = || progress.inc(1);
            let r = reference(
                &inp.source.mesh()?,
                inp.source.params(),
                &inp.source.weights()?,
                inp.calibration,
                &reader,
                &spec.cohort,
                &kinds,
                &params,
                &tick,
            )?;
            progress.finish_and_clear();
            cache.put(
                "cohort",
                &cohort_key,
                &[("reference.csv".into(), reference_csv(&r).into_bytes())],
            )?;
            record("cohort", &cohort_key, false, t);
            r
        }
    };

    let observer = reader.observer(inp.model, inp.calibration.clone())?;
    let training: Vec<[f64; AU_COUNT]> = inp.samples.iter().map(|s| s.aus).collect();
    let target = training_range(spec.table2_normalization, &training);
    let clips = clip_ranges(&reference_frames);

    // Transfer, per seed.
    let mut rows = Vec::new();
    let mut first = None;
    let mut first_key = String::new();
    for (seed, train_key, mlp) in &inp.unified {
        let mut inputs = vec![cohort_key.as_str(), train_key.as_str(), inp.dataset_key];
        inputs.extend(inp.basis_key);
        let key = cache::key("transfer", TRANSFER_VERSION, &values(&["table2."]), &inputs);
        let t = Instant::now();
        let transfers = match cache.get("transfer", &key)? {
            Some(e) => {
                let text = String::from_utf8(e.read("transfers.csv")?)?;
                let r = transfers_from_csv(&text, &e.path("transfers.csv").display().to_string())?;
                record("transfer", &key, true, t);
                r
            }
            None => {
                let progress = bar(2 * clips.len() as u64, &format!("transfer {seed}"));
                let tick = || progress.inc(1);
                let mut out = Vec::new();
                for setting in Setting::ALL {
                    let mut frames: Vec<Transferred> = Vec::with_capacity(reference_frames.len());
                    for kind in CohortKind::ALL {
                        let mine: Vec<&std::ops::Range<usize>> = clips
                            .iter()
                            .filter(|r| reference_frames[r.start].cohort == kind)
                            .collect();
                        let aus: Vec<Vec<[f64; AU_COUNT]>> = mine
                            .iter()
                            .map(|r| {
                                reference_frames[(*r).clone()]
                                    .iter()
                                    .map(|f| f.aus)
                                    .collect()
                            })
                            .collect();
                        let all: Vec<[f64; AU_COUNT]> = aus.iter().flatten().copied().collect();
                        let map = (setting == Setting::Normalized)
                            .then(|| range_map(spec.table2_normalization, &all, &target));
                        let t = transfer(
                            inp.model,
                            inp.basis,
                            &reader,
                            &observer,
                            mlp,
                            map.as_ref(),
                            &aus,
                            &params,
                            &tick,
                        )
                        .with_context(|| {
                            format!("Table 2, seed {seed}: {} {}", kind.name(), setting.name())
                        })?;
                        frames.extend(t.into_iter().flatten());
                    }
                    out.push((setting, frames));
                }
                progress.finish_and_clear();
                cache.put(
                    "transfer",
                    &key,
                    &[("transfers.csv".into(), transfers_csv(&out).into_bytes())],
                )?;
                record("transfer", &key, false, t);
                out
            }
        };
        for (setting, frames) in &transfers {
            for kind in CohortKind::ALL {
                let idx: Vec<usize> = (0..reference_frames.len())
                    .filter(|&i| reference_frames[i].cohort == kind)
                    .collect();
                let r: Vec<_> = idx.iter().map(|&i| reference_frames[i].aus).collect();
                let t: Vec<_> = idx.iter().map(|&i| frames[i].aus).collect();
                rows.push(Row {
                    seed: *seed,
                    cohort: kind,
                    setting: *setting,
                    mse: table2::au_mse(&r, &t),
                });
            }
        }
        if first.is_none() {
            first = Some(transfers);
            first_key = key;
        }
    }
    let first = first.context("Table 2 needs at least one seed")?;

    // Renders of the first seed.
    let key = cache::key("renders", RENDERS_VERSION, "", &[&first_key]);
    let t = Instant::now();
    let names = [
        "transfer_grid.png",
        "onset_videos.gif",
        "talking_videos.gif",
    ];
    let renders = match cache.get("renders", &key)? {
        Some(e) => {
            let r = names
                .iter()
                .map(|n| Ok((n.to_string(), e.read(n)?)))
                .collect::<Result<Vec<_>>>()?;
            record("renders", &key, true, t);
            r
        }
        None => {
            let r = renders(inp, &reference_frames, &first, &params)?;
            cache.put("renders", &key, &r)?;
            record("renders", &key, false, t);
            r
        }
    };
    Ok(Table2Result {
        cohort_key,
        rows,
        reference: reference_frames,
        first,
        renders,
    })
}

const CELL: RenderOptions = RenderOptions {
    width: 240,
    height: 280,
    camera: crate::report::render::Camera {
        eye: [0.0, 0.0, 0.62],
        target: [0.0, -0.005, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_degrees: 18.5,
    },
    muscle_overlay: false,
};

/// Solves a sequence of activations on `model` (first from the basis or rest, then warm).
fn states(
    model: &FaceModel,
    basis: Option<&LinearBasis>,
    acts: &[Activations],
    params: &SolveParams,
) -> Result<Vec<State>> {
    let mut ws = Workspace::new(model);
    let mut out: Vec<State> = Vec::with_capacity(acts.len());
    for a in acts {
        let s = match (out.last(), basis) {
            (Some(prev), _) => {
                let mut s = prev.clone();
                solve(model, a, &mut s, &mut ws, params)?;
                s
            }
            (None, Some(b)) => solve_predicted(model, b, a, &mut ws, params)?.0,
            (None, None) => solve_from_rest(model, a, &mut ws, params)?.0,
        };
        out.push(s);
    }
    Ok(out)
}

fn activations_of(values: &[f64]) -> Result<Activations> {
    let v: [f64; crate::sim::CONTROL_COUNT] = values.try_into().context("control count")?;
    Ok(Activations::from_values(&v)?)
}

/// The paper's Fig. 5 (two image subjects, each emotion: subject, unnormalized and normalized
/// transfer) and, per video cohort, a GIF of one clip (subject beside normalized transfer).
fn renders(
    inp: &Inputs,
    reference_frames: &[RefFrame],
    first: &[(Setting, Vec<Transferred>)],
    params: &SolveParams,
) -> Result<Vec<(String, Vec<u8>)>> {
    let mesh = inp.source.mesh()?;
    let weights = inp.source.weights()?;
    let subject = |kind: CohortKind, i: usize| {
        Subject::draw(
            &mesh,
            inp.source.params(),
            &weights,
            &inp.spec.cohort.subjects,
            inp.spec.cohort.seed,
            kind.name(),
            i,
        )
    };
    let model_faces = |idx: &[usize], setting: usize| -> Result<Vec<RgbImage>> {
        let acts: Vec<Activations> = idx
            .iter()
            .map(|&i| to_activations(&first[setting].1[i].activations.map(|v| v as f32)))
            .collect();
        let mut out = Vec::new();
        for a in &acts {
            // Images are independent: each from the basis or rest.
            let s = states(inp.model, inp.basis, std::slice::from_ref(a), params)?;
            out.push(render(inp.model, &s[0], &CELL));
        }
        Ok(out)
    };
    let find = |kind: CohortKind, subject: usize, e: Expression| -> Vec<usize> {
        (0..reference_frames.len())
            .filter(|&i| {
                let f = &reference_frames[i];
                f.cohort == kind && f.subject == subject && f.expression == Some(e)
            })
            .collect()
    };
    let mut out = Vec::new();

    // Fig. 5.
    let images = inp.spec.cohort.images.subjects.min(2);
    let mut cells = Vec::new();
    let mut row_labels = Vec::new();
    for s in 0..images {
        let subj = subject(CohortKind::Images, s)?;
        let idx: Vec<usize> = Expression::ALL
            .iter()
            .flat_map(|&e| find(CohortKind::Images, s, e))
            .collect();
        let mut faces = Vec::new();
        for &i in &idx {
            let a = activations_of(&reference_frames[i].activations)?;
            let st = states(&subj.model, None, std::slice::from_ref(&a), params)?;
            faces.push(render(&subj.model, &st[0], &CELL));
        }
        cells.push(faces);
        row_labels.push(format!("subject {s}"));
        for (k, name) in ["unnormalized", "normalized"].iter().enumerate() {
            cells.push(model_faces(&idx, k)?);
            row_labels.push(format!("model,\n{name}"));
        }
    }
    let columns: Vec<String> = Expression::ALL.iter().map(|e| e.to_string()).collect();
    let grid = labelled_grid(
        "Expression transfer from the image cohort (subject -> model)",
        &cells,
        &row_labels,
        &columns,
    )?;
    out.push(("transfer_grid.png".to_string(), png_bytes(&grid)?));

    // One clip per video cohort: subject 0 (joy for onset, sadness for talking, as the paper's
    // Fig. 6 shows a sad talking subject).
    for (kind, e) in [
        (CohortKind::OnsetVideos, Expression::Joy),
        (CohortKind::TalkingVideos, Expression::Sadness),
    ] {
        let idx = find(kind, 0, e);
        let subj = subject(kind, 0)?;
        let acts: Vec<Activations> = idx
            .iter()
            .map(|&i| activations_of(&reference_frames[i].activations))
            .collect::<Result<_>>()?;
        let reference_states = states(&subj.model, None, &acts, params)?;
        let transferred: Vec<Activations> = idx
            .iter()
            .map(|&i| to_activations(&first[1].1[i].activations.map(|v| v as f32)))
            .collect();
        let transfer_states = states(inp.model, inp.basis, &transferred, params)?;
        let title = format!("{} ({e})", kind.name().replace('_', " "));
        let columns = ["subject 0".to_string(), "model, normalized".to_string()];
        let frames: Vec<RgbImage> = reference_states
            .iter()
            .zip(&transfer_states)
            .map(|(r, t)| {
                let cells = vec![vec![
                    render(&subj.model, r, &CELL),
                    render(inp.model, t, &CELL),
                ]];
                labelled_grid(&title, &cells, &[String::new()], &columns)
            })
            .collect::<Result<_>>()?;
        let delay = (1000.0 / inp.spec.cohort.clip(kind).fps).round() as u32;
        out.push((
            format!("{}.gif", kind.name()),
            gif_bytes(&frames, delay.max(20))?,
        ));
    }
    Ok(out)
}

fn fmt(v: f64) -> String {
    format!("{v:.6e}")
}

fn row_name(kind: CohortKind, setting: Setting) -> String {
    format!("{}-{}", kind.name().replace('_', "-"), setting.name())
}

/// Rows in table order: each cohort, unnormalized then normalized.
fn order() -> Vec<(CohortKind, Setting)> {
    CohortKind::ALL
        .iter()
        .flat_map(|&k| Setting::ALL.iter().map(move |&s| (k, s)))
        .collect()
}

/// One table row over seeds: per AU then the mean over 17, the mean over seeds and the 95%
/// interval.
struct Summary {
    key: (CohortKind, Setting),
    mean: Vec<f64>,
    ci: Vec<f64>,
}

/// Mean and 95% interval over seeds of each of the 17 AUs' MSE and of their mean, from one
/// table row's per-seed MSEs.
fn over_seeds(per_seed: &[&[f64; AU_COUNT]]) -> (Vec<f64>, Vec<f64>) {
    let col = |j: usize| -> Vec<f64> {
        per_seed
            .iter()
            .map(|m| {
                if j < AU_COUNT {
                    m[j]
                } else {
                    m.iter().sum::<f64>() / AU_COUNT as f64
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
fn summary(rows: &[Row]) -> Vec<Summary> {
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
fn real_summary(real: &[FileRow]) -> Vec<(String, Vec<f64>, Vec<f64>)> {
    Setting::ALL
        .iter()
        .filter_map(|&s| {
            let mine: Vec<&FileRow> = real.iter().filter(|r| r.setting == s).collect();
            let first = mine.first()?;
            let mses: Vec<&[f64; AU_COUNT]> = mine.iter().map(|r| &r.mse).collect();
            let (mean, ci) = over_seeds(&mses);
            Some((format!("{}-{}", first.person, s.name()), mean, ci))
        })
        .collect()
}

/// `seed,cohort,setting,AU01..AU45,mean`, per seed, then `mean` and `ci95` rows.
pub fn csv(rows: &[Row]) -> String {
    let mut out = format!("seed,cohort,setting,{},mean\n", AU_NAMES.join(","));
    let line = |label: &str, k: CohortKind, s: Setting, v: &[f64]| {
        format!(
            "{label},{},{},{}\n",
            k.name(),
            s.name(),
            v.iter().map(|x| fmt(*x)).collect::<Vec<_>>().join(",")
        )
    };
    for r in rows {
        let v: Vec<f64> = r.mse.iter().copied().chain([r.mean()]).collect();
        out.push_str(&line(&r.seed.to_string(), r.cohort, r.setting, &v));
    }
    for Summary {
        key: (k, s),
        mean,
        ci,
    } in summary(rows)
    {
        out.push_str(&line("mean", k, s, &mean));
        out.push_str(&line("ci95", k, s, &ci));
    }
    out
}

fn paper_aus() -> Vec<usize> {
    table2::PAPER_AUS
        .iter()
        .map(|a| AU_NAMES.iter().position(|n| n == a).expect("known AU"))
        .collect()
}

/// The paper row that plays the same role, if any.
fn paper_row(k: CohortKind, s: Setting) -> Option<usize> {
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
    let aus = paper_aus();
    out.push_str(&format!(
        "| setting | {} | mean (17) |\n|---|{}---|\n",
        table2::PAPER_AUS.join(" | "),
        "---|".repeat(aus.len())
    ));
    let line = |name: &str, mean: &[f64], ci: &[f64]| {
        let cell = |j: usize| {
            if seeds > 1 {
                format!("{:.3} ± {:.3}", mean[j], ci[j])
            } else {
                format!("{:.3}", mean[j])
            }
        };
        format!(
            "| {name} | {} | {} |\n",
            aus.iter().map(|&j| cell(j)).collect::<Vec<_>>().join(" | "),
            cell(AU_COUNT)
        )
    };
    for Summary {
        key: (k, s),
        mean,
        ci,
    } in summary(rows)
    {
        out.push_str(&line(&row_name(k, s), &mean, &ci));
        if let Some(p) = paper_row(k, s) {
            let (name, v, m) = &table2::PAPER[p];
            out.push_str(&format!(
                "| *Zeng et al.: {name}* | {} | *{m:.3}* |\n",
                v.iter()
                    .map(|x| format!("*{x:.3}*"))
                    .collect::<Vec<_>>()
                    .join(" | ")
            ));
        }
    }
    for (name, mean, ci) in real_summary(real) {
        out.push_str(&line(&name, &mean, &ci));
    }
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

pub fn tex(rows: &[Row], real: &[FileRow]) -> String {
    let aus = paper_aus();
    let mut out = String::from(
        "% Table 2: AU MSE of transferred expressions (facelab; paper rows in italics)\n",
    );
    out.push_str(&format!(
        "\\begin{{tabular}}{{l{}}}\n\\hline\nSetting & {} & Average \\\\\n\\hline\n",
        "r".repeat(aus.len() + 1),
        table2::PAPER_AUS
            .iter()
            .map(|a| format!("MSE$_{{\\mathrm{{{a}}}}}$"))
            .collect::<Vec<_>>()
            .join(" & ")
    ));
    for Summary {
        key: (k, s), mean, ..
    } in summary(rows)
    {
        out.push_str(&format!(
            "{} & {} & {:.3} \\\\\n",
            row_name(k, s),
            aus.iter()
                .map(|&j| format!("{:.3}", mean[j]))
                .collect::<Vec<_>>()
                .join(" & "),
            mean[AU_COUNT]
        ));
        if let Some(p) = paper_row(k, s) {
            let (name, v, m) = &table2::PAPER[p];
            out.push_str(&format!(
                "\\textit{{{name}}} & {} & \\textit{{{m:.3}}} \\\\\n",
                v.iter()
                    .map(|x| format!("\\textit{{{x:.3}}}"))
                    .collect::<Vec<_>>()
                    .join(" & ")
            ));
        }
    }
    for (name, mean, _) in real_summary(real) {
        out.push_str(&format!(
            "{name} & {} & {:.3} \\\\\n",
            aus.iter()
                .map(|&j| format!("{:.3}", mean[j]))
                .collect::<Vec<_>>()
                .join(" & "),
            mean[AU_COUNT]
        ));
    }
    out.push_str("\\hline\n\\end{tabular}\n");
    out
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

/// The transfer's per-frame data for the first seed: reference and transferred AUs per setting.
pub fn frames_csv(reference: &[RefFrame], first: &[(Setting, Vec<Transferred>)]) -> String {
    let mut out = String::from("cohort,subject,expression,frame");
    for a in AU_NAMES {
        out.push_str(&format!(",ref_{a}"));
    }
    for (s, _) in first {
        for a in AU_NAMES {
            out.push_str(&format!(",{}_{a}", s.name()));
        }
    }
    out.push('\n');
    for (i, f) in reference.iter().enumerate() {
        out.push_str(&format!(
            "{},{},{},{}",
            f.cohort.name(),
            f.subject,
            f.expression.map_or("neutral", |e| e.name()),
            f.frame
        ));
        for v in &f.aus {
            out.push_str(&format!(",{v:.4}"));
        }
        for (_, t) in first {
            for v in &t[i].aus {
                out.push_str(&format!(",{v:.4}"));
            }
        }
        out.push('\n');
    }
    out
}

/// The mean AU MSE over the 17 AUs and the seeds of one cohort and setting.
fn mean_over_aus(s: &[Summary], kind: CohortKind, setting: Setting) -> f64 {
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
    let mut out = String::from(
        "\n## Table 2: mean AU MSE over 17 AUs (unnormalized / normalized)\n\n| cell |",
    );
    for k in CohortKind::ALL {
        out.push_str(&format!(" {} |", k.name().replace('_', " ")));
    }
    out.push_str(&format!(
        "\n|---|{}\n",
        "---|".repeat(CohortKind::ALL.len())
    ));
    for (name, rows) in cells {
        let s = summary(rows);
        let mean = |k, setting| mean_over_aus(&s, k, setting);
        out.push_str(&format!("| {name} |"));
        for k in CohortKind::ALL {
            out.push_str(&format!(
                " {:.4} / {:.4} |",
                mean(k, Setting::Unnormalized),
                mean(k, Setting::Normalized)
            ));
        }
        out.push('\n');
    }
    out
}
