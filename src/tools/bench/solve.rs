//! `facelab bench solve`: the face's equilibrium solves, cold, warm and from the basis.

use crate::io::face::FaceSource;
use crate::sim::basis::LinearBasis;
use crate::sim::expression::Expression;
use crate::sim::grid::ExpressionGrid;
use crate::sim::solver::{
    iteration_cost, softest_mode, solve_from_grid, solve_predicted, SoftMode,
};
use crate::sim::{solve, solve_from_rest, Activations, SolveParams, Workspace};
use crate::stats::median;
use anyhow::Result;
use std::io::Write;
use std::time::Instant;

use super::*;

#[allow(clippy::too_many_arguments)]
pub fn bench_solve(
    source: &FaceSource,
    levels: &[u8],
    samples: usize,
    seed: u64,
    grid_steps: usize,
    params: &SolveParams,
    out: &mut impl Write,
) -> Result<()> {
    if (1..3).contains(&grid_steps) {
        anyhow::bail!(
            "--grid {grid_steps}: the grid's cubics need 3 or more intervals (0 for none)"
        );
    }
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
        let mut ws = Workspace::new(&model)?;
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
            // More than one piece: Newton from the prediction failed and the solve followed
            // the continuation path, from a fraction of the prediction or from rest.
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
        // Chains, as the dataset could solve a chunk: per expression, draws of s and jaw
        // (4 x the batch over the six), ordered by `chain_order`, solved as one clip
        // (`table2::solve_clip`: the first from the prediction, each next by continuation from
        // the one before); against the same draws each from the basis prediction.
        if level == 0 {
            let mut rng = stream(seed, "bench/solve/chains");
            let per = (4 * count / 6).max(2);
            let (mut independent, mut chained) = (0.0, 0.0);
            let colds = std::cell::Cell::new(0usize);
            let mut drawn = 0usize;
            let (mut chain_apart, mut chain_off) = (0.0f64, 0usize);
            for e in crate::sim::expression::Expression::ALL {
                let draws: Vec<_> = (0..per)
                    .map(|_| {
                        let (s, jaw) = (rng.uniform(), rng.uniform());
                        weights.sample(e, s, jaw)
                    })
                    .collect();
                drawn += draws.len();
                let t = Instant::now();
                let mut alone = Vec::with_capacity(per);
                for a in &draws {
                    alone.push(solve_predicted(&model, &basis, a, &mut ws, &params)?.0);
                }
                independent += t.elapsed().as_secs_f64();
                let order = chain_order(&draws);
                let chain: Vec<Activations> = order.iter().map(|&i| draws[i].clone()).collect();
                let mut solved: Vec<Option<crate::sim::State>> = vec![None; per];
                let t = Instant::now();
                crate::transfer::network::solve_clip(
                    &model,
                    &chain,
                    |a, ws| {
                        colds.set(colds.get() + 1);
                        Ok(solve_predicted(&model, &basis, a, ws, &params)?.0)
                    },
                    &mut ws,
                    &params,
                    |f, s| {
                        solved[order[f]] = Some(s.clone());
                        Ok(())
                    },
                )?;
                chained += t.elapsed().as_secs_f64();
                for (a, b) in alone.iter().zip(&solved) {
                    let b = b.as_ref().expect("every draw solved");
                    let d = landmark_error(a.surface(n), b.surface(n)).1;
                    chain_apart = chain_apart.max(d);
                    chain_off += usize::from(d > 1e-5);
                }
            }
            let c = "solve.chain.sub0";
            line(out, &format!("{c}.samples"), drawn as f64, "count")?;
            line(
                out,
                &format!("{c}.predicted_ms_per_sample"),
                independent * 1e3 / drawn as f64,
                "ms",
            )?;
            line(
                out,
                &format!("{c}.chained_ms_per_sample"),
                chained * 1e3 / drawn as f64,
                "ms",
            )?;
            line(
                out,
                &format!("{c}.cold_starts"),
                colds.get() as f64,
                "count",
            )?;
            line(
                out,
                &format!("{c}.chained_vs_predicted_landmark_max_mm"),
                chain_apart * 1e3,
                "mm",
            )?;
            line(
                out,
                &format!("{c}.samples_over_0.01_mm_apart"),
                chain_off as f64,
                "count",
            )?;
        }

        // The grid's interpolated equilibria as starts (`dataset.grid`), at subdivision 0:
        // speed, and how many faces end on another equilibrium than the solve from rest's
        // (over 0.01 mm, the tolerance's slack; over 0.1 mm, another equilibrium), against
        // the basis' start.
        if level == 0 && grid_steps > 0 {
            let g = format!("solve.grid{grid_steps}.sub0");
            let t = Instant::now();
            let grid =
                ExpressionGrid::build(&model, &weights, &Expression::ALL, grid_steps, &params)?;
            line(out, &format!("{g}.build_s"), t.elapsed().as_secs_f64(), "s")?;
            let mut iterations = Vec::with_capacity(count);
            let mut solved = Vec::with_capacity(count);
            let t = Instant::now();
            for (&draw, a) in random_draws(seed, count).iter().zip(&batch) {
                let (state, r) =
                    solve_from_grid(&model, &grid, Some(&basis), draw, a, &mut ws, &params)?;
                iterations.push(r.iterations as f64);
                solved.push(state);
            }
            let ms = t.elapsed().as_secs_f64() * 1e3 / count as f64;
            line(out, &format!("{g}.ms_per_sample"), ms, "ms")?;
            line(
                out,
                &format!("{g}.iterations_per_sample"),
                iterations.iter().sum::<f64>() / count as f64,
                "count",
            )?;
            line(
                out,
                &format!("{g}.iterations_median"),
                median(&mut iterations),
                "count",
            )?;
            for (name, faces) in [("grid", &solved), ("predicted", &predicted_states)] {
                let apart: Vec<f64> = faces
                    .iter()
                    .zip(&states)
                    .map(|(a, b)| landmark_error(a.surface(n), b.surface(n)).1)
                    .collect();
                let over = |mm: f64| apart.iter().filter(|&&d| d > mm * 1e-3).count() as f64;
                line(
                    out,
                    &format!("{g}.{name}_vs_cold_over_0.01_mm"),
                    over(0.01),
                    "count",
                )?;
                line(
                    out,
                    &format!("{g}.{name}_vs_cold_over_0.1_mm"),
                    over(0.1),
                    "count",
                )?;
                let max = apart.iter().copied().fold(0.0, f64::max);
                line(
                    out,
                    &format!("{g}.{name}_vs_cold_landmark_max_mm"),
                    max * 1e3,
                    "mm",
                )?;
            }
        }

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

/// An order of `draws` for solving them as a chain: from the draw nearest neutral, always on to
/// the nearest (in activation space) not yet visited. Depends only on the draws.
fn chain_order(draws: &[Activations]) -> Vec<usize> {
    let distance = |a: &Activations, b: &Activations| -> f64 {
        a.values()
            .iter()
            .zip(b.values())
            .map(|(x, y)| (x - y) * (x - y))
            .sum()
    };
    let mut left: Vec<usize> = (0..draws.len()).collect();
    let mut order = Vec::with_capacity(draws.len());
    let mut here = Activations::neutral();
    while !left.is_empty() {
        let (k, _) = left
            .iter()
            .enumerate()
            .map(|(k, &i)| (k, distance(&here, &draws[i])))
            .fold(
                (0, f64::INFINITY),
                |best, c| if c.1 < best.1 { c } else { best },
            );
        let i = left.swap_remove(k);
        here = draws[i].clone();
        order.push(i);
    }
    order
}
