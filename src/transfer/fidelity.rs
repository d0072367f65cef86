//! The judge in `facelab transfer`: every transferred frame read by MediaPipe's blendshapes
//! (`crate::judge`) beside the input picture's, written as `fidelity.csv` (a row per frame and
//! reading, `<blendshape>_in` and `<blendshape>_out` per score) and `fidelity.md` (per
//! blendshape group: the mean in and out, the mean absolute difference and, over three frames
//! or more, Pearson's r), with one summary line per reading for the terminal.
//!
//! The `mesh` reading is cheap and reads every frame; the `render` reading renders the face
//! and runs the landmarker, so a clip is rendered at most [`RENDER_FRAMES`] times, evenly
//! spread (the first frame always).

use anyhow::Result;

use crate::judge::{agreement, groups, verdict, GroupAgreement, Judge, Reading, GROUPS};
use crate::landmark::{Blendshapes, BLENDSHAPE_NAMES};
use crate::report::render::RenderOptions;
use crate::sim::{FaceModel, State};

/// Most frames of a clip the render reading reads.
pub const RENDER_FRAMES: usize = 60;

/// The judge's readings of a transfer as its frames are solved.
pub struct JudgeFrames {
    judge: Judge,
    options: RenderOptions,
    render_every: usize,
    /// Per reading, per frame: the output's scores (`None`: not read, or no face found).
    render: Vec<Option<Blendshapes>>,
    rendered: Vec<bool>,
    mesh: Vec<Option<Blendshapes>>,
}

/// The judge's readings of one frame ([`JudgeFrames::reading`]).
#[derive(Clone, Debug)]
pub struct FrameReading {
    mesh: Option<Blendshapes>,
    /// `Some` on the frames whose render is read.
    render: Option<Option<Blendshapes>>,
}

/// What the judge found: the files' text and the summary lines.
#[derive(Clone, Debug, PartialEq)]
pub struct Fidelity {
    pub csv: String,
    pub markdown: String,
    pub summary: Vec<String>,
    /// Per reading with an input: its groups' agreement.
    pub agreement: Vec<(Reading, Vec<GroupAgreement>)>,
}

impl JudgeFrames {
    /// For a transfer of `frames` frames, rendered through `options` (the transfer's camera).
    pub fn new(frames: usize, options: RenderOptions) -> Result<JudgeFrames> {
        Ok(JudgeFrames {
            judge: Judge::new()?,
            options,
            render_every: frames.div_ceil(RENDER_FRAMES).max(1),
            render: vec![None; frames],
            rendered: vec![false; frames],
            mesh: vec![None; frames],
        })
    }

    /// The judge's readings of frame `i` (its solved, posed face): the mesh's, and the
    /// render's on every `render_every`th frame. A function of the frame alone, so frames are
    /// read side by side and [`JudgeFrames::store`]d in order.
    pub fn reading(&self, model: &FaceModel, state: &State, i: usize) -> Result<FrameReading> {
        let mesh = self
            .judge
            .face(model, state, &self.options, Reading::Mesh)?;
        let render = if i % self.render_every == 0 {
            Some(
                self.judge
                    .face(model, state, &self.options, Reading::Render)?,
            )
        } else {
            None
        };
        Ok(FrameReading { mesh, render })
    }

    /// Keeps frame `i`'s readings.
    pub fn store(&mut self, i: usize, reading: FrameReading) {
        self.mesh[i] = reading.mesh;
        if let Some(render) = reading.render {
            self.rendered[i] = true;
            self.render[i] = render;
        }
    }

    /// The files and summary, with the input's scores per frame where the input is a
    /// picture (`None` for an OpenFace file: the judge then reads only the output).
    pub fn finish(self, frames: &[i64], input: Option<Vec<Option<Blendshapes>>>) -> Fidelity {
        let mut csv = String::from("frame,reading,success_in,success_out");
        for n in BLENDSHAPE_NAMES {
            csv.push_str(&format!(",{n}_in,{n}_out"));
        }
        csv.push('\n');
        let readings = [
            (Reading::Render, &self.render, Some(&self.rendered)),
            (Reading::Mesh, &self.mesh, None),
        ];
        for (i, frame) in frames.iter().enumerate() {
            for (reading, out, read) in &readings {
                if read.is_some_and(|r| !r[i]) {
                    continue;
                }
                let a = input.as_ref().and_then(|v| v[i]);
                let b = out[i];
                csv.push_str(&format!(
                    "{frame},{},{},{}",
                    reading.name(),
                    if input.is_none() {
                        String::new()
                    } else {
                        u8::from(a.is_some()).to_string()
                    },
                    u8::from(b.is_some())
                ));
                for k in 0..BLENDSHAPE_NAMES.len() {
                    let cell = |s: Option<Blendshapes>| {
                        s.map_or(String::new(), |s| format!("{:.4}", s[k]))
                    };
                    csv.push_str(&format!(",{},{}", cell(a), cell(b)));
                }
                csv.push('\n');
            }
        }

        let mut markdown = String::from(
            "# What MediaPipe's blendshapes read: the input and the transferred face\n\n",
        );
        let mut summary = Vec::new();
        let mut agreements = Vec::new();
        markdown.push_str(&format!(
            "Groups average MediaPipe's left and right scores. `render`: the transferred face \
             rendered and read by the landmarker ({} of {} frames); `mesh`: its vertices \
             projected into the same camera (every frame; at rest this reading shows brow down \
             about 0.3, which the render does not). A group is shown at >= {} and absent below \
             {}.\n\n",
            self.rendered.iter().filter(|r| **r).count(),
            frames.len(),
            crate::judge::SHOWN,
            crate::judge::ABSENT
        ));
        for (reading, out, read) in &readings {
            let keep = |i: usize| read.is_none_or(|r| r[i]);
            let outs: Vec<Option<Blendshapes>> = (0..frames.len())
                .filter(|&i| keep(i))
                .map(|i| out[i])
                .collect();
            let found = outs.iter().filter(|o| o.is_some()).count();
            markdown.push_str(&format!(
                "## {} reading ({found} of {} frames read have a face)\n\n",
                reading.name(),
                outs.len()
            ));
            match &input {
                Some(input) => {
                    let ins: Vec<Option<Blendshapes>> = (0..frames.len())
                        .filter(|&i| keep(i))
                        .map(|i| input[i])
                        .collect();
                    let a = agreement(&ins, &outs);
                    let v = verdict(&a);
                    markdown.push_str(
                        "| group | mean in | mean out | mean abs diff | r |\n|---|---|---|---|---|\n",
                    );
                    for g in &a {
                        markdown.push_str(&format!(
                            "| {} | {:.2} | {:.2} | {:.2} | {} |\n",
                            g.group,
                            g.mean_in,
                            g.mean_out,
                            g.mean_abs_diff,
                            g.r.map_or("-".into(), |r| format!("{r:.2}"))
                        ));
                    }
                    let line = format!(
                        "judge ({}): of {} groups the input shows, {} kept within 0.1 \
                         (mean |diff| {:.2}); {} shown that the input does not show",
                        reading.name(),
                        v.shown,
                        v.kept,
                        v.shown_diff,
                        v.added
                    );
                    markdown.push_str(&format!("\n{line}\n\n"));
                    summary.push(line);
                    agreements.push((*reading, a));
                }
                None => {
                    let mean: Vec<f64> = (0..GROUPS.len())
                        .map(|g| {
                            let v: Vec<f64> = outs.iter().flatten().map(|s| groups(s)[g]).collect();
                            v.iter().sum::<f64>() / v.len().max(1) as f64
                        })
                        .collect();
                    markdown.push_str("| group | mean out |\n|---|---|\n");
                    for ((name, _), m) in GROUPS.iter().zip(&mean) {
                        markdown.push_str(&format!("| {name} | {m:.2} |\n"));
                    }
                    let shown: Vec<String> = GROUPS
                        .iter()
                        .zip(&mean)
                        .filter(|(_, m)| **m >= crate::judge::SHOWN)
                        .map(|((n, _), m)| format!("{n} {m:.2}"))
                        .collect();
                    let line = format!(
                        "judge ({}): an OpenFace file has no picture, so only the output is \
                         read; groups shown: {}",
                        reading.name(),
                        if shown.is_empty() {
                            "none".to_string()
                        } else {
                            shown.join(", ")
                        }
                    );
                    markdown.push_str(&format!("\n{line}\n\n"));
                    summary.push(line);
                }
            }
        }
        Fidelity {
            csv,
            markdown,
            summary,
            agreement: agreements,
        }
    }
}

/// `blendshapes.png` for a clip: MediaPipe's smile, jaw open, eye blink, inner brow up and
/// brow down (left and right averaged) over time, broken at frames without a face.
pub fn blendshape_figure(scores: &[Option<Blendshapes>], fps: f64, name: &str) -> Result<Vec<u8>> {
    let fps = if fps > 0.0 { fps } else { 1.0 };
    let times: Vec<f64> = (0..scores.len()).map(|i| i as f64 / fps).collect();
    let curves: Vec<(String, Vec<Option<f64>>)> = [
        "smile",
        "jaw open",
        "eye blink",
        "inner brow up",
        "brow down",
    ]
    .iter()
    .map(|g| {
        let k = GROUPS
            .iter()
            .position(|(n, _)| n == g)
            .expect("a judge group");
        let v = scores
            .iter()
            .map(|s| s.as_ref().map(|s| groups(s)[k]))
            .collect();
        (g.to_string(), v)
    })
    .collect();
    let image = crate::report::figures::score_curves(
        &format!("MediaPipe's blendshapes of {name} (left and right averaged)"),
        &times,
        &curves,
    )?;
    crate::report::compose::png_bytes(&image)
}
