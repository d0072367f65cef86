//! `facelab edit`: keyframe editing of activation curves by displacement mapping (Choe et
//! al. 2001; the method is `crate::edit`), with Choe's Fig. 7 as an optional figure.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::edit::{edit, Key};
use crate::io::atomic::write_atomic;
use crate::io::curves::{read_curves, Curves};
use crate::report::figures::{edit_figure, EditRow};

/// Parses `FRAME:name=value[,name=value...]` keys against the curves' columns.
pub fn parse_keys(texts: &[String], curves: &Curves) -> Result<Vec<Key>> {
    let mut keys = Vec::new();
    for text in texts {
        let (frame, rest) = text
            .split_once(':')
            .with_context(|| format!("--key `{text}`: expected FRAME:name=value"))?;
        let frame: f64 = frame
            .trim()
            .parse()
            .with_context(|| format!("--key `{text}`: `{frame}` is not a frame number"))?;
        for pair in rest.split(',') {
            let (name, value) = pair
                .split_once('=')
                .with_context(|| format!("--key `{text}`: expected name=value, got `{pair}`"))?;
            let value: f64 = value
                .trim()
                .parse()
                .with_context(|| format!("--key `{text}`: `{value}` is not a number"))?;
            let curve = curves
                .column(name.trim())
                .with_context(|| format!("--key `{text}`"))?;
            keys.push(Key {
                frame,
                curve,
                value,
            });
        }
    }
    Ok(keys)
}

/// Edits `input`'s curves with `keys` at knot spacing `spacing`, writes `out` (and, with
/// `figure`, Choe's Fig. 7 for the first keyed curve at each of `figure_spacings`).
pub fn edit_file(
    input: &Path,
    keys: &[String],
    spacing: f64,
    out: &Path,
    figure: Option<(&Path, &[f64])>,
) -> Result<Vec<PathBuf>> {
    let curves = read_curves(input)?;
    let keys = parse_keys(keys, &curves)?;
    let edited = edit(&curves.frames, &curves.values, &keys, spacing)
        .with_context(|| format!("{}: editing", input.display()))?;
    let result = Curves {
        values: edited.values,
        ..curves.clone()
    };
    let mut written = Vec::new();
    write_atomic(out, result.to_csv().as_bytes())?;
    written.push(out.to_path_buf());
    if let Some((path, spacings)) = figure {
        let Some(first) = keys.first() else {
            bail!("--figure needs at least one --key");
        };
        let c = first.curve;
        let column = |v: &[Vec<f64>]| v.iter().map(|r| r[c]).collect::<Vec<f64>>();
        let mine: Vec<Key> = keys.iter().filter(|k| k.curve == c).cloned().collect();
        let mut rows = Vec::new();
        for &h in spacings {
            let e = edit(&curves.frames, &curves.values, &mine, h)?;
            let d = &e.displacements[0].1;
            rows.push(EditRow {
                label: format!("knot spacing {h}"),
                displacement: curves.frames.iter().map(|&t| d.at(t)).collect(),
                edited: column(&e.values),
            });
        }
        edit_figure(
            path,
            &format!(
                "Displacement mapping of {} ({})",
                curves.names[c],
                input.file_name().unwrap_or_default().to_string_lossy()
            ),
            &curves.frames,
            &column(&curves.values),
            &mine.iter().map(|k| (k.frame, k.value)).collect::<Vec<_>>(),
            &rows,
        )?;
        written.push(path.to_path_buf());
    }
    Ok(written)
}

/// `facelab retarget`: one activation sequence on the base face and on `subjects` image-cohort
/// subjects (their own geometry, stiffness and muscle strengths; `experiments/base.toml`'s
/// `[cohort]`), as a grid of renders at `frames` (Choe et al.'s Fig. 10) and an animated GIF
/// of all faces side by side.
pub fn retarget(
    layout: &crate::io::Layout,
    input: &Path,
    subjects: usize,
    frames: &[f64],
    out: &Path,
) -> Result<Vec<PathBuf>> {
    use crate::cohort::{CohortKind, Subject};
    use crate::report::compose::{gif_bytes, labelled_grid, png_bytes};
    use crate::report::render::{render, RenderOptions};
    use crate::sim::{solve, solve_from_rest, Activations, SolveParams, State, Workspace};
    use rayon::prelude::*;

    let curves = read_curves(input)?;
    let names = crate::sim::control_names();
    let mut sequence = Vec::with_capacity(curves.frames.len());
    for (row, &f) in curves.values.iter().zip(&curves.frames) {
        let mut a = Activations::neutral();
        for (name, &v) in curves.names.iter().zip(row) {
            if !names.contains(name) {
                bail!(
                    "{}: `{name}` is not a control of the model",
                    input.display()
                );
            }
            a.set(name, v)
                .with_context(|| format!("{}: frame {f}", input.display()))?;
        }
        sequence.push(a);
    }
    for f in frames {
        if !curves.frames.contains(f) {
            bail!("{}: no frame {f} to render", input.display());
        }
    }
    let spec = crate::spec::load(layout, &layout.file("experiments/base.toml"), &[])?.remove(0);
    let source = crate::io::face::FaceSource::of(layout);
    let (mesh, weights) = (source.mesh()?, source.weights()?);
    let mut faces = vec![("base model".to_string(), source.model()?)];
    for i in 0..subjects {
        let s = Subject::draw(
            &mesh,
            source.params(),
            &weights,
            &spec.spec.cohort.subjects,
            spec.spec.cohort.seed,
            CohortKind::Images.name(),
            i,
        )?;
        faces.push((format!("subject {i}"), s.model));
    }
    let cell = RenderOptions {
        width: 240,
        height: 280,
        ..RenderOptions::default()
    };
    let params = SolveParams::default();
    // Per face: every frame rendered, the sequence solved warm from frame to frame; a frame
    // the warm solve cannot reach (a subject's face whose previous state, carried to the new
    // jaw, inverts a prism) is solved again from rest, as a transfer's frames are.
    let renders: Vec<Vec<image::RgbImage>> = faces
        .par_iter()
        .map(|(name, model)| -> Result<Vec<image::RgbImage>> {
            let mut ws = Workspace::new(model)?;
            let mut out = Vec::with_capacity(sequence.len());
            let failures = crate::transfer::solve_clip_tolerant(
                &sequence,
                |_, a, last: Option<&State>, ws| {
                    Ok(match last {
                        Some(previous) => {
                            let mut state = previous.clone();
                            solve(model, a, &mut state, ws, &params)?;
                            state
                        }
                        None => solve_from_rest(model, a, ws, &params)?.0,
                    })
                },
                &mut ws,
                |_, state| {
                    if let Some(state) = state {
                        out.push(render(model, state, &cell));
                    }
                    Ok(())
                },
            )?;
            if let Some((i, why)) = failures.first() {
                bail!("{name}: frame {}: {why}", curves.frames[*i]);
            }
            Ok(out)
        })
        .collect::<Result<_>>()?;
    let columns: Vec<String> = faces.iter().map(|(n, _)| n.clone()).collect();
    let index = |f: f64| curves.frames.iter().position(|&g| g == f).expect("checked");
    let grid: Vec<Vec<image::RgbImage>> = frames
        .iter()
        .map(|&f| renders.iter().map(|r| r[index(f)].clone()).collect())
        .collect();
    let labels: Vec<String> = frames.iter().map(|f| format!("frame {f}")).collect();
    let title = format!("One activation sequence on {} faces", faces.len());
    let mut written = Vec::new();
    let mut write = |name: &str, bytes: Vec<u8>| -> Result<()> {
        let path = out.join(name);
        write_atomic(&path, &bytes)?;
        written.push(path);
        Ok(())
    };
    write(
        "retarget.png",
        png_bytes(&labelled_grid(&title, &grid, &labels, &columns)?)?,
    )?;
    let gif_frames: Vec<image::RgbImage> = (0..sequence.len())
        .map(|k| {
            let row = vec![renders.iter().map(|r| r[k].clone()).collect()];
            labelled_grid(&title, &row, &[String::new()], &columns)
        })
        .collect::<Result<_>>()?;
    write("retarget.gif", gif_bytes(&gif_frames, 67)?)?;
    Ok(written)
}
