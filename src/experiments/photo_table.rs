//! The real-photo table (`tables = ["photos"]`): every committed licensed real picture of
//! `experiments/photos.csv` through the cell's first unified network onto the face, judged two
//! ways. facelab's own observer reads the picture's AUs (against the model's rest face, as
//! `facelab transfer PHOTO` reads one photo) and the transferred face's; MediaPipe's
//! blendshapes (`crate::judge`) read the picture and the transferred face, rendered frontally
//! (`render`) and from its projected vertices (`mesh`). The face is solved without the neck
//! (the expression alone), as a frontal render of `activations.csv` would show it.
//!
//! Writes `photos.csv` into the run folder (per picture and reading: the AUs and blendshape
//! groups in and out), `photos.md` into the tables folder, and `figures/photos/<picture>.png`:
//! the picture, cut to the face, beside the transferred face. Stage key (`photos`): the
//! pictures' and the list's content, and the keys of the first seed's unified network.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::photos::{
    face_window, landmark_frames, observer_for, read_frames, InputKind, PhotoNeutral,
};
use super::table2::predict_activations;
use crate::cache::{self, Entry};
use crate::experiments::cell::{spec_calibration, CellRun, Experiment, Plan};
use crate::experiments::stage::{text, Artifact, Unit};
use crate::judge::{groups, Judge, Reading, ABSENT, GROUPS, GROUP_LABELS, SHOWN};
use crate::landmark::{Blendshapes, Landmarker};
use crate::observe::{landmarks, AU_COUNT, AU_NAMES};
use crate::report::compose::{png_bytes, side_by_side};
use crate::report::render::{render, RenderOptions};
use crate::sim::{solve_from_rest, SolveParams, Workspace};

// 1: first version.
const PHOTOS_VERSION: u32 = 1;

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
pub fn pictures() -> Result<Vec<Picture>> {
    let list = crate::io::data_path(PHOTOS_LIST);
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
            path: crate::io::data_path(cells[0]),
        });
    }
    if out.is_empty() {
        bail!("{}: lists no picture", list.display());
    }
    Ok(out)
}

/// The list's and every picture's content, as key text.
fn content(pictures: &[Picture]) -> Result<String> {
    let list = crate::io::data_path(PHOTOS_LIST);
    let mut content = format!(
        "list={}\n",
        cache::sha256(&std::fs::read(&list).with_context(|| list.display().to_string())?)
    );
    for p in pictures {
        let bytes =
            std::fs::read(&p.path).with_context(|| format!("{}: cannot read", p.path.display()))?;
        content.push_str(&format!("{}={}\n", p.file, cache::sha256(&bytes)));
    }
    Ok(content)
}

fn unit(content: &str, train_key: &str) -> Unit {
    Unit::new("photos", PHOTOS_VERSION, &content, &[train_key])
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

    fn first_seed_only(&self) -> bool {
        true
    }

    fn plan(&self, plan: &mut Plan) -> Result<()> {
        let content = content(&pictures()?)?;
        let k = plan.keys();
        let Some((_, train_key)) = k.unified().into_iter().next() else {
            bail!("the photo table needs a unified network (table1's training)");
        };
        let u = unit(&content, train_key);
        plan.add("photos", u);
        Ok(())
    }

    fn run(&self, cx: &mut CellRun) -> Result<()> {
        let list = pictures()?;
        let content = content(&list)?;
        let spec = cx.spec;
        let (n, k, model) = (cx.networks()?, cx.keys()?, cx.model()?);
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
        let made = cx
            .stages()
            .get_or_compute(&unit(&content, &train_key), |_| {
                let landmarker = Landmarker::new()?;
                let judge = Judge::new()?;
                let options = RenderOptions::default();
                let mut ws = Workspace::new(&model)?;
                let mut rows = Vec::new();
                let mut figures = Vec::new();
                for p in &list {
                    let (frames, _) = read_frames(&p.path, InputKind::Image)?;
                    let l = landmark_frames(
                        &landmarker,
                        &model,
                        InputKind::Image,
                        frames,
                        0.0,
                        &p.file,
                    )?;
                    let found = &l.found[0];
                    let (Some(metric), Some(scores_in)) = (&found.metric, found.blendshapes) else {
                        bail!("{}: no face found", p.file);
                    };
                    let observer =
                        observer_for(&model, &l.found, PhotoNeutral::Model, calibration.clone())?;
                    let aus_in = observer.observe(&landmarks(&metric.points))?.aus;
                    let acts = predict_activations(mlp, None, &[aus_in])?;
                    let (state, _) = solve_from_rest(&model, &acts[0], &mut ws, &params)
                        .with_context(|| format!("{}: solving the transferred face", p.file))?;
                    let surface = state.surface(model.vertex_count());
                    let aus_out = observer.observe(&landmarks(surface))?.aus;
                    for reading in [Reading::Render, Reading::Mesh] {
                        let out = judge.face(&model, &state, &options, reading)?;
                        rows.push(Row {
                            file: p.file.clone(),
                            reading,
                            aus_in,
                            aus_out,
                            blend_in: scores_in,
                            blend_out: out,
                        });
                    }
                    let face = render(&model, &state, &options);
                    let [x, y, w, h] = face_window(&l);
                    let frame = &l.frames[0];
                    let whole = image::RgbImage::from_raw(
                        frame.width as u32,
                        frame.height as u32,
                        frame.data.clone(),
                    )
                    .context("an RGB frame's pixels")?;
                    let picture = image::imageops::crop_imm(&whole, x, y, w, h).to_image();
                    figures.push((
                        format!("{}.png", p.stem()),
                        png_bytes(&side_by_side(&picture, &face))?,
                    ));
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
    pub reading: Reading,
    pub aus_in: [f64; AU_COUNT],
    pub aus_out: [f64; AU_COUNT],
    pub blend_in: Blendshapes,
    pub blend_out: Option<Blendshapes>,
}

fn csv(rows: &[Row]) -> String {
    let mut text = String::from("file,reading,success_out");
    for a in AU_NAMES {
        text.push_str(&format!(",{a}_in,{a}_out"));
    }
    for g in GROUP_LABELS {
        text.push_str(&format!(",{g}_in,{g}_out"));
    }
    text.push('\n');
    for r in rows {
        text.push_str(&format!(
            "{},{},{}",
            r.file,
            r.reading.name(),
            u8::from(r.blend_out.is_some())
        ));
        for k in 0..AU_COUNT {
            text.push_str(&format!(",{:.4},{:.4}", r.aus_in[k], r.aus_out[k]));
        }
        let gin = groups(&r.blend_in);
        let gout = r.blend_out.as_ref().map(groups);
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
        let want = 3 + 2 * AU_COUNT + 2 * GROUPS.len();
        if c.len() != want {
            bail!("photos.csv:{}: {} cells, expected {want}", i + 1, c.len());
        }
        let num = |s: &str| -> Result<f64> {
            s.parse()
                .with_context(|| format!("photos.csv:{}: `{s}` is not a number", i + 1))
        };
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
        // Groups are stored, not the 52 scores: keep them in the first GROUPS slots.
        let base = 3 + 2 * AU_COUNT;
        let mut blend_in = [0.0; 52];
        let mut blend_out = [0.0; 52];
        for g in 0..GROUPS.len() {
            blend_in[g] = num(c[base + 2 * g])?;
            if c[2] == "1" {
                blend_out[g] = num(c[base + 2 * g + 1])?;
            }
        }
        rows.push(Row {
            file: c[0].to_string(),
            reading,
            aus_in,
            aus_out,
            blend_in,
            blend_out: (c[2] == "1").then_some(blend_out),
        });
    }
    Ok(rows)
}

/// `photos.md`: per picture, what the judge sees in and out, and facelab's AUs.
fn markdown(rows: &[Row], list: &[Picture], spec: &crate::spec::Spec) -> String {
    let mut md = format!(
        "# Real pictures through the face (`{}`, its first unified network)\n\n\
         Each committed real picture (`{PHOTOS_LIST}`) is read by facelab's observer against \
         the model's rest face, transferred by the network onto the face (no neck: the \
         expression alone) and read again. MediaPipe's blendshapes judge the picture and the \
         transferred face, rendered frontally (`render`) and from its projected vertices \
         (`mesh`), in groups of left and right averaged. A group is shown at >= {SHOWN} and \
         absent below {ABSENT}; *kept* counts the shown groups the face reproduces within \
         0.1, *added* the groups the face shows that the picture does not.\n\n",
        spec.experiment
    );
    md.push_str(
        "| picture | shows | reading | groups shown in -> out | kept | added (out) | mean abs diff (shown) | AUs <= 0.5 in out > 1.0 | AUs >= 2 in below 70% out |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let p = list.iter().find(|p| p.file == r.file);
        let gin = &r.blend_in[..GROUPS.len()];
        let (shown, kept, added, diff) = match &r.blend_out {
            Some(out) => {
                let gout = &out[..GROUPS.len()];
                let shown: Vec<usize> = (0..GROUPS.len()).filter(|&g| gin[g] >= SHOWN).collect();
                let list: Vec<String> = shown
                    .iter()
                    .map(|&g| format!("{} {:.2} -> {:.2}", GROUPS[g].0, gin[g], gout[g]))
                    .collect();
                let kept = shown
                    .iter()
                    .filter(|&&g| (gin[g] - gout[g]).abs() <= 0.1)
                    .count();
                let added: Vec<String> = (0..GROUPS.len())
                    .filter(|&g| gin[g] < ABSENT && gout[g] >= SHOWN)
                    .map(|g| format!("{} {:.2}", GROUPS[g].0, gout[g]))
                    .collect();
                let diff = if shown.is_empty() {
                    "-".to_string()
                } else {
                    format!(
                        "{:.2}",
                        shown.iter().map(|&g| (gin[g] - gout[g]).abs()).sum::<f64>()
                            / shown.len() as f64
                    )
                };
                (
                    if list.is_empty() {
                        "none".to_string()
                    } else {
                        list.join("; ")
                    },
                    format!("{kept} of {}", shown.len()),
                    if added.is_empty() {
                        "none".to_string()
                    } else {
                        added.join("; ")
                    },
                    diff,
                )
            }
            None => (
                "no face found in the render".into(),
                "-".into(),
                "-".into(),
                "-".into(),
            ),
        };
        let low: Vec<String> = (0..AU_COUNT)
            .filter(|&k| r.aus_in[k] <= 0.5 && r.aus_out[k] > 1.0)
            .map(|k| format!("{} {:.1}", AU_NAMES[k], r.aus_out[k]))
            .collect();
        let strong: Vec<String> = (0..AU_COUNT)
            .filter(|&k| r.aus_in[k] >= 2.0 && r.aus_out[k] < 0.7 * r.aus_in[k])
            .map(|k| format!("{} {:.1} -> {:.1}", AU_NAMES[k], r.aus_in[k], r.aus_out[k]))
            .collect();
        let or_none = |v: Vec<String>| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join("; ")
            }
        };
        md.push_str(&format!(
            "| {} | {} | {} | {shown} | {kept} | {added} | {diff} | {} | {} |\n",
            p.map_or(r.file.as_str(), |p| p.stem()),
            p.map_or("", |p| p.shows.as_str()),
            r.reading.name(),
            or_none(low),
            or_none(strong),
        ));
    }
    let render: Vec<&Row> = rows
        .iter()
        .filter(|r| r.reading == Reading::Render)
        .collect();
    let (mut shown, mut kept, mut added) = (0, 0, 0);
    for r in &render {
        if let Some(out) = &r.blend_out {
            for g in 0..GROUPS.len() {
                let (a, b) = (r.blend_in[g], out[g]);
                if a >= SHOWN {
                    shown += 1;
                    kept += usize::from((a - b).abs() <= 0.1);
                }
                added += usize::from(a < ABSENT && b >= SHOWN);
            }
        }
    }
    md.push_str(&format!(
        "\nOver the {} pictures (render reading): {kept} of the {shown} groups the pictures \
         show are kept within 0.1; the faces show {added} groups the pictures do not.\n",
        render.len()
    ));
    md
}
