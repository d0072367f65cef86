//! `facelab bench neck`: one second of the neck at 4 kHz with both controllers.

use crate::rng::stream;
use anyhow::Result;
use std::io::Write;
use std::time::Instant;

use super::*;

/// The neck: one simulated second at 4 kHz with the reflex every step and the learned
/// voluntary controller's network (its shape from `experiments/base.toml`'s `[headpose]`,
/// weights from a seeded draw: the time does not depend on them) at 25 Hz; the step alone;
/// and the teacher's equilibrium fit. Single thread.
pub fn bench_neck(seconds: f64, out: &mut impl Write) -> Result<()> {
    use crate::headneck::{HeadposeParams, Learned};
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
    let mut done = Vec::with_capacity(fits.len());
    for d in fits {
        done.push(neck.fit(HeadPose::from_degrees(d[0], d[1], d[2]))?);
    }
    line(
        out,
        "neck.teacher_fit.ms",
        t.elapsed().as_secs_f64() * 1e3 / fits.len() as f64,
        "ms",
    )?;
    line(
        out,
        "neck.teacher_fit.steps_mean",
        done.iter().map(|f| f.iterations as f64).sum::<f64>() / fits.len() as f64,
        "count",
    )?;
    line(
        out,
        "neck.teacher_fit.converged",
        done.iter().filter(|f| f.converged).count() as f64,
        "count",
    )?;
    line(
        out,
        "neck.teacher_fit.error_max_deg",
        done.iter().map(|f| f.error_degrees).fold(0.0, f64::max),
        "deg",
    )?;
    Ok(())
}
