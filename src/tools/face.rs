//! Loading the face, posing it from the command line, rendering it, and the gallery of
//! expressions and single muscles (`facelab render`, `facelab gallery`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::io::atomic::write_atomic;
use crate::io::expressions::controls_activations;
use crate::io::face::FaceSource;
use crate::io::reach::read_reach;
use crate::judge::{groups, Judge, Reading, GROUPS, GROUP_LABELS};
use crate::landmark::{Blendshapes, BLENDSHAPE_NAMES};
use crate::observe::au::AU_NAMES;
use crate::report::compose::contact_sheet;
use crate::report::figures::heat_map_with;
use crate::report::render::{render, Camera, RenderOptions};
use crate::report::save_png;
use crate::sim::controls::{control_names, JAW_ROTATION};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::validity::defects;
use crate::sim::{solve_from_rest, Activations, FaceModel, SolveParams, State, Workspace};

/// What to pose: an expression at a scale, then individual overrides.
#[derive(Clone, Debug, Default)]
pub struct PoseRequest {
    pub expression: Option<Expression>,
    pub scale: f64,
    /// `name=value` pairs, applied after the expression.
    pub activations: Vec<(String, f64)>,
    pub jaw_rotation: Option<f64>,
}

/// Parses `name=value,name=value`.
pub fn parse_assignments(text: &str) -> Result<Vec<(String, f64)>> {
    text.split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|item| {
            let (name, value) = item
                .split_once('=')
                .with_context(|| format!("`{item}` is not of the form name=value"))?;
            let value: f64 = value
                .trim()
                .parse()
                .with_context(|| format!("`{}` in `{item}` is not a number", value.trim()))?;
            Ok((name.trim().to_string(), value))
        })
        .collect()
}

impl PoseRequest {
    pub fn activations(&self, weights: &ExpressionWeights) -> Result<Activations> {
        if !(0.0..=1.0).contains(&self.scale) {
            bail!("--scale {} is outside [0, 1]", self.scale);
        }
        let mut a = match self.expression {
            Some(e) => weights.activations(e, self.scale),
            None => Activations::neutral(),
        };
        for (name, value) in &self.activations {
            a.set(name, *value)?;
        }
        if let Some(r) = self.jaw_rotation {
            a.set_index(JAW_ROTATION, r).context("--jaw-rotation")?;
        }
        Ok(a)
    }
}

/// Solves `a` from rest, with the error saying which activations failed.
pub fn pose(model: &FaceModel, a: &Activations, ws: &mut Workspace) -> Result<State> {
    let (state, _) = solve_from_rest(model, a, ws, &SolveParams::default()).with_context(|| {
        let active: Vec<String> = control_names()
            .iter()
            .zip(a.values())
            .filter(|(name, &v)| {
                v != if name.as_str() == "jaw_slide" || name.as_str() == "jaw_twist" {
                    0.5
                } else {
                    0.0
                }
            })
            .map(|(name, v)| format!("{name}={v}"))
            .collect();
        format!("solving the face for {}", active.join(","))
    })?;
    Ok(state)
}

/// `pose`, refusing a face that folds, inverts an element or pushes the lips or lids through
/// each other (`what` names the case in the error).
pub fn valid_pose(
    model: &FaceModel,
    a: &Activations,
    ws: &mut Workspace,
    what: &str,
) -> Result<State> {
    let state = pose(model, a, ws)?;
    let d = defects(model, &state);
    if !d.is_clean() {
        bail!("{what}: the solved face is not valid: {d}");
    }
    Ok(state)
}

/// Each AU's FACS muscles at full activation (the AU rows of the range-of-motion table;
/// combined actions and second measures of an AU's face, `AU12_width`, are not AUs of their
/// own).
pub fn au_alone_cases(layout: &crate::io::Layout) -> Result<Vec<(String, Activations)>> {
    let mut out = Vec::new();
    for row in read_reach(&layout.reach())? {
        if crate::observe::au::au_index(&row.row).is_none_or(|k| AU_NAMES[k] != row.row) {
            continue;
        }
        let a = controls_activations(&row.controls)
            .map_err(|e| anyhow::anyhow!("reach row {}: {e}", row.row))?;
        out.push((row.row, a));
    }
    Ok(out)
}

/// A line of `judge.csv`: one face, one reading, MediaPipe's 52 scores.
pub struct JudgeLine {
    pub case: String,
    pub reading: Reading,
    pub scores: Option<Blendshapes>,
}

/// `facelab face judge`: what MediaPipe's blendshapes read on the face at rest, the six
/// expressions at s = 1 and each AU's muscles alone, rendered frontally (`render`) and from
/// the projected vertices (`mesh`). Writes `judge.csv` (`case,reading,success` and the 52
/// scores) and `judge.png` (the groups of the render reading as a heat map).
pub fn face_judge(
    layout: &crate::io::Layout,
    source: &FaceSource,
    out: &Path,
) -> Result<(Vec<JudgeLine>, Vec<PathBuf>)> {
    let model = source.model()?;
    let weights = source.weights()?;
    let judge = Judge::new()?;
    let mut ws = Workspace::new(&model)?;
    let mut cases = vec![("rest".to_string(), Activations::neutral())];
    for e in Expression::ALL {
        cases.push((format!("{e} (s = 1)"), weights.activations(e, 1.0)));
    }
    for (au, a) in au_alone_cases(layout)? {
        cases.push((format!("{au} alone"), a));
    }
    let options = RenderOptions::default();
    let mut lines = Vec::new();
    for (case, a) in &cases {
        let state = valid_pose(&model, a, &mut ws, case)?;
        for reading in [Reading::Render, Reading::Mesh] {
            lines.push(JudgeLine {
                case: case.clone(),
                reading,
                scores: judge.face(&model, &state, &options, reading)?,
            });
        }
    }
    let mut text = format!("case,reading,success,{}\n", BLENDSHAPE_NAMES.join(","));
    for l in &lines {
        text.push_str(&format!("{},{},", l.case, l.reading.name()));
        match &l.scores {
            Some(s) => {
                text.push('1');
                for v in s {
                    text.push_str(&format!(",{v:.4}"));
                }
            }
            None => text.push_str(&format!("0{}", ",".repeat(BLENDSHAPE_NAMES.len()))),
        }
        text.push('\n');
    }
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let csv = out.join("judge.csv");
    write_atomic(&csv, text.as_bytes())?;
    let rows: Vec<&JudgeLine> = lines
        .iter()
        .filter(|l| l.reading == Reading::Render)
        .collect();
    let png = out.join("judge.png");
    heat_map_with(
        &png,
        "MediaPipe's blendshapes on facelab's face (render reading; left and right averaged)",
        &rows.iter().map(|l| l.case.clone()).collect::<Vec<_>>(),
        &GROUP_LABELS
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>(),
        &rows
            .iter()
            .map(|l| {
                l.scores
                    .as_ref()
                    .map_or(vec![0.0; GROUPS.len()], |s| groups(s).to_vec())
            })
            .collect::<Vec<_>>(),
        1.0,
        2,
    )?;
    Ok((lines, vec![csv, png]))
}

/// `facelab render`.
pub fn render_to(
    source: &FaceSource,
    request: &PoseRequest,
    options: &RenderOptions,
    out: &Path,
) -> Result<()> {
    let model = source.model()?;
    let weights = source.weights()?;
    let a = request.activations(&weights)?;
    let mut ws = Workspace::new(&model)?;
    let state = pose(&model, &a, &mut ws)?;
    save_png(&render(&model, &state, options), out)
}

/// `facelab gallery`: the rest face, each expression at s = 1 (frontal and three-quarter),
/// each muscle and jaw input alone at 1.0, and a muscle overlay.
pub fn gallery(
    layout: &crate::io::Layout,
    source: &FaceSource,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let model = source.model()?;
    let weights = source.weights()?;
    let mut ws = Workspace::new(&model)?;
    let mut written = Vec::new();
    let mut write = |state: &State, options: &RenderOptions, path: PathBuf| -> Result<()> {
        save_png(&render(&model, state, options), &path)?;
        written.push(path);
        Ok(())
    };
    let frontal = RenderOptions::default();
    let side = RenderOptions {
        camera: Camera::three_quarter(),
        ..frontal
    };
    let small = RenderOptions {
        width: 240,
        height: 280,
        ..frontal
    };
    let rest = model.rest_state();
    write(&rest, &frontal, out.join("rest.png"))?;
    write(&rest, &side, out.join("rest_three_quarter.png"))?;
    // The contact sheet: rest, the six expressions at s = 1, each AU's FACS muscles at full
    // activation (the rows of the range-of-motion table), labelled.
    let mut sheet = vec![("rest".to_string(), render(&model, &rest, &small))];
    for e in Expression::ALL {
        let state = valid_pose(
            &model,
            &weights.activations(e, 1.0),
            &mut ws,
            &e.to_string(),
        )?;
        sheet.push((format!("{e} (s = 1)"), render(&model, &state, &small)));
        write(&state, &frontal, out.join(format!("{e}.png")))?;
        write(&state, &side, out.join(format!("{e}_three_quarter.png")))?;
        if e == Expression::Joy {
            let overlay = RenderOptions {
                muscle_overlay: true,
                ..frontal
            };
            write(&state, &overlay, out.join("joy_muscles.png"))?;
        }
    }
    for (index, name) in control_names().iter().enumerate() {
        if name == "auxiliary" {
            continue;
        }
        let mut a = Activations::neutral();
        a.set_index(index, 1.0)?;
        let state = valid_pose(&model, &a, &mut ws, name)?;
        write(
            &state,
            &small,
            out.join("single").join(format!("{name}.png")),
        )?;
    }
    for (au, a) in au_alone_cases(layout)? {
        let state = valid_pose(&model, &a, &mut ws, &au)?;
        sheet.push((format!("{au} alone"), render(&model, &state, &small)));
    }
    let sheet_path = out.join("contact_sheet.png");
    save_png(
        &contact_sheet(
            "facelab: rest, the six expressions at s = 1, each AU's muscles at full activation",
            &sheet,
            6,
        )?,
        &sheet_path,
    )?;
    written.push(sheet_path);
    Ok(written)
}
