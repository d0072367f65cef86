//! The real-data table (`tables = ["realfaces"]`, DESIGN 2.4): real OpenFace files transferred
//! onto the model through a run's unified network, unnormalized and normalized, and by the
//! AU-space fit (`facelab transfer`'s default for OpenFace files), and scored as
//! Table 2 scores the cohorts: per-AU MSE on the 0-1 scale between OpenFace's AUs in the file
//! and the spec's observer's reading of the transferred face. With the readout fitted to
//! OpenFace (`observer.calibration = "experiments/au_observer_fit.csv"`) both sides are on
//! OpenFace's scale.
//!
//! The files are those of a list (`realfaces.files`, default `experiments/realdata.csv`: file,
//! person, licence) under a data folder (`realfaces.data`, default `../shared/realdata`),
//! which the project does not commit. Stage keys: `realfaces`, per seed, the content of every
//! listed file, `realfaces.frame_stride`, `table2.normalization`, and the keys of the seed's
//! unified network, the dataset (its AU range) and the basis; `realfaces_fit`, once, the
//! content, the stride, `inversion.refinements`, the fit's prior and the dataset's and
//! basis' keys.

use anyhow::{bail, Context, Result};

use crate::cache::{self, Entry};
use crate::dataset::reader::FaceReader;
use crate::experiments::Products;
use crate::transfer::inverter::AU_PRIOR;
use crate::transfer::network::{au_mse, range_map, training_range, transfer, Setting};
use std::rc::Rc;

mod report;
use crate::io::openface::read_openface;
use crate::io::realdata::RealInput;
use crate::io::rows::{self, num, CsvRow};
use crate::learn::Mlp;
use crate::observe::{Observer, AU_COUNT, AU_NAMES};
use crate::run::cell::{spec_calibration, CellRun, Experiment, Plan, Sweep};
use crate::run::stage::{text, Artifact, Stages, Unit};
use crate::sim::basis::LinearBasis;
use crate::sim::{FaceModel, SolveParams};
use crate::spec::Spec;
use crate::spec::Table;
pub use report::{markdown, sweep_markdown};

// 1: first version.
const REALFACES_VERSION: u32 = 1;
// 1: first version.
const REALFACES_FIT_VERSION: u32 = 1;

/// How a file's AUs became activations: the unified network in one of Table 2's settings,
/// or the AU-space fit (`facelab transfer`'s default for OpenFace files), which needs no
/// network. Written as `unnormalized`, `normalized`, `au_fit`.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Route {
    Unnormalized,
    Normalized,
    AuFit,
}

impl Route {
    pub const ALL: [Route; 3] = [Route::Unnormalized, Route::Normalized, Route::AuFit];

    pub fn name(self) -> &'static str {
        match self {
            Route::Unnormalized => "unnormalized",
            Route::Normalized => "normalized",
            Route::AuFit => "au_fit",
        }
    }
}

impl From<Setting> for Route {
    fn from(s: Setting) -> Route {
        match s {
            Setting::Unnormalized => Route::Unnormalized,
            Setting::Normalized => Route::Normalized,
        }
    }
}

/// AU12 at or above this in the file marks a real smile (the smile check).
pub const SMILE_AU12: f64 = 2.5;
/// AU01 and AU02 both at or above this mark a real brow raise.
pub const BROW_RAISE: f64 = 2.0;

/// One file by one route, for one seed (the AU fit's rows carry the first seed: it has no
/// network).
#[derive(Clone, Debug, PartialEq)]
pub struct FileRow {
    pub seed: u64,
    pub file: String,
    pub person: String,
    pub route: Route,
    /// Frames transferred.
    pub frames: usize,
    /// Rows with `success = 0`, skipped.
    pub skipped: usize,
    pub mse: [f64; AU_COUNT],
    /// Frames with AU12 >= `SMILE_AU12` in the file, and the mean |AU12 in - AU12 out| over
    /// them.
    pub smile: (usize, f64),
    /// Frames with AU01 and AU02 >= `BROW_RAISE`, and the mean |AU01 in - out| and
    /// |AU02 in - out| over them.
    pub brow: (usize, f64, f64),
}

impl FileRow {
    pub fn mean(&self) -> f64 {
        crate::stats::mean(&self.mse)
    }
}

/// What the stage needs from the rest of the cell.
pub struct Inputs<'a> {
    pub spec: &'a Spec,
    pub files: &'a [RealInput],
    pub dataset_key: &'a str,
    pub basis_key: Option<&'a str>,
    /// Per seed: the unified network's train key and network.
    pub unified: Vec<(u64, String, &'a Mlp)>,
    pub training_aus: &'a [[f64; AU_COUNT]],
    pub model: &'a FaceModel,
    pub basis: Option<&'a LinearBasis>,
    pub reader: &'a FaceReader,
    pub observer: &'a Observer,
}

/// One seed's rows as `realfaces.csv`.
struct RealRows(String);

impl Artifact for RealRows {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![("realfaces.csv".into(), self.0.clone().into_bytes())])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        Ok(RealRows(text(entry, "realfaces.csv")?))
    }
}

/// A file's used frames (every `stride`-th row with success = 1) and its skipped count.
fn frames_of(input: &RealInput, stride: usize) -> Result<(Vec<[f64; AU_COUNT]>, usize)> {
    let file = read_openface(&input.path)?;
    let rows: Vec<[f64; AU_COUNT]> = file.rows.iter().step_by(stride).map(|r| r.aus).collect();
    if rows.is_empty() {
        bail!(
            "{}: no row with success = 1 ({} skipped)",
            input.path.display(),
            file.skipped
        );
    }
    Ok((rows, file.skipped))
}

fn mean_abs(pairs: impl Iterator<Item = (f64, f64)>) -> (usize, f64) {
    let (n, sum) = pairs.fold((0, 0.0), |(n, s), (a, b)| (n + 1, s + (a - b).abs()));
    (n, if n > 0 { sum / n as f64 } else { f64::NAN })
}

/// What the real files hold, as key text: `file=sha256` per listed file.
pub fn content(files: &[RealInput]) -> Result<String> {
    let mut content = String::new();
    for f in files {
        let bytes =
            std::fs::read(&f.path).with_context(|| format!("{}: cannot read", f.path.display()))?;
        content.push_str(&format!("{}={}\n", f.file, cache::sha256(&bytes)));
    }
    Ok(content)
}

/// One seed's real-data transfer: the files' content, `realfaces.frame_stride`,
/// `table2.normalization`, and the keys of the seed's unified network, the dataset and the
/// basis.
pub fn unit(
    spec: &Spec,
    content: &str,
    train_key: &str,
    dataset_key: &str,
    basis_key: Option<&str>,
) -> Unit {
    let mut deps = vec![train_key, dataset_key];
    deps.extend(basis_key);
    Unit::new(
        "realfaces",
        REALFACES_VERSION,
        &(
            content,
            spec.realfaces.frame_stride,
            spec.table2_normalization,
        ),
        &deps,
    )
}

/// The real-data table in the registry.
pub(crate) struct Realfaces;

/// A cell's real-data rows, for the sweep's summary.
pub(crate) struct RealfacesRows(Vec<FileRow>);

impl Experiment for Realfaces {
    fn name(&self) -> &'static str {
        "realfaces"
    }

    fn table(&self) -> Option<Table> {
        Some(Table::Realfaces)
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        match crate::io::realdata::inputs(&plan.spec.realfaces) {
            Ok(files) => {
                plan_files(plan, "realfaces", &files)?;
                let k = plan.keys();
                let u = fit_unit(plan.spec, &content(&files)?, &k.dataset, k.basis.as_deref());
                plan.add("realfaces au fit", u);
                Ok(())
            }
            Err(e) => {
                plan.waiting("realfaces", e.to_string());
                Ok(())
            }
        }
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let files = crate::io::realdata::inputs(&cx.spec.realfaces)?;
        let mut rows = through_networks(cx, &files)?;
        rows.extend(through_fit(cx, &files)?);
        cx.output("realfaces.csv", csv(&rows))?;
        cx.table("realfaces.md", &markdown(&rows, cx.spec))?;
        Products::of(cx).realfaces = Some(Rc::new(RealfacesRows(rows)));
        Ok(())
    }

    fn sweep(&self, sweep: &mut Sweep) -> Result<()> {
        let cells: Vec<(String, Vec<FileRow>)> = Products::each(sweep, |p| p.realfaces.clone())
            .into_iter()
            .map(|(name, r)| (name, r.0.clone()))
            .collect();
        if !cells.is_empty() {
            sweep.markdown.push_str(&sweep_markdown(&cells));
        }
        Ok(())
    }
}

/// Real OpenFace files through every seed's unified network of the cell (the real-data table,
/// and the committed file Table 2 reports beside its cohorts).
pub(crate) fn through_networks(cx: &mut CellRun, files: &[RealInput]) -> Result<Vec<FileRow>> {
    let spec = cx.spec;
    let (n, k, model, basis) = (cx.networks()?, cx.keys()?, cx.model()?, cx.basis()?);
    let reader = FaceReader::new(spec.observer_source)?;
    let observer = reader.observer(&model, spec_calibration(spec)?)?;
    let training = n.training_aus();
    let inputs = Inputs {
        spec,
        files,
        dataset_key: &k.dataset,
        basis_key: k.basis.as_deref(),
        unified: n.unified(&k),
        training_aus: &training,
        model: &model,
        basis: basis.as_ref().as_ref(),
        reader: &reader,
        observer: &observer,
    };
    run(&inputs, &mut cx.stages())
}

/// The real files through the AU-space fit: the files' content, `realfaces.frame_stride`,
/// `inversion.refinements`, the fit's prior, and the keys of the dataset (face, observer and
/// tolerance) and the basis.
pub fn fit_unit(spec: &Spec, content: &str, dataset_key: &str, basis_key: Option<&str>) -> Unit {
    let mut deps = vec![dataset_key];
    deps.extend(basis_key);
    Unit::new(
        "realfaces_fit",
        REALFACES_FIT_VERSION,
        &(
            content,
            spec.realfaces.frame_stride,
            spec.inversion.refinements,
            AU_PRIOR,
        ),
        &deps,
    )
}

/// Real OpenFace files through the AU-space fit, each frame a function of its own AUs (the
/// frames of a file are fitted in parallel), each face read as the cell reads its faces.
/// The rows carry the first seed.
fn through_fit(cx: &mut CellRun, files: &[RealInput]) -> Result<Vec<FileRow>> {
    let spec = cx.spec;
    let (k, model) = (cx.keys()?, cx.model()?);
    let calibration = spec_calibration(spec)?;
    let reader = FaceReader::new(spec.observer_source)?;
    let observer = reader.observer(&model, calibration.clone())?;
    let content = content(files)?;
    let unit = fit_unit(spec, &content, &k.dataset, k.basis.as_deref());
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };
    let RealRows(text) = cx.stages().get_or_compute(&unit, |stages| {
        let progress = stages.bar(files.len() as u64, "realfaces au fit");
        let mut rows = Vec::new();
        for f in files {
            let (reference, skipped) = frames_of(f, spec.realfaces.frame_stride)?;
            let targets: Vec<Option<[f64; AU_COUNT]>> =
                reference.iter().copied().map(Some).collect();
            let fits = crate::transfer::au_space_fit(spec, &model, &calibration, &targets)
                .with_context(|| format!("{}: the AU fit", f.file))?;
            let mut ws = crate::sim::Workspace::new(&model)?;
            let mut got = Vec::with_capacity(fits.len());
            for (i, fit) in fits.into_iter().enumerate() {
                let fit = fit.expect("every frame has AUs");
                let state = match fit.state {
                    Some(state) => state,
                    None => {
                        crate::sim::solve_from_rest(&model, &fit.activations, &mut ws, &params)
                            .with_context(|| {
                                format!("{}: used frame {}: the AU fit's face", f.file, i + 1)
                            })?
                            .0
                    }
                };
                got.push(observer.observe(&reader.read(&model, &state, None)?)?.aus);
            }
            rows.push(file_row(
                spec.seeds[0],
                f,
                Route::AuFit,
                &reference,
                skipped,
                &got,
            ));
            progress.inc(1);
        }
        progress.finish_and_clear();
        Ok(RealRows(csv(&rows)))
    })?;
    from_csv(&text, "realfaces.csv")
}

/// The units of `files` through every seed's unified network, labelled `label seed N`.
pub(crate) fn plan_files(plan: &mut Plan, label: &str, files: &[RealInput]) -> Result<()> {
    let content = content(files)?;
    let k = plan.keys();
    let units: Vec<(String, Unit)> = k
        .unified()
        .into_iter()
        .map(|(seed, train_key)| {
            let u = unit(
                plan.spec,
                &content,
                train_key,
                &k.dataset,
                k.basis.as_deref(),
            );
            (format!("{label} seed {seed}"), u)
        })
        .collect();
    for (label, u) in units {
        plan.add(label, u);
    }
    Ok(())
}

/// Transfers every file in both settings for every seed (cached per seed).
pub fn run(inp: &Inputs, stages: &mut Stages) -> Result<Vec<FileRow>> {
    let spec = inp.spec;
    let stride = spec.realfaces.frame_stride;
    let mut files = Vec::with_capacity(inp.files.len());
    let content = content(inp.files)?;
    for f in inp.files {
        files.push(frames_of(f, stride)?);
    }
    let kind = spec.table2_normalization;
    let target = training_range(kind, inp.training_aus);
    let maps: Vec<_> = files
        .iter()
        .map(|(rows, _)| range_map(kind, rows, &target))
        .collect();
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };
    let mut out = Vec::new();
    for (seed, train_key, mlp) in &inp.unified {
        let unit = unit(spec, &content, train_key, inp.dataset_key, inp.basis_key);
        let RealRows(text) = stages.get_or_compute(&unit, |stages| {
            // One clip per file and setting; clips run in parallel. The normalized clips
            // carry each file's map already applied (in f32, as the network sees them).
            let mut clips: Vec<Vec<[f64; AU_COUNT]>> = Vec::new();
            for setting in Setting::ALL {
                for ((reference, _), map) in files.iter().zip(&maps) {
                    clips.push(match setting {
                        Setting::Unnormalized => reference.clone(),
                        Setting::Normalized => {
                            let flat: Vec<f32> =
                                reference.iter().flatten().map(|&v| v as f32).collect();
                            map.apply(&flat)
                                .chunks_exact(AU_COUNT)
                                .map(|c| std::array::from_fn(|k| c[k] as f64))
                                .collect()
                        }
                    });
                }
            }
            let progress = stages.bar(clips.len() as u64, "realfaces");
            let tick = || progress.inc(1);
            let transferred = transfer(
                inp.model,
                inp.basis,
                inp.reader,
                inp.observer,
                mlp,
                None,
                &clips,
                &params,
                &tick,
            )
            .with_context(|| format!("transferring the real files (seed {seed})"))?;
            progress.finish_and_clear();
            let mut rows = Vec::new();
            for (ci, frames) in transferred.iter().enumerate() {
                let setting = Setting::ALL[ci / files.len()];
                let i = ci % files.len();
                let (reference, skipped) = &files[i];
                let got: Vec<[f64; AU_COUNT]> = frames.iter().map(|f| f.aus).collect();
                rows.push(file_row(
                    *seed,
                    &inp.files[i],
                    setting.into(),
                    reference,
                    *skipped,
                    &got,
                ));
            }
            Ok(RealRows(csv(&rows)))
        })?;
        out.extend(from_csv(&text, "realfaces.csv")?);
    }
    Ok(out)
}

/// A file's row: its AUs `reference` against the transferred face's `got`.
fn file_row(
    seed: u64,
    input: &RealInput,
    route: Route,
    reference: &[[f64; AU_COUNT]],
    skipped: usize,
    got: &[[f64; AU_COUNT]],
) -> FileRow {
    let raised: Vec<_> = reference
        .iter()
        .zip(got)
        .filter(|(r, _)| r[AU01] >= BROW_RAISE && r[AU02] >= BROW_RAISE)
        .collect();
    FileRow {
        seed,
        file: input.file.clone(),
        person: input.person.clone(),
        route,
        frames: reference.len(),
        skipped,
        mse: au_mse(reference, got),
        smile: mean_abs(
            reference
                .iter()
                .zip(got)
                .filter(|(r, _)| r[AU12] >= SMILE_AU12)
                .map(|(r, g)| (r[AU12], g[AU12])),
        ),
        brow: {
            let (n, a) = mean_abs(raised.iter().map(|(r, g)| (r[AU01], g[AU01])));
            let (_, b) = mean_abs(raised.iter().map(|(r, g)| (r[AU02], g[AU02])));
            (n, a, b)
        },
    }
}

const AU01: usize = 0;
const AU02: usize = 1;
const AU12: usize = 8;

/// A line of the real-data table: one file in one setting for one seed.
#[derive(serde::Serialize, serde::Deserialize)]
struct FileLine {
    seed: u64,
    file: String,
    person: String,
    setting: Route,
    frames: usize,
    skipped: usize,
    #[serde(with = "num::all")]
    mse: [f64; AU_COUNT],
    #[serde(serialize_with = "num::shortest")]
    mean: f64,
    smile_frames: usize,
    #[serde(serialize_with = "num::shortest")]
    smile_au12_error: f64,
    brow_frames: usize,
    #[serde(serialize_with = "num::shortest")]
    brow_au01_error: f64,
    #[serde(serialize_with = "num::shortest")]
    brow_au02_error: f64,
}

impl CsvRow for FileLine {
    fn header() -> Vec<String> {
        let head = ["seed", "file", "person", "setting", "frames", "skipped"];
        let tail = [
            "mean",
            "smile_frames",
            "smile_au12_error",
            "brow_frames",
            "brow_au01_error",
            "brow_au02_error",
        ];
        head.into_iter()
            .chain(AU_NAMES)
            .chain(tail)
            .map(String::from)
            .collect()
    }
}

/// The rows as CSV; numbers in Rust's shortest round-trip form, so reading gives the same bits.
pub fn csv(rows: &[FileRow]) -> String {
    let lines: Vec<FileLine> = rows
        .iter()
        .map(|r| FileLine {
            seed: r.seed,
            file: r.file.clone(),
            person: r.person.clone(),
            setting: r.route,
            frames: r.frames,
            skipped: r.skipped,
            mse: r.mse,
            mean: r.mean(),
            smile_frames: r.smile.0,
            smile_au12_error: r.smile.1,
            brow_frames: r.brow.0,
            brow_au01_error: r.brow.1,
            brow_au02_error: r.brow.2,
        })
        .collect();
    rows::to_csv(&lines)
}

pub fn from_csv(text: &str, name: &str) -> Result<Vec<FileRow>> {
    Ok(rows::from_csv::<FileLine>(text, name)?
        .into_iter()
        .map(|l| FileRow {
            seed: l.seed,
            file: l.file,
            person: l.person,
            route: l.setting,
            frames: l.frames,
            skipped: l.skipped,
            mse: l.mse,
            smile: (l.smile_frames, l.smile_au12_error),
            brow: (l.brow_frames, l.brow_au01_error, l.brow_au02_error),
        })
        .collect())
}
