//! `facelab bench solve`: solve time per sample (cold from rest, warm from the previous
//! sample), model size, where a Newton iteration's time goes, how many returned faces are
//! saddles of the energy rather than stable equilibria, and the linear basis' time and
//! landmark error against the nonlinear solve. Prints `name value unit` lines. Run it on a
//! release build.

use std::io::Write;
use std::time::Instant;

use anyhow::Result;

use super::face::FaceSource;
use super::observe::median;
use crate::observe::landmarks;
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::geom::{norm, sub, V3};
use crate::sim::solver::{iteration_cost, softest_mode, solve_predicted, SoftMode};
use crate::sim::{solve, solve_from_rest, Activations, SolveParams, Workspace};

/// Random expression activations as the dataset stage draws them: a random expression,
/// s ~ U[0, 1], jaw rotation ~ U[0, 1].
pub fn random_samples(weights: &ExpressionWeights, seed: u64, count: usize) -> Vec<Activations> {
    let mut rng = stream(seed, "bench/solve/samples");
    (0..count)
        .map(|_| {
            let e = Expression::ALL[rng.index(6)];
            let s = rng.uniform();
            let jaw = rng.uniform();
            weights.sample(e, s, jaw)
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
        d.iter().sum::<f64>() / d.len() as f64,
        d.iter().cloned().fold(0.0, f64::max),
    )
}

pub fn bench_solve(
    source: &FaceSource,
    levels: &[u8],
    samples: usize,
    seed: u64,
    params: &SolveParams,
    out: &mut impl Write,
) -> Result<()> {
    let weights = source.weights()?;
    let params = *params;
    for &level in levels {
        let model = FaceSource {
            subdivisions: level,
            ..source.clone()
        }
        .model()?;
        let p = format!("solve.nonlinear.sub{level}");
        let n = model.vertex_count();
        line(out, &format!("{p}.surface_vertices"), n as f64, "count")?;
        line(
            out,
            &format!("{p}.free_nodes"),
            model.free.iter().filter(|&&f| f).count() as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.springs"),
            model.tissue.springs.len() as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.prisms"),
            model.tissue.prisms.len() as f64,
            "count",
        )?;
        let count = if level == 0 {
            samples
        } else {
            (samples / 5).max(3)
        };
        let batch = random_samples(&weights, seed, count);
        let t = Instant::now();
        let mut ws = Workspace::new(&model);
        line(
            out,
            &format!("{p}.setup_ms"),
            t.elapsed().as_secs_f64() * 1e3,
            "ms",
        )?;

        // Cold: each sample from rest by continuation.
        let mut cold_iterations = 0;
        let mut states = Vec::with_capacity(count);
        let t = Instant::now();
        for a in &batch {
            let (state, r) = solve_from_rest(&model, a, &mut ws, &params)?;
            cold_iterations += r.iterations;
            states.push(state);
        }
        let cold = t.elapsed().as_secs_f64() / count as f64;
        line(out, &format!("{p}.cold_ms_per_sample"), cold * 1e3, "ms")?;
        line(
            out,
            &format!("{p}.cold_iterations_per_sample"),
            cold_iterations as f64 / count as f64,
            "count",
        )?;

        // Warm: each sample from the previous sample's equilibrium.
        let mut state = model.rest_state();
        let mut warm_iterations = 0;
        let t = Instant::now();
        for a in &batch {
            let r = solve(&model, a, &mut state, &mut ws, &params)?;
            warm_iterations += r.iterations;
        }
        let warm = t.elapsed().as_secs_f64() / count as f64;
        line(out, &format!("{p}.warm_ms_per_sample"), warm * 1e3, "ms")?;
        line(
            out,
            &format!("{p}.warm_iterations_per_sample"),
            warm_iterations as f64 / count as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.warm_ms_per_iteration"),
            warm * 1e3 * count as f64 / warm_iterations.max(1) as f64,
            "ms",
        )?;

        // Where an iteration's time goes, at the first equilibria of the batch.
        let probes = &states[..states.len().min(10)];
        let (mut assemble, mut factorize, mut energy) = (0.0, 0.0, 0.0);
        for s in probes {
            let c = iteration_cost(&model, s, &mut ws, 5);
            assemble += c.assemble / probes.len() as f64;
            factorize += c.factorize / probes.len() as f64;
            energy += c.energy / probes.len() as f64;
        }
        line(
            out,
            &format!("{p}.hessian_nonzeros"),
            ws.hessian_nonzeros() as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.factor_nonzeros"),
            ws.factor_nonzeros() as f64,
            "count",
        )?;
        line(out, &format!("{p}.assemble_ms"), assemble * 1e3, "ms")?;
        line(
            out,
            &format!("{p}.factorize_solve_ms"),
            factorize * 1e3,
            "ms",
        )?;
        line(out, &format!("{p}.energy_ms"), energy * 1e3, "ms")?;

        // The softest mode of every returned face: a negative one marks a saddle of the
        // energy, not a stable equilibrium.
        let mut springs: Vec<f64> = model.tissue.springs.iter().map(|s| s.k).collect();
        line(
            out,
            &format!("{p}.spring_stiffness_median_n_per_m"),
            median(&mut springs),
            "N/m",
        )?;
        let modes: Vec<SoftMode> = states
            .iter()
            .filter_map(|s| softest_mode(&model, s, &mut ws, true, 80))
            .collect();
        let mut stiffness: Vec<f64> = modes.iter().map(|m| m.stiffness).collect();
        let mut saddle_share: Vec<f64> = modes
            .iter()
            .filter(|m| m.stiffness < 0.0)
            .map(|m| m.vertex_share)
            .collect();
        line(
            out,
            &format!("{p}.saddles"),
            saddle_share.len() as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.saddle_mode_vertex_share_median"),
            median(&mut saddle_share),
            "fraction",
        )?;
        line(
            out,
            &format!("{p}.softest_mode_min_n_per_m"),
            stiffness.iter().copied().fold(f64::INFINITY, f64::min),
            "N/m",
        )?;
        line(
            out,
            &format!("{p}.softest_mode_median_n_per_m"),
            median(&mut stiffness),
            "N/m",
        )?;

        // Linear basis, and solves started from its prediction.
        let t = Instant::now();
        let basis = LinearBasis::build(&model, &params)?;
        line(
            out,
            &format!("solve.linear.sub{level}.build_s"),
            t.elapsed().as_secs_f64(),
            "s",
        )?;
        let mut predicted_iterations = Vec::with_capacity(count);
        let mut fallbacks = 0;
        let mut predicted_states = Vec::with_capacity(count);
        let t = Instant::now();
        for a in &batch {
            let (state, r) = solve_predicted(&model, &basis, a, &mut ws, &params)?;
            predicted_iterations.push(r.iterations as f64);
            // More than one piece: Newton from the prediction failed and the solve went
            // the continuation path from rest.
            fallbacks += usize::from(r.pieces > 1);
            predicted_states.push(state);
        }
        let predicted = t.elapsed().as_secs_f64() / count as f64;
        line(
            out,
            &format!("{p}.predicted_ms_per_sample"),
            predicted * 1e3,
            "ms",
        )?;
        line(
            out,
            &format!("{p}.predicted_iterations_per_sample"),
            predicted_iterations.iter().sum::<f64>() / count as f64,
            "count",
        )?;
        line(
            out,
            &format!("{p}.predicted_iterations_median"),
            median(&mut predicted_iterations),
            "count",
        )?;
        line(
            out,
            &format!("{p}.predicted_fallbacks_to_continuation"),
            fallbacks as f64,
            "count",
        )?;
        let mut apart = 0.0f64;
        for (a, b) in predicted_states.iter().zip(&states) {
            apart = apart.max(landmark_error(a.surface(n), b.surface(n)).1);
        }
        line(
            out,
            &format!("{p}.predicted_vs_cold_landmark_max_mm"),
            apart * 1e3,
            "mm",
        )?;

        // How far the returned faces are from a 100x tighter solve of the same activations.
        let tight = SolveParams {
            tolerance: params.tolerance * 1e-2,
            ..params
        };
        let mut drift = 0.0f64;
        for s in &states {
            let mut refined = s.clone();
            solve(&model, &s.activations, &mut refined, &mut ws, &tight)?;
            drift = drift.max(landmark_error(refined.surface(n), s.surface(n)).1);
        }
        line(
            out,
            &format!("{p}.tolerance_landmark_drift_max_mm"),
            drift * 1e3,
            "mm",
        )?;

        let mut surface = Vec::new();
        let repeats = 200;
        let t = Instant::now();
        for _ in 0..repeats {
            for a in &batch {
                basis.evaluate(a, &mut surface);
                std::hint::black_box(&surface);
            }
        }
        let per = t.elapsed().as_secs_f64() / (repeats * count) as f64;
        line(
            out,
            &format!("solve.linear.sub{level}.us_per_sample"),
            per * 1e6,
            "us",
        )?;
        let (mut mean, mut max) = (0.0, 0.0f64);
        for (a, s) in batch.iter().zip(&states) {
            basis.evaluate(a, &mut surface);
            let (m, x) = landmark_error(&surface, s.surface(n));
            mean += m / count as f64;
            max = max.max(x);
        }
        line(
            out,
            &format!("solve.linear.sub{level}.landmark_error_mean_mm"),
            mean * 1e3,
            "mm",
        )?;
        line(
            out,
            &format!("solve.linear.sub{level}.landmark_error_max_mm"),
            max * 1e3,
            "mm",
        )?;
        let rest = model.rest_state();
        let motion: f64 = states
            .iter()
            .map(|s| landmark_error(s.surface(n), rest.surface(n)).0)
            .sum::<f64>()
            / count as f64;
        line(
            out,
            &format!("solve.nonlinear.sub{level}.landmark_motion_mean_mm"),
            motion * 1e3,
            "mm",
        )?;
        out.flush()?;
    }
    Ok(())
}

/// `facelab bench observe`: observing one face (landmarks + 17 AUs), and reading a full
/// 714-column OpenFace file of `frames` rows written to a temporary folder.
pub fn bench_observe(frames: usize, out: &mut impl Write) -> Result<()> {
    use crate::experiments::observe::model_observer;
    use crate::io::calibration::{default_calibration_path, read_calibration};
    use crate::io::openface::{full_header, read_openface};

    let source = FaceSource::default();
    let model = source.model()?;
    let weights = source.weights()?;
    let calibration = read_calibration(&default_calibration_path())?.calibration();
    let observer = model_observer(&model, calibration)?;
    let mut ws = Workspace::new(&model);
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
/// fixed smooth function of them), `epochs` epochs, batch 32. `export` writes the pairs as CSV
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
pub fn bench_transfer(run: &std::path::Path, clips: usize, out: &mut impl Write) -> Result<()> {
    use super::observe::model_observer;
    use super::table2::{clip_ranges, predict_activations, reference_from_csv, solve_clip};
    use crate::cohort::CohortKind;
    use crate::io::calibration::{default_calibration_path, read_calibration};
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
    let model = FaceSource::default().model()?;
    let calibration = read_calibration(&default_calibration_path())?.calibration();
    let observer = model_observer(&model, calibration)?;
    let params = SolveParams::default();
    let mut ws = Workspace::new(&model);
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

/// The neck: one simulated second at 4 kHz with the reflex every step and the learned
/// voluntary controller's network (its shape from `experiments/base.toml`'s `[headpose]`,
/// weights from a seeded draw: the time does not depend on them) at 25 Hz; the step alone;
/// and the teacher's equilibrium fit. Single thread.
pub fn bench_neck(seconds: f64, out: &mut impl Write) -> Result<()> {
    use super::headpose::{HeadposeParams, Learned};
    use crate::learn::{Mlp, Normalizer};
    use crate::sim::neck::{simulate, BodyState, Command, HeadPose, PoseSequence};
    let p = HeadposeParams::default();
    let neck = p.neck();
    let mut rng = stream(1, "bench/neck/network");
    let mut uniform = || rng.uniform();
    let normalizer = Normalizer {
        offset: vec![0.0; 9],
        scale: vec![1.0; 9],
    };
    let mlp = Mlp::new(
        9,
        3 * crate::sim::neck::MUSCLES,
        &p.model,
        normalizer,
        &mut uniform,
    )?;
    let targets = PoseSequence::hold(HeadPose::from_degrees(20.0, 30.0, 10.0));
    // Warm-up, then the timed run.
    simulate(
        &neck,
        &mut Learned { mlp: &mlp },
        &targets,
        BodyState::rest(),
        0.05,
        1000,
    )?;
    let t = Instant::now();
    let run = simulate(
        &neck,
        &mut Learned { mlp: &mlp },
        &targets,
        BodyState::rest(),
        seconds,
        1000,
    )?;
    let wall = t.elapsed().as_secs_f64();
    std::hint::black_box(&run);
    line(out, "neck.simulated_seconds", seconds, "s")?;
    line(out, "neck.wall_seconds", wall, "s")?;
    line(out, "neck.realtime_factor", seconds / wall, "x")?;
    let steps = 4000;
    let mut s = BodyState::rest();
    let command = Command::passive();
    let t = Instant::now();
    for n in 0..steps {
        neck.step(&mut s, &command, true, n as f64 / 4000.0)?;
    }
    line(
        out,
        "neck.step.us",
        t.elapsed().as_secs_f64() * 1e6 / steps as f64,
        "us",
    )?;
    let t = Instant::now();
    let calls = 200;
    for k in 0..calls {
        let x = [0.01 * k as f32; 9];
        std::hint::black_box(mlp.predict(&x)?);
    }
    line(
        out,
        "neck.voluntary_network.us",
        t.elapsed().as_secs_f64() * 1e6 / calls as f64,
        "us",
    )?;
    let fits = [
        [0.0, 0.0, 0.0],
        [30.0, 0.0, 0.0],
        [0.0, -40.0, 0.0],
        [-30.0, 40.0, 20.0],
    ];
    let t = Instant::now();
    for d in fits {
        neck.fit(HeadPose::from_degrees(d[0], d[1], d[2]))?;
    }
    line(
        out,
        "neck.teacher_fit.ms",
        t.elapsed().as_secs_f64() * 1e3 / fits.len() as f64,
        "ms",
    )?;
    Ok(())
}

/// `facelab bench landmark`: the picture path per frame on the calling thread: detection,
/// landmarks (MediaPipe's two networks), the metric fit and the observer, on a 640x360 frame
/// (the committed astronaut photo scaled into it), `frames` times each; then a `seconds`-long
/// clip at 24 fps of that frame, from frames in memory to AU rows with tracking, as
/// `observe` runs it.
pub fn bench_landmark(frames: usize, seconds: f64, out: &mut impl Write) -> Result<()> {
    use crate::experiments::observe::model_observer;
    use crate::experiments::photos::{landmark_frames, openface_rows, InputKind};
    use crate::io::calibration::{default_calibration_path, read_calibration};
    use crate::landmark::{metric, Landmarker, RgbFrame};

    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/landmarker/photos/astronaut.png");
    let photo = image::open(&path)?.to_rgb8();
    let scaled = image::imageops::resize(&photo, 360, 360, image::imageops::FilterType::Triangle);
    let mut canvas = image::RgbImage::from_pixel(640, 360, image::Rgb([90, 90, 90]));
    image::imageops::replace(&mut canvas, &scaled, 140, 0);
    let frame = RgbFrame::new(640, 360, canvas.into_raw());

    let landmarker = Landmarker::new()?;
    let model = FaceSource::default().model()?;
    let rest = model.rest_state();
    let rest = rest.surface(model.vertex_count()).to_vec();
    let calibration = read_calibration(&default_calibration_path())?.calibration();
    let observer = model_observer(&model, calibration.clone())?;
    let time = |f: &mut dyn FnMut() -> Result<()>| -> Result<f64> {
        f()?;
        let t = Instant::now();
        for _ in 0..frames {
            f()?;
        }
        Ok(t.elapsed().as_secs_f64() / frames as f64 * 1e3)
    };
    let detection = landmarker.detector.detect(&frame)?;
    let face = anyhow::Context::context(detection.first(), "the bench photo has a face")?.clone();
    let rect = face.face_rect();
    let mesh = landmarker.mesh.run(&frame, &rect)?;
    let detect_ms = time(&mut || {
        std::hint::black_box(landmarker.detector.detect(&frame)?);
        Ok(())
    })?;
    let mesh_ms = time(&mut || {
        std::hint::black_box(landmarker.mesh.run(&frame, &rect)?);
        Ok(())
    })?;
    let fit_ms = time(&mut || {
        std::hint::black_box(metric::fit(&mesh.points, &rest));
        Ok(())
    })?;
    let fitted = metric::fit(&mesh.points, &rest);
    let observe_ms = time(&mut || {
        std::hint::black_box(observer.observe(&landmarks(&fitted.points))?);
        Ok(())
    })?;
    line(out, "landmark.detect_ms", detect_ms, "ms")?;
    line(out, "landmark.mesh_ms", mesh_ms, "ms")?;
    line(out, "landmark.metric_fit_ms", fit_ms, "ms")?;
    line(out, "landmark.observe_ms", observe_ms, "ms")?;
    line(
        out,
        "landmark.frame_detect_ms",
        detect_ms + mesh_ms + fit_ms + observe_ms,
        "ms",
    )?;
    line(
        out,
        "landmark.frame_track_ms",
        mesh_ms + fit_ms + observe_ms,
        "ms",
    )?;

    let n = (seconds * 24.0).round() as usize;
    let clip = vec![frame; n];
    let t = Instant::now();
    let l = landmark_frames(&landmarker, &model, InputKind::Video, clip, 24.0, "bench")?;
    let observer = model_observer(&model, calibration)?;
    let rows = openface_rows(&l, &observer)?;
    std::hint::black_box(&rows);
    line(out, "landmark.clip_frames", n as f64, "count")?;
    line(out, "landmark.clip_s", t.elapsed().as_secs_f64(), "s")?;
    out.flush()?;
    Ok(())
}
