//! The landmark-space fit of a transfer (`--method landmarks`, the default for pictures):
//! each frame's landmark displacements -> activations by the inversion table's `Inverter`,
//! corrected through the nonlinear face, and their face, all frames in parallel.

use std::path::Path;

use anyhow::{Context, Result};
use rayon::prelude::*;

use super::run_spec;
use crate::io::openface::OpenFaceFile;
use crate::sim::basis::LinearBasis;
use crate::sim::solver::solve_predicted;
use crate::sim::{solve, Activations, SolveParams, Workspace};
use crate::transfer::inverter::{Inverter, Refined, AU_PRIOR};

/// A frame's activations found without the network, and their face, solved at the run's
/// tolerance. Each such frame is a function of its own input, so the frames are solved in
/// parallel and the transfer takes their faces as they are instead of solving again frame by
/// frame (fitted activations jump from frame to frame, which makes a warm-started chain slow).
/// `state: None`: the face did not solve there, and the transfer tries it in its own way.
#[derive(Clone, Debug)]
pub struct Fitted {
    pub activations: Activations,
    pub state: Option<crate::sim::State>,
}

/// The landmark-space fit of every used row of an OpenFace file with 3D landmarks, against
/// the file's own neutral face (the per-landmark median of its rows), indexed by `frame - 1`.
pub(super) fn openface_fit(
    file: &OpenFaceFile,
    layout: &crate::io::Layout,
    run: &Path,
) -> Result<Vec<Option<Fitted>>> {
    use crate::io::openface::{camera_faces, observable};
    use crate::observe::median_face;
    let input = &file.path;
    observable(file).context("--method landmarks fits the file's 3D landmarks")?;
    let spec = run_spec(layout, run)?;
    let model = spec.face_source().model()?;
    let calibration = crate::run::cell::spec_calibration(&spec)?;
    let faces = camera_faces(file);
    let observer = crate::observe::Observer::new(&median_face(&faces), calibration.clone())
        .with_context(|| format!("{}: the neutral face", input.display()))?;
    let frames = file.rows.iter().map(|r| r.frame).max().unwrap_or(0).max(0) as usize;
    let mut displacements = vec![None; frames];
    for (r, face) in file.rows.iter().zip(&faces) {
        if r.frame < 1 {
            continue;
        }
        let d = observer
            .displacements(face)
            .with_context(|| format!("{}:{}", input.display(), r.line))?;
        displacements[r.frame as usize - 1] = Some(crate::transfer::inverter::flat(&d));
    }
    landmark_fit(&spec, &model, &calibration, &displacements)
}

/// Each used row's AUs, indexed by `frame - 1` (`None`: no used row), what
/// [`au_space_fit`] matches.
pub(super) fn aus_by_frame(file: &OpenFaceFile) -> Vec<Option<[f64; crate::observe::AU_COUNT]>> {
    let frames = file.rows.iter().map(|r| r.frame).max().unwrap_or(0).max(0) as usize;
    let mut aus = vec![None; frames];
    for r in file.rows.iter().filter(|r| r.frame >= 1) {
        aus[r.frame as usize - 1] = Some(r.aus);
    }
    aus
}

/// The landmark-space fit of each frame's landmark displacements (`None`: no face): the
/// inversion table's `Inverter` on the linear basis of `model`, built at the spec's solver
/// tolerance, corrected `inversion.refinements` times through the nonlinear face
/// ([`Inverter::landmarks_refined`]); the frames are fitted in parallel (each fit is a
/// function of its frame alone).
pub(super) fn landmark_fit(
    spec: &crate::spec::Spec,
    model: &crate::sim::FaceModel,
    calibration: &crate::observe::Calibration,
    displacements: &[Option<Vec<f64>>],
) -> Result<Vec<Option<Fitted>>> {
    let refinements = spec.inversion.refinements;
    fit_frames(
        spec,
        model,
        calibration,
        displacements,
        |inverter, d, ws, params| {
            inverter
                .landmarks_refined(d, refinements, ws, params)
                .context("the landmark fit's face")
        },
    )
}

/// The AU-space fit of each frame's AUs (`None`: no face): the activations whose face the
/// spec's observer reads as those AUs, least squares through the linear basis over the box
/// with `AU_PRIOR` times the squared activations added, corrected `inversion.refinements`
/// times through the nonlinear face ([`Inverter::aus_refined`]); frames in parallel.
/// Where an AU asks for more than the face can make, its muscles go to their bound and the
/// rest of the reading is still matched, instead of the network's extrapolation.
pub(crate) fn au_space_fit(
    spec: &crate::spec::Spec,
    model: &crate::sim::FaceModel,
    calibration: &crate::observe::Calibration,
    aus: &[Option<[f64; crate::observe::AU_COUNT]>],
) -> Result<Vec<Option<Fitted>>> {
    let refinements = spec.inversion.refinements;
    fit_frames(spec, model, calibration, aus, |inverter, r, ws, params| {
        inverter
            .aus_refined(r, AU_PRIOR, refinements, ws, params)
            .context("the AU fit's face")
    })
}

/// Each frame's input fitted by `fit` with the inversion table's `Inverter` on the linear
/// basis of `model` (built at the spec's solver tolerance), in parallel, and the fitted
/// activations' face solved at that tolerance from the fit's own face (from the basis
/// prediction where that fails).
fn fit_frames<T: Sync>(
    spec: &crate::spec::Spec,
    model: &crate::sim::FaceModel,
    calibration: &crate::observe::Calibration,
    inputs: &[Option<T>],
    fit: impl Fn(&Inverter, &T, &mut Workspace, &SolveParams) -> Result<Refined> + Sync,
) -> Result<Vec<Option<Fitted>>> {
    let params = SolveParams {
        tolerance: spec.dataset.tolerance,
        ..SolveParams::default()
    };
    let basis =
        LinearBasis::build(model, &params).context("the linear basis for the transfer's fit")?;
    let inverter = Inverter::new(model, &basis, calibration)?;
    inputs
        .par_iter()
        .enumerate()
        .map_init(
            || Workspace::new(model),
            |ws, (i, input)| {
                let Some(input) = input else { return Ok(None) };
                let ws = ws.as_mut().map_err(|e| anyhow::anyhow!("{e:#}"))?;
                let fit = fit(&inverter, input, ws, &params)
                    .with_context(|| format!("frame {}", i + 1))?;
                // The kept face, solved at the loosened tolerance, is a near start for the
                // full one; where that fails, the basis prediction.
                let a = fit.activations;
                let near = fit.state.and_then(|mut state| {
                    solve(model, &a, &mut state, ws, &params)
                        .ok()
                        .map(|_| state)
                });
                let state = near.or_else(|| {
                    solve_predicted(model, &basis, &a, ws, &params)
                        .ok()
                        .map(|r| r.0)
                });
                Ok(Some(Fitted {
                    activations: a,
                    state,
                }))
            },
        )
        .collect()
}
