//! The network's path from AUs to a face (Zeng et al.): reference AUs, mapped onto the
//! training data's range or taken as read (`Setting`), through a unified network to
//! activations, then solved frame by frame on the base model and read by the observer; and
//! the AU MSE that scores it. Table 2, the real-faces table, the inversion table and
//! `facelab transfer --method network` all take this path.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use crate::dataset::reader::FaceReader;
use crate::learn::{Mlp, Normalization, Normalizer, Pairs};
use crate::observe::au::AU_MAX;
use crate::observe::{Observer, AU_COUNT};
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{CONTROL_COUNT, JAW_SLIDE, JAW_TWIST};
use crate::sim::solver::solve_predicted;
use crate::sim::{solve, solve_from_rest, Activations, FaceModel, SolveParams, State, Workspace};

/// Whether reference AUs are mapped onto the training range before the network.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Setting {
    Unnormalized,
    Normalized,
}

impl Setting {
    pub const ALL: [Setting; 2] = [Setting::Unnormalized, Setting::Normalized];

    pub fn name(self) -> &'static str {
        match self {
            Setting::Unnormalized => "unnormalized",
            Setting::Normalized => "normalized",
        }
    }

    pub fn parse(s: &str) -> Option<Setting> {
        Setting::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// Solves a clip frame by frame (the first from rest, each next from the previous frame's
/// equilibrium), calling `each` with every frame's state.
pub fn solve_clip(
    model: &FaceModel,
    frames: &[Activations],
    first: impl Fn(&Activations, &mut Workspace) -> Result<State>,
    ws: &mut Workspace,
    params: &SolveParams,
    mut each: impl FnMut(usize, &State) -> Result<()>,
) -> Result<()> {
    let mut state: Option<State> = None;
    for (f, a) in frames.iter().enumerate() {
        match state.as_mut() {
            None => state = Some(first(a, ws).with_context(|| format!("frame {f}"))?),
            Some(s) => {
                solve(model, a, s, ws, params).with_context(|| format!("frame {f}"))?;
            }
        }
        each(f, state.as_ref().expect("solved"))?;
    }
    Ok(())
}

fn pairs_of(rows: &[[f64; AU_COUNT]]) -> Pairs {
    Pairs {
        inputs: AU_COUNT,
        outputs: 0,
        x: rows.iter().flatten().map(|&v| v as f32).collect(),
        y: Vec::new(),
    }
}

/// Below this spread (range for min-max, SD for z-score; AU intensity on the 0-5 scale) an AU
/// carries no range to normalize: a single image, or an AU that barely moves in a clip.
pub const FLAT_SPREAD: f64 = 0.1;

/// The AUs whose spread across `input` is below [`FLAT_SPREAD`] (all of them for one row).
pub fn flat_aus(kind: Normalization, input: &[[f64; AU_COUNT]]) -> Vec<usize> {
    if kind == Normalization::None {
        return Vec::new();
    }
    (0..AU_COUNT)
        .filter(|&k| {
            let column: Vec<f64> = input.iter().map(|r| r[k]).collect();
            let (_, spread) = kind.offset_spread(&column);
            spread.is_nan() || spread < FLAT_SPREAD
        })
        .collect()
}

/// The per-AU affine map that takes `input`'s range (min-max) or mean and SD (z-score) onto
/// `target`'s: `x -> (x - offset) * scale`. The identity when the two agree, and for every
/// AU of [`flat_aus`]: a range that is not there cannot be stretched, so a single image or a
/// still AU keeps its own reading (on the observer's scale, which the training data share)
/// instead of landing on the training minimum, a neutral face.
pub fn range_map(
    kind: Normalization,
    input: &[[f64; AU_COUNT]],
    target: &Normalizer,
) -> Normalizer {
    let mut map = Normalizer::fit(kind, &pairs_of(input)).onto(target);
    for k in flat_aus(kind, input) {
        map.offset[k] = 0.0;
        map.scale[k] = 1.0;
    }
    map
}

/// The training data's per-AU statistics as a normalizer of `kind`.
pub fn training_range(kind: Normalization, training_aus: &[[f64; AU_COUNT]]) -> Normalizer {
    Normalizer::fit(kind, &pairs_of(training_aus))
}

/// Network outputs as activations the base model accepts: each clamped to [0, 1], jaw slide
/// and twist neutral.
pub fn to_activations(out: &[f32]) -> Activations {
    let mut values: [f64; CONTROL_COUNT] = std::array::from_fn(|k| (out[k] as f64).clamp(0.0, 1.0));
    values[JAW_SLIDE] = 0.5;
    values[JAW_TWIST] = 0.5;
    Activations::from_values(&values).expect("clamped")
}

/// The unified network's activations for rows of reference AUs (after `map`, if any).
pub fn predict_activations(
    mlp: &Mlp,
    map: Option<&Normalizer>,
    rows: &[[f64; AU_COUNT]],
) -> Result<Vec<Activations>> {
    let inputs: Vec<f32> = rows.iter().flatten().map(|&v| v as f32).collect();
    let inputs = match map {
        Some(m) => m.apply(&inputs),
        None => inputs,
    };
    if inputs.iter().any(|v| !v.is_finite()) {
        bail!("reference AUs contain NaN or infinite values");
    }
    let out = mlp
        .predict(&inputs)
        .context("running the unified network")?;
    Ok(out
        .chunks_exact(CONTROL_COUNT)
        .map(to_activations)
        .collect())
}

/// One transferred frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Transferred {
    pub activations: [f64; CONTROL_COUNT],
    pub aus: [f64; AU_COUNT],
}

/// Transfers clips of input AUs (each a sequence of frames) onto the base model: the network
/// (after `map`, if any), then a solve per frame (the first from the basis prediction or rest,
/// each next warm from the previous one), then the observer. Clips run in parallel; frames in
/// order. Calls `tick` per clip.
#[allow(clippy::too_many_arguments)]
pub fn transfer(
    model: &FaceModel,
    basis: Option<&LinearBasis>,
    reader: &FaceReader,
    observer: &Observer,
    mlp: &Mlp,
    map: Option<&Normalizer>,
    clips: &[Vec<[f64; AU_COUNT]>],
    params: &SolveParams,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Vec<Transferred>>> {
    let rows: Vec<[f64; AU_COUNT]> = clips.iter().flatten().copied().collect();
    let mut acts = predict_activations(mlp, map, &rows)?.into_iter();
    let jobs: Vec<Vec<Activations>> = clips
        .iter()
        .map(|c| acts.by_ref().take(c.len()).collect())
        .collect();
    jobs.par_iter()
        .enumerate()
        .map_init(
            || Workspace::new(model),
            |ws, (ci, acts)| -> Result<Vec<Transferred>> {
                let ws = ws.as_mut().map_err(|e| e.clone())?;
                let mut frames = Vec::with_capacity(acts.len());
                solve_clip(
                    model,
                    acts,
                    |a, ws| {
                        Ok(match basis {
                            Some(b) => solve_predicted(model, b, a, ws, params)?.0,
                            None => solve_from_rest(model, a, ws, params)?.0,
                        })
                    },
                    ws,
                    params,
                    |_, state| {
                        let o = observer.observe(&reader.read(model, state, None)?)?;
                        frames.push(Transferred {
                            activations: *state.activations.values(),
                            aus: o.aus,
                        });
                        Ok(())
                    },
                )
                .with_context(|| format!("transferring clip {ci}"))?;
                tick();
                Ok(frames)
            },
        )
        .collect()
}

/// Per-AU MSE of (reference - transferred) / 5 over all frames.
pub fn au_mse(reference: &[[f64; AU_COUNT]], transferred: &[[f64; AU_COUNT]]) -> [f64; AU_COUNT] {
    std::array::from_fn(|k| {
        let d: Vec<f64> = reference
            .iter()
            .zip(transferred)
            .map(|(r, t)| (r[k] - t[k]) / AU_MAX)
            .collect();
        crate::stats::mean_square(&d)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_map_is_the_identity_when_ranges_match() {
        let a: Vec<[f64; AU_COUNT]> = (0..5)
            .map(|i| std::array::from_fn(|k| (i * (k + 1)) as f64 * 0.1))
            .collect();
        // Same ranges, different samples inside them.
        let mut b = a.clone();
        b.swap(1, 3);
        b[2] = std::array::from_fn(|k| a[2][k] * 0.5 + a[3][k] * 0.5);
        for kind in [Normalization::MinMax] {
            let m = range_map(kind, &b, &training_range(kind, &a));
            for (o, s) in m.offset.iter().zip(&m.scale) {
                assert!(o.abs() < 1e-6, "offset {o}");
                assert!((s - 1.0).abs() < 1e-6, "scale {s}");
            }
        }
        let z = range_map(
            Normalization::ZScore,
            &a,
            &training_range(Normalization::ZScore, &a),
        );
        let x: Vec<f32> = a.iter().flatten().map(|&v| v as f32).collect();
        for (u, v) in z.apply(&x).iter().zip(&x) {
            assert!((u - v).abs() < 1e-5);
        }
    }

    #[test]
    fn range_map_takes_one_range_onto_another() {
        let input: Vec<[f64; AU_COUNT]> = vec![[1.0; AU_COUNT], [2.0; AU_COUNT]];
        let target: Vec<[f64; AU_COUNT]> = vec![[0.0; AU_COUNT], [4.0; AU_COUNT]];
        let m = range_map(
            Normalization::MinMax,
            &input,
            &training_range(Normalization::MinMax, &target),
        );
        let y = m.apply(&[1.5; AU_COUNT]);
        assert!(y.iter().all(|v| (v - 2.0).abs() < 1e-6), "{y:?}");
    }

    #[test]
    fn a_single_row_or_a_still_au_keeps_its_reading() {
        let target = training_range(Normalization::MinMax, &[[0.0; AU_COUNT], [4.0; AU_COUNT]]);
        let mut smile = [0.0; AU_COUNT];
        smile[8] = 3.0;
        for kind in [Normalization::MinMax, Normalization::ZScore] {
            assert_eq!(flat_aus(kind, &[smile]).len(), AU_COUNT);
            let m = range_map(kind, &[smile], &target);
            let x: Vec<f32> = smile.iter().map(|&v| v as f32).collect();
            assert_eq!(m.apply(&x), x, "{kind:?}");
        }
        // In a clip, only the AU that does not move passes through.
        let mut faint = smile;
        faint[8] = 1.0;
        let clip = vec![smile, faint];
        let flat = flat_aus(Normalization::MinMax, &clip);
        assert_eq!(flat.len(), AU_COUNT - 1);
        assert!(!flat.contains(&8));
        assert!(flat_aus(Normalization::None, &[smile]).is_empty());
    }

    #[test]
    fn mse_is_on_the_unit_scale() {
        let r = vec![[5.0; AU_COUNT], [0.0; AU_COUNT]];
        let t = vec![[0.0; AU_COUNT], [0.0; AU_COUNT]];
        assert!(au_mse(&r, &t).iter().all(|&m| m == 0.5));
    }
}
