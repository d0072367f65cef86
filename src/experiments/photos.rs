//! The real-photo table (`tables = ["photos"]`): every committed licensed real picture of
//! `experiments/photos.csv` onto the face by three methods, judged two ways. The methods:
//! `network`, the cell's first unified network on the AUs facelab's observer reads in the
//! picture (against the model's rest face, as `facelab transfer PHOTO` reads one photo);
//! `landmarks`, the landmark-space fit of the inversion table (Choe et al.'s eq. 10 with the
//! box: the activations whose linear-basis face moves the 68 landmarks as the picture's moved
//! from the model's rest face); and `aus`, the AU-space fit of those AUs (with the prior
//! `AU_PRIOR` toward rest); both fits corrected through the nonlinear face, then solved. The judges: facelab's observer
//! reads the transferred face's AUs; MediaPipe's blendshapes (`crate::judge`) read the picture
//! and the transferred face, rendered frontally (`render`) and from its projected vertices
//! (`mesh`). The face is solved without the neck (the expression alone).
//!
//! Writes `photos.csv` into the run folder (per picture, method and reading: the AUs and
//! blendshape groups in and out), `photos.md` into the tables folder, and
//! `figures/photos/<picture>.png`: the picture, cut to the face, beside its three transferred
//! faces (network, landmarks, AUs). Stage key (`photos`): the pictures' and the list's content, and the keys of the
//! first seed's unified network and of the basis.

use crate::io::Layout;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::cache::{self, Entry};
use crate::judge::{
    group_agreement, groups, verdict, Groups, Judge, Reading, ABSENT, GROUPS, GROUP_LABELS, SHOWN,
};
use crate::observe::{landmarks, AU_COUNT, AU_NAMES};
use crate::report::compose::{png_bytes, side_by_side};
use crate::report::render::{render, RenderOptions, RENDER_VERSION};
use crate::run::cell::{spec_calibration, CellRun, Experiment, Plan};
use crate::run::stage::{text, Artifact, Unit};
use crate::sim::basis::LinearBasis;
use crate::sim::{solve_from_rest, SolveParams, Workspace};
use crate::spec::Table;
use crate::transfer::inverter::{flat, Inverter, AU_PRIOR};
use crate::transfer::network::predict_activations;
use crate::transfer::pictures::{
    face_window, landmark_frames, observer_for, read_frames, InputKind, PhotoNeutral,
};

// 1: first version. 2: the landmark-space method beside the network. 3: the landmark fit
// corrected through the nonlinear face (`inversion.refinements` times). 4: the renders' neck
// runs 6.5 cm below the chin onto shoulders. 5: the landmark fit by projected Newton, its
// corrections solved warm at a loosened tolerance. 6: the AU-space fit as a third method.
// (What the renderer draws is in the content: `render::RENDER_VERSION`.)
const PHOTOS_VERSION: u32 = 6;

/// The transfer methods, in table order.
pub const METHODS: [&str; 3] = ["network", "landmarks", "aus"];

/// The list of pictures, relative to the checkout.
pub const PHOTOS_LIST: &str = "experiments/photos.csv";

/// One listed picture.
#[derive(Clone, Debug)]
pub struct Picture {
    pub file: String,
    pub shows: String,
    pub path: PathBuf,
}

impl Picture {
    pub fn stem(&self) -> &str {
        let name = self.file.rsplit('/').next().unwrap_or(&self.file);
        name.rsplit_once('.').map_or(name, |(s, _)| s)
    }
}

/// The pictures of `experiments/photos.csv` (`file,shows,licence`; `#` lines are comments).
pub fn pictures(layout: &Layout) -> Result<Vec<Picture>> {
    let list = layout.file(PHOTOS_LIST);
    let text = std::fs::read_to_string(&list)
        .with_context(|| format!("{}: cannot read", list.display()))?;
    let mut out = Vec::new();
    let mut header = true;
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if header {
            if line.trim() != "file,shows,licence" {
                bail!(
                    "{}:{}: expected the header `file,shows,licence`",
                    list.display(),
                    i + 1
                );
            }
            header = false;
            continue;
        }
        let cells: Vec<&str> = line.splitn(3, ',').collect();
        if cells.len() != 3 || cells[0].is_empty() {
            bail!(
                "{}:{}: expected `file,shows,licence`",
                list.display(),
                i + 1
            );
        }
        out.push(Picture {
            file: cells[0].to_string(),
            shows: cells[1].to_string(),
            path: layout.file(cells[0]),
        });
    }
    if out.is_empty() {
        bail!("{}: lists no picture", list.display());
    }
    Ok(out)
}

/// The list's and every picture's content, as key text.
fn content(layout: &Layout, pictures: &[Picture], refinements: usize) -> Result<String> {
    let list = layout.file(PHOTOS_LIST);
    let mut content = format!(
        "list={}\nrefinements={refinements}\nrenderer={RENDER_VERSION}\n",
        cache::sha256(&std::fs::read(&list).with_context(|| list.display().to_string())?)
    );
    for p in pictures {
        let bytes =
            std::fs::read(&p.path).with_context(|| format!("{}: cannot read", p.path.display()))?;
        content.push_str(&format!("{}={}\n", p.file, cache::sha256(&bytes)));
    }
    Ok(content)
}

fn unit(content: &str, train_key: &str, basis_key: Option<&str>) -> Unit {
    let mut deps = vec![train_key];
    deps.extend(basis_key);
    Unit::new("photos", PHOTOS_VERSION, &content, &deps)
}

/// What the stage keeps: `photos.csv` and one figure per picture.
struct PhotoFiles {
    csv: String,
    figures: Vec<(String, Vec<u8>)>,
}

impl Artifact for PhotoFiles {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        let names: Vec<&str> = self.figures.iter().map(|(n, _)| n.as_str()).collect();
        let mut out = vec![
            ("photos.csv".to_string(), self.csv.clone().into_bytes()),
            ("figures.txt".to_string(), names.join("\n").into_bytes()),
        ];
        out.extend(self.figures.iter().cloned());
        Ok(out)
    }
    fn decode(entry: &Entry) -> Result<Self> {
        let csv = text(entry, "photos.csv")?;
        let mut figures = Vec::new();
        for name in text(entry, "figures.txt")?.lines() {
            figures.push((name.to_string(), entry.read(name)?));
        }
        Ok(PhotoFiles { csv, figures })
    }
}

/// The real-photo table in the registry.
pub(crate) struct Photos;

impl Experiment for Photos {
    fn name(&self) -> &'static str {
        "photos"
    }

    fn table(&self) -> Option<Table> {
        Some(Table::Photos)
    }

    fn first_seed_only(&self) -> bool {
        true
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let layout = &plan.spec.layout;
        let content = content(layout, &pictures(layout)?, plan.spec.inversion.refinements)?;
        let k = plan.keys();
        let Some((_, train_key)) = k.unified().into_iter().next() else {
            bail!("the photo table needs a unified network (table1's training)");
        };
        let u = unit(&content, train_key, k.basis.as_deref());
        plan.add("photos", u);
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let spec = cx.spec;
        let list = pictures(&spec.layout)?;
        let content = content(&spec.layout, &list, spec.inversion.refinements)?;
        let (n, k, model, basis) = (cx.networks()?, cx.keys()?, cx.model()?, cx.basis()?);
        let (_, train_key, mlp) = n
            .unified(&k)
            .into_iter()
            .next()
            .context("the photo table needs a unified network")?;
        let calibration = spec_calibration(spec)?;
        let params = SolveParams {
            tolerance: spec.dataset.tolerance,
            ..SolveParams::default()
        };
        let key = unit(&content, &train_key, k.basis.as_deref());
        let made = cx.stages().get_or_compute(&key, |_| {
            let built;
            let basis = match basis.as_ref() {
                Some(b) => b,
                None => {
                    built = LinearBasis::build(&model, &params)?;
                    &built
                }
            };
            let inverter = Inverter::new(&model, basis, &calibration)?;
            let judge = Judge::new()?;
            let landmarker = judge.landmarker();
            let options = RenderOptions::default();
            let mut ws = Workspace::new(&model)?;
            let mut rows = Vec::new();
            let mut figures = Vec::new();
            for p in &list {
                let (frames, _) = read_frames(&p.path, InputKind::Image)?;
                let l =
                    landmark_frames(landmarker, &model, InputKind::Image, frames, 0.0, &p.file)?;
                let found = &l.found[0];
                let (Some(metric), Some(scores_in)) = (&found.metric, found.blendshapes) else {
                    bail!("{}: no face found", p.file);
                };
                let observer =
                    observer_for(&model, &l.found, PhotoNeutral::Model, calibration.clone())?;
                let points = landmarks(&metric.points);
                let aus_in = observer.observe(&points)?.aus;
                let network = predict_activations(mlp, None, &[aus_in])?.remove(0);
                let d = flat(&inverter.observer.displacements(&points)?);
                let fitted = inverter
                    .landmarks_refined(&d, spec.inversion.refinements, &mut ws, &params)
                    .with_context(|| format!("{}: the landmark fit's face", p.file))?
                    .activations;
                let au_fitted = inverter
                    .aus_refined(
                        &aus_in,
                        AU_PRIOR,
                        spec.inversion.refinements,
                        &mut ws,
                        &params,
                    )
                    .with_context(|| format!("{}: the AU fit's face", p.file))?
                    .activations;
                let mut faces = Vec::new();
                for (method, a) in METHODS.iter().zip([network, fitted, au_fitted]) {
                    let (state, _) = solve_from_rest(&model, &a, &mut ws, &params)
                        .with_context(|| format!("{}: solving the {method} face", p.file))?;
                    let surface = state.surface(model.vertex_count());
                    let aus_out = observer.observe(&landmarks(surface))?.aus;
                    for reading in [Reading::Render, Reading::Mesh] {
                        let out = judge.face(&model, &state, &options, reading)?;
                        rows.push(Row {
                            file: p.file.clone(),
                            method,
                            reading,
                            aus_in,
                            aus_out,
                            groups_in: groups(&scores_in),
                            groups_out: out.as_ref().map(groups),
                        });
                    }
                    faces.push(render(&model, &state, &options));
                }
                let [x, y, w, h] = face_window(&l);
                let frame = &l.frames[0];
                let whole = image::RgbImage::from_raw(
                    frame.width as u32,
                    frame.height as u32,
                    frame.data.clone(),
                )
                .context("an RGB frame's pixels")?;
                let picture = image::imageops::crop_imm(&whole, x, y, w, h).to_image();
                let all = faces
                    .iter()
                    .fold(picture, |row, face| side_by_side(&row, face));
                figures.push((format!("{}.png", p.stem()), png_bytes(&all)?));
            }
            Ok(PhotoFiles {
                csv: csv(&rows),
                figures,
            })
        })?;
        cx.output("photos.csv", made.csv.clone())?;
        let rows = from_csv(&made.csv)?;
        cx.table("photos.md", &markdown(&rows, &list, spec))?;
        if let Some(dir) = cx.figures("photos") {
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
            for (name, bytes) in &made.figures {
                crate::io::atomic::write_atomic(&dir.join(name), bytes)?;
            }
        }
        Ok(())
    }
}

/// One picture read one way.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub file: String,
    pub method: &'static str,
    pub reading: Reading,
    pub aus_in: [f64; AU_COUNT],
    pub aus_out: [f64; AU_COUNT],
    /// MediaPipe's blendshape groups of the picture and of the transferred face (`None`:
    /// no face found in the render), in `judge::GROUPS` order.
    pub groups_in: Groups,
    pub groups_out: Option<Groups>,
}

fn csv(rows: &[Row]) -> String {
    let mut text = String::from("file,method,reading,success_out");
    for a in AU_NAMES {
        text.push_str(&format!(",{a}_in,{a}_out"));
    }
    for g in GROUP_LABELS {
        text.push_str(&format!(",{g}_in,{g}_out"));
    }
    text.push('\n');
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{}",
            r.file,
            r.method,
            r.reading.name(),
            u8::from(r.groups_out.is_some())
        ));
        for k in 0..AU_COUNT {
            text.push_str(&format!(",{:.4},{:.4}", r.aus_in[k], r.aus_out[k]));
        }
        let (gin, gout) = (r.groups_in, r.groups_out);
        for g in 0..GROUPS.len() {
            text.push_str(&format!(
                ",{:.4},{}",
                gin[g],
                gout.map_or(String::new(), |o| format!("{:.4}", o[g]))
            ));
        }
        text.push('\n');
    }
    text
}

/// The rows back from `photos.csv` (groups stand in for the 52 scores: only they are kept).
fn from_csv(text: &str) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let want = 4 + 2 * AU_COUNT + 2 * GROUPS.len();
        if c.len() != want {
            bail!("photos.csv:{}: {} cells, expected {want}", i + 1, c.len());
        }
        let num = |s: &str| -> Result<f64> {
            s.parse()
                .with_context(|| format!("photos.csv:{}: `{s}` is not a number", i + 1))
        };
        let method = METHODS
            .iter()
            .find(|m| **m == c[1])
            .with_context(|| format!("photos.csv:{}: unknown method `{}`", i + 1, c[1]))?;
        let c = &c[1..];
        let reading = match c[1] {
            "render" => Reading::Render,
            "mesh" => Reading::Mesh,
            other => bail!("photos.csv:{}: unknown reading `{other}`", i + 1),
        };
        let mut aus_in = [0.0; AU_COUNT];
        let mut aus_out = [0.0; AU_COUNT];
        for k in 0..AU_COUNT {
            aus_in[k] = num(c[3 + 2 * k])?;
            aus_out[k] = num(c[4 + 2 * k])?;
        }
        let base = 3 + 2 * AU_COUNT;
        let mut groups_in = [0.0; GROUPS.len()];
        let mut groups_out = [0.0; GROUPS.len()];
        for g in 0..GROUPS.len() {
            groups_in[g] = num(c[base + 2 * g])?;
            if c[2] == "1" {
                groups_out[g] = num(c[base + 2 * g + 1])?;
            }
        }
        rows.push(Row {
            file: line.split(',').next().unwrap_or_default().to_string(),
            method,
            reading,
            aus_in,
            aus_out,
            groups_in,
            groups_out: (c[2] == "1").then_some(groups_out),
        });
    }
    Ok(rows)
}

/// An AU at or below this in the picture should stay at or below [`RAISED`] on the face.
const ABSENT_AU: f64 = 0.5;
const RAISED: f64 = 1.0;
/// An AU at or above this in the picture should come out at [`KEPT`] of it or more.
const STRONG: f64 = 2.0;
const KEPT: f64 = 0.7;

/// The AUs a row's picture does not show that its face raises.
fn absent_raised(r: &Row) -> impl Iterator<Item = usize> + '_ {
    (0..AU_COUNT).filter(|&k| r.aus_in[k] <= ABSENT_AU && r.aus_out[k] > RAISED)
}

/// The strong AUs of a row's picture that its face does not keep.
fn strong_lost(r: &Row) -> impl Iterator<Item = usize> + '_ {
    (0..AU_COUNT).filter(|&k| r.aus_in[k] >= STRONG && r.aus_out[k] < KEPT * r.aus_in[k])
}

fn or_none(v: Vec<String>) -> String {
    if v.is_empty() {
        "none".to_string()
    } else {
        v.join("; ")
    }
}

/// `photos.md`: per picture and method, what the judge sees in and out (render reading),
/// facelab's AUs, and a summary per method.
fn markdown(rows: &[Row], list: &[Picture], spec: &crate::spec::Spec) -> String {
    let mut md = format!(
        "# Real pictures through the face (`{}`)\n\n\
         Each committed real picture (`{PHOTOS_LIST}`) goes onto the face (no neck: the \
         expression alone) by three methods: `network`, the spec's first unified network on \
         the AUs facelab's observer reads in the picture against the model's rest face; \
         `landmarks`, the landmark-space fit of the inversion table (the activations whose \
         linear-basis face moves the 68 landmarks as the picture's moved from the model's \
         rest face, within the box), corrected through the nonlinear face (what `facelab \
         transfer PHOTO` does); and `aus`, the AU-space fit (the activations whose face \
         facelab's observer reads as the picture's AUs, with a small prior toward rest), \
         corrected the same way. MediaPipe's blendshapes judge the picture and the transferred face, \
         rendered frontally, in groups of left and right averaged (the reading of the \
         projected vertices, `mesh`, is in the run folder's `photos.csv`). A group is shown at \
         >= {SHOWN} and absent below {ABSENT}; *kept* counts the shown groups the face \
         reproduces within 0.1, *added* the groups the face shows that the picture does not. \
         The last two columns are facelab's own AUs, in and out.\n\n",
        spec.experiment
    );
    md.push_str(
        "| picture | shows | method | groups shown in -> out | kept | added (out) | mean abs diff (shown) | AUs <= 0.5 in, out > 1.0 | AUs >= 2 in, out below 70% |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows.iter().filter(|r| r.reading == Reading::Render) {
        let p = list.iter().find(|p| p.file == r.file);
        let gin = &r.groups_in;
        let (shown, kept, added, diff) = match &r.groups_out {
            Some(out) => {
                let v = verdict(&group_agreement(&[Some(*gin)], &[Some(*out)]));
                let shown: Vec<String> = (0..GROUPS.len())
                    .filter(|&g| gin[g] >= SHOWN)
                    .map(|g| format!("{} {:.2} -> {:.2}", GROUPS[g].0, gin[g], out[g]))
                    .collect();
                let added: Vec<String> = (0..GROUPS.len())
                    .filter(|&g| gin[g] < ABSENT && out[g] >= SHOWN)
                    .map(|g| format!("{} {:.2}", GROUPS[g].0, out[g]))
                    .collect();
                (
                    or_none(shown),
                    format!("{} of {}", v.kept, v.shown),
                    or_none(added),
                    if v.shown == 0 {
                        "-".to_string()
                    } else {
                        format!("{:.2}", v.shown_diff)
                    },
                )
            }
            None => (
                "no face found in the render".into(),
                "-".into(),
                "-".into(),
                "-".into(),
            ),
        };
        let low: Vec<String> = absent_raised(r)
            .map(|k| format!("{} {:.1}", AU_NAMES[k], r.aus_out[k]))
            .collect();
        let strong: Vec<String> = strong_lost(r)
            .map(|k| format!("{} {:.1} -> {:.1}", AU_NAMES[k], r.aus_in[k], r.aus_out[k]))
            .collect();
        md.push_str(&format!(
            "| {} | {} | {} | {shown} | {kept} | {added} | {diff} | {} | {} |\n",
            p.map_or(r.file.as_str(), |p| p.stem()),
            p.map_or("", |p| p.shows.as_str()),
            r.method,
            or_none(low),
            or_none(strong),
        ));
    }
    md.push('\n');
    for method in METHODS {
        let mine: Vec<&Row> = rows
            .iter()
            .filter(|r| r.reading == Reading::Render && r.method == method)
            .collect();
        let (mut shown, mut kept, mut added) = (0, 0, 0);
        let (mut low, mut strong, mut strong_kept) = (0, 0, 0);
        for r in &mine {
            if let Some(out) = &r.groups_out {
                let v = verdict(&group_agreement(&[Some(r.groups_in)], &[Some(*out)]));
                (shown, kept, added) = (shown + v.shown, kept + v.kept, added + v.added);
            }
            low += absent_raised(r).count();
            let all = (0..AU_COUNT).filter(|&k| r.aus_in[k] >= STRONG).count();
            strong += all;
            strong_kept += all - strong_lost(r).count();
        }
        md.push_str(&format!(
            "- `{method}`, over the {} pictures: of the {shown} blendshape groups the pictures \
             show, {kept} kept within 0.1; {added} groups shown that the pictures do not. \
             facelab's AUs: {low} at or below 0.5 in come out above 1.0; {strong_kept} of the \
             {strong} at or above 2 in come out at 70% or more.\n",
            mine.len()
        ));
    }
    md
}
