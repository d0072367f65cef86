//! `facelab bench solve`: solve time per sample (cold from rest, warm from the previous
//! sample), model size, where a Newton iteration's time goes, how many returned faces are
//! saddles of the energy rather than stable equilibria, and the linear basis' time and
//! landmark error against the nonlinear solve. Prints `name value unit` lines. Run it on a
//! release build.

use crate::io::Layout;
use std::io::Write;
use std::time::Instant;

use anyhow::Result;
use rayon::prelude::*;

use crate::io::face::FaceSource;
use crate::observe::landmarks;
use crate::rng::stream;
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::geom::{norm, sub, V3};
use crate::sim::{solve_from_rest, Activations, SolveParams, Workspace};

mod landmark;
mod neck;
mod solve;

pub use landmark::bench_landmark;
pub use neck::bench_neck;
pub use solve::bench_solve;

/// Random expression activations as the dataset stage draws them: a random expression,
/// s ~ U[0, 1], jaw rotation ~ U[0, 1].
pub fn random_samples(weights: &ExpressionWeights, seed: u64, count: usize) -> Vec<Activations> {
    random_draws(seed, count)
        .into_iter()
        .map(|(e, s, jaw)| weights.sample(e, s, jaw))
        .collect()
}

/// The paper family's `(expression, s, jaw)` of [`random_samples`].
pub fn random_draws(seed: u64, count: usize) -> Vec<(Expression, f64, f64)> {
    let mut rng = stream(seed, "bench/solve/samples");
    (0..count)
        .map(|_| {
            let e = Expression::ALL[rng.index(6)];
            let s = rng.uniform();
            let jaw = rng.uniform();
            (e, s, jaw)
        })
        .collect()
}

fn line(out: &mut impl Write, name: &str, value: f64, unit: &str) -> Result<()> {
    writeln!(out, "{name} {value:.4} {unit}")?;
    Ok(())
}

/// Mean and max distance between two landmark sets (m).
fn landmark_error(a: &[V3], b: &[V3]) -> (f64, f64) {
    let la = landmarks(a);
    let lb = landmarks(b);
    let d: Vec<f64> = la.iter().zip(&lb).map(|(p, q)| norm(sub(*p, *q))).collect();
    (
        crate::stats::mean(&d),
        d.iter().cloned().fold(0.0, f64::max),
    )
}

/// `facelab bench observe`: observing one face (landmarks + 17 AUs), and reading a full
/// 714-column OpenFace file of `frames` rows written to a temporary folder.
pub fn bench_observe(layout: &Layout, frames: usize, out: &mut impl Write) -> Result<()> {
    use crate::io::calibration::read_calibration;
    use crate::io::openface::{full_header, read_openface};
    use crate::observe::model_observer;

    let source = FaceSource::of(layout);
    let model = source.model()?;
    let weights = source.weights()?;
    let calibration = read_calibration(&layout.calibration())?.calibration();
    let observer = model_observer(&model, calibration)?;
    let mut ws = Workspace::new(&model)?;
    let (state, _) = solve_from_rest(
        &model,
        &weights.activations(Expression::Joy, 1.0),
        &mut ws,
        &SolveParams::default(),
    )?;
    let surface = state.surface(model.vertex_count());
    let repeats = 20_000;
    let t = Instant::now();
    for _ in 0..repeats {
        let o = observer.observe(&landmarks(std::hint::black_box(surface)))?;
        std::hint::black_box(o);
    }
    let per = t.elapsed().as_secs_f64() / repeats as f64;
    line(out, "observe.face_us", per * 1e6, "us")?;

    let header = full_header();
    let mut rng = stream(1, "bench/observe/openface");
    let mut text = header.join(",");
    text.push('\n');
    for f in 0..frames {
        let mut row = vec![
            (f + 1).to_string(),
            "0".into(),
            format!("{:.3}", f as f64 / 30.0),
            "0.98".into(),
            "1".into(),
        ];
        row.extend((5..header.len()).map(|_| format!("{:.3}", rng.range(-50.0, 50.0))));
        text.push_str(&row.join(","));
        text.push('\n');
    }
    let dir = std::env::temp_dir().join(format!("facelab-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("openface.csv");
    std::fs::write(&path, &text)?;
    let t = Instant::now();
    let file = read_openface(&path)?;
    let read = t.elapsed().as_secs_f64();
    std::fs::remove_dir_all(&dir)?;
    line(
        out,
        "observe.openface_columns",
        header.len() as f64,
        "count",
    )?;
    line(
        out,
        "observe.openface_rows",
        file.rows.len() as f64,
        "count",
    )?;
    line(out, "observe.openface_bytes", text.len() as f64, "bytes")?;
    line(out, "observe.openface_read_s", read, "s")?;
    out.flush()?;
    Ok(())
}

/// `facelab bench train`: the training loop alone (data in memory) for the unified network's
/// shape, 17 -> 4 x 100 -> 56, on `pairs` synthetic pairs (uniform AUs on 0..5, targets a
/// fixed smooth function of them), `epochs` epochs, batch 32, alone and five of it as one
/// batched model (`learn::batch`). `export` writes the pairs as CSV
/// (17 inputs then 56 targets per row) so another framework can train on the same data.
pub fn bench_train(
    pairs: usize,
    epochs: usize,
    export: Option<&std::path::Path>,
    out: &mut impl Write,
) -> Result<()> {
    use crate::learn::{train, ModelParams, Pairs, TrainParams};
    let mut rng = stream(1, "bench/train/data");
    let mut data = Pairs {
        inputs: 17,
        outputs: 56,
        ..Pairs::default()
    };
    let mix: Vec<f64> = (0..17 * 56).map(|_| rng.range(-1.0, 1.0)).collect();
    for _ in 0..pairs {
        let x: Vec<f64> = (0..17).map(|_| rng.range(0.0, 5.0)).collect();
        data.x.extend(x.iter().map(|v| *v as f32));
        for o in 0..56 {
            let s: f64 = (0..17).map(|i| mix[o * 17 + i] * x[i]).sum::<f64>() / 17.0;
            data.y.push((0.5 + 0.5 * s.tanh()) as f32);
        }
    }
    if let Some(path) = export {
        let mut text = String::new();
        for r in 0..pairs {
            let row: Vec<String> = data.x[r * 17..(r + 1) * 17]
                .iter()
                .chain(&data.y[r * 56..(r + 1) * 56])
                .map(|v| format!("{v}"))
                .collect();
            text.push_str(&row.join(","));
            text.push('\n');
        }
        std::fs::write(path, text)?;
    }
    let params = TrainParams {
        epochs,
        ..TrainParams::default()
    };
    let empty = Pairs {
        inputs: 17,
        outputs: 56,
        ..Pairs::default()
    };
    let mut u = stream(1, "bench/train/init");
    let mut uniform = || u.uniform();
    let t = Instant::now();
    let (_, curves) = train(
        &data,
        &empty,
        &ModelParams::default(),
        &params,
        &mut uniform,
    )?;
    let secs = t.elapsed().as_secs_f64();
    line(out, "train.unified", secs, "s")?;
    // The same network five times (a kind's seeds) as one batched model, each with its own
    // initialization stream: what the run's training stage does per network kind.
    const SEEDS: usize = 5;
    // Five seeds of one network on `pairs` as one batched model, each from its own stream.
    let seeds = |pairs: &Pairs, name: &str| -> Result<()> {
        let mut streams: Vec<_> = (0..SEEDS as u64).map(|s| stream(1 + s, name)).collect();
        let mut sources: Vec<_> = streams.iter_mut().map(|r| move || r.uniform()).collect();
        let mut jobs: Vec<crate::learn::Job> = sources
            .iter_mut()
            .map(|uniform| crate::learn::Job {
                train: pairs,
                test: &empty,
                uniform,
            })
            .collect();
        crate::learn::train_batch(&mut jobs, &ModelParams::default(), &params)?;
        Ok(())
    };
    let t = Instant::now();
    seeds(&data, "bench/train/init")?;
    let batched = t.elapsed().as_secs_f64();
    line(out, "train.batched_5", batched, "s")?;
    line(
        out,
        "train.batched_per_network",
        batched / SEEDS as f64,
        "s",
    )?;
    // The paper's 35 networks as its training stage runs them: per kind (the unified network on
    // every pair, each expression's on a sixth of them), the five seeds as one batched model,
    // the kinds side by side on rayon's workers (`--threads`).
    let kinds: Vec<usize> = std::iter::once(pairs)
        .chain(std::iter::repeat_n(pairs / 6, 6))
        .collect();
    let subsets: Vec<Pairs> = kinds
        .iter()
        .map(|&n| Pairs {
            inputs: 17,
            outputs: 56,
            x: data.x[..n * 17].to_vec(),
            y: data.y[..n * 56].to_vec(),
        })
        .collect();
    let t = Instant::now();
    subsets
        .par_iter()
        .enumerate()
        .map(|(k, subset)| seeds(subset, &format!("bench/train/init/{k}")))
        .collect::<Result<Vec<()>>>()?;
    line(out, "train.paper_35", t.elapsed().as_secs_f64(), "s")?;
    line(
        out,
        "train.threads",
        rayon::current_num_threads() as f64,
        "count",
    )?;
    line(out, "train.pairs", pairs as f64, "count")?;
    line(out, "train.epochs", epochs as f64, "count")?;
    line(
        out,
        "train.final_mse",
        curves.train.last().copied().unwrap_or(f64::NAN),
        "mse",
    )?;
    out.flush()?;
    Ok(())
}

/// `facelab bench transfer`: one frame of transfer (network, solve, observe) on one core, for
/// the talking-video frames (each solved warm from the previous frame) and the images (each
/// from rest), taking reference AUs and the network from a run folder with Table 2.
pub fn bench_transfer(
    layout: &Layout,
    run: &std::path::Path,
    clips: usize,
    out: &mut impl Write,
) -> Result<()> {
    use crate::cohort::CohortKind;
    use crate::experiments::table2::{clip_ranges, reference_from_csv};
    use crate::io::calibration::read_calibration;
    use crate::observe::model_observer;
    use crate::transfer::network::{predict_activations, solve_clip};
    use anyhow::Context;

    let path = run.join("reference.csv");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "{}: cannot read (a run with Table 2 writes it)",
            path.display()
        )
    })?;
    let reference = reference_from_csv(&text, &path.display().to_string())?;
    let bytes = std::fs::read(run.join("unified.safetensors"))
        .with_context(|| format!("{}: no unified.safetensors", run.display()))?;
    let mlp = crate::learn::Mlp::from_safetensors(&bytes)?;
    let model = FaceSource::of(layout).model()?;
    let calibration = read_calibration(&layout.calibration())?.calibration();
    let observer = model_observer(&model, calibration)?;
    let params = SolveParams::default();
    let mut ws = Workspace::new(&model)?;
    for (kind, name) in [
        (CohortKind::TalkingVideos, "video"),
        (CohortKind::Images, "image"),
    ] {
        let ranges: Vec<_> = clip_ranges(&reference)
            .into_iter()
            .filter(|r| reference[r.start].cohort == kind)
            .take(clips)
            .collect();
        let (mut network, mut solving, mut observing, mut frames) = (0.0, 0.0, 0.0, 0usize);
        for r in ranges {
            let aus: Vec<_> = reference[r].iter().map(|f| f.aus).collect();
            let t = Instant::now();
            let mut acts = Vec::new();
            for a in &aus {
                acts.extend(predict_activations(&mlp, None, std::slice::from_ref(a))?);
            }
            network += t.elapsed().as_secs_f64();
            let mut last = Instant::now();
            solve_clip(
                &model,
                &acts,
                |a, ws| Ok(solve_from_rest(&model, a, ws, &params)?.0),
                &mut ws,
                &params,
                |_, state| {
                    solving += last.elapsed().as_secs_f64();
                    let t = Instant::now();
                    std::hint::black_box(
                        observer.observe(&landmarks(state.surface(model.vertex_count())))?,
                    );
                    observing += t.elapsed().as_secs_f64();
                    frames += 1;
                    last = Instant::now();
                    Ok(())
                },
            )?;
        }
        let n = frames.max(1) as f64;
        line(out, &format!("transfer.{name}.frames"), n, "frames")?;
        line(
            out,
            &format!("transfer.{name}.network_us_per_frame"),
            1e6 * network / n,
            "us",
        )?;
        line(
            out,
            &format!("transfer.{name}.solve_ms_per_frame"),
            1e3 * solving / n,
            "ms",
        )?;
        line(
            out,
            &format!("transfer.{name}.observe_us_per_frame"),
            1e6 * observing / n,
            "us",
        )?;
        line(
            out,
            &format!("transfer.{name}.ms_per_frame"),
            1e3 * (network + solving + observing) / n,
            "ms",
        )?;
    }
    Ok(())
}
