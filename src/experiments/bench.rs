//! `facelab bench solve`: solve time per sample (cold from rest, warm from the previous
//! sample), model size, and the linear basis' time and landmark error against the nonlinear
//! solve. Prints `name value unit` lines. Run it on a release build.

use std::io::Write;
use std::time::Instant;

use anyhow::Result;

use super::face::FaceSource;
use crate::observe::landmarks;
use crate::rng::stream;
use crate::sim::basis::LinearBasis;
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::geom::{norm, sub, V3};
use crate::sim::solver::solve_predicted;
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

        // Linear basis, and solves started from its prediction.
        let t = Instant::now();
        let basis = LinearBasis::build(&model, &params)?;
        line(
            out,
            &format!("solve.linear.sub{level}.build_s"),
            t.elapsed().as_secs_f64(),
            "s",
        )?;
        let mut predicted_iterations = 0;
        let mut predicted_states = Vec::with_capacity(count);
        let t = Instant::now();
        for a in &batch {
            let (state, r) = solve_predicted(&model, &basis, a, &mut ws, &params)?;
            predicted_iterations += r.iterations;
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
            predicted_iterations as f64 / count as f64,
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
