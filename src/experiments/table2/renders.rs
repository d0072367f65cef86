//! Table 2's renders: the transfer grid and the video GIFs, cached by their inputs.

use crate::cohort::{CohortKind, Subject};
use crate::experiments::table2::RefFrame;
use crate::report::compose::{gif_bytes, labelled_grid, png_bytes};
use crate::report::render::{render, RenderOptions};
use crate::sim::basis::LinearBasis;
use crate::sim::expression::Expression;
use crate::sim::solver::solve_predicted;
use crate::sim::{solve, solve_from_rest, Activations, FaceModel, SolveParams, State, Workspace};
use crate::transfer::network::{to_activations, Setting, Transferred};
use anyhow::{Context, Result};
use image::RgbImage;

use super::*;

pub(super) const CELL: RenderOptions = RenderOptions {
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
pub(super) fn states(
    model: &FaceModel,
    basis: Option<&LinearBasis>,
    acts: &[Activations],
    params: &SolveParams,
) -> Result<Vec<State>> {
    let mut ws = Workspace::new(model)?;
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

pub(super) fn activations_of(values: &[f64]) -> Result<Activations> {
    let v: [f64; crate::sim::CONTROL_COUNT] = values.try_into().context("control count")?;
    Ok(Activations::from_values(&v)?)
}

/// The paper's Fig. 5 (two image subjects, each emotion: subject, unnormalized and normalized
/// transfer) and, per video cohort, a GIF of one clip (subject beside normalized transfer).
pub(super) fn renders(
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
