//! The neck's tests: passive behaviour, energy, the fit, the controllers.

use super::*;
use rayon::prelude::*;

fn passive_run(neck: &Neck, seconds: f64, command: &Command) -> BodyState {
    let mut s = BodyState::rest();
    let steps = (seconds * neck.params.simulation_rate) as usize;
    for n in 0..steps {
        neck.step(&mut s, command, false, n as f64 * neck.time_step())
            .unwrap();
    }
    s
}

#[test]
fn passive_head_sags_but_stays_within_the_range_of_motion() {
    let neck = Neck::new(NeckParams::default());
    let s = passive_run(&neck, 3.0, &Command::passive());
    let pose = neck.observe(&s).pose.degrees();
    assert!(pose[0] > 10.0, "the head should sag forward: {pose:?}");
    let q = s.angles();
    for (j, rom) in body::RANGE_OF_MOTION_DEGREES.iter().enumerate() {
        for a in 0..3 {
            let angle = q[3 * j + a].to_degrees().abs();
            assert!(
                angle < rom[a],
                "joint {j} axis {a}: {angle} deg beyond {}",
                rom[a]
            );
        }
    }
    // It has (nearly) come to rest: only a slow creep against the ligaments is left.
    assert!(
        s.velocity.iter().all(|v| v.abs() < 0.02),
        "{:?}",
        s.velocity
    );
}

#[test]
fn symmetric_activations_give_no_yaw_or_roll() {
    let neck = Neck::new(NeckParams::default());
    let mut command = Command::passive();
    for (k, a) in command.activation.iter_mut().enumerate() {
        *a = 0.05 + 0.3 * ((k / 2) % 5) as f64 / 4.0;
    }
    let s = passive_run(&neck, 0.5, &command);
    let pose = neck.observe(&s).pose;
    assert!(pose.yaw.abs() < 1e-9 && pose.roll.abs() < 1e-9, "{pose:?}");
    assert!(
        pose.pitch.abs() > 1e-3,
        "the activations should move the head: {pose:?}"
    );
}

#[test]
fn energy_drifts_little_without_damping() {
    let neck = Neck::new(NeckParams {
        damping: false,
        ..NeckParams::default()
    });
    let mut s = BodyState::rest();
    let e0 = neck.energy(&s);
    let (mut lo, mut hi) = (e0, e0);
    for n in 0..4000 {
        neck.step(&mut s, &Command::passive(), false, n as f64 / 4000.0)
            .unwrap();
        let e = neck.energy(&s);
        lo = lo.min(e);
        hi = hi.max(e);
    }
    // The head falls about 35 degrees and swings: about 0.5 J goes between gravity,
    // springs and motion; the total may wander by a few percent of that.
    assert!(hi - lo < 0.02, "energy wandered {lo} .. {hi} J");
    assert!(
        neck.observe(&s).pose.pitch.abs() > 0.05,
        "the head should have moved"
    );
}

#[test]
fn static_targets_in_the_range_are_reached_within_2_degrees_and_held() {
    let neck = Neck::new(NeckParams::default());
    let targets = [
        [30.0, 0.0, 0.0],
        [-30.0, 0.0, 0.0],
        [0.0, 40.0, 0.0],
        [0.0, -40.0, 0.0],
        [0.0, 0.0, 20.0],
        [0.0, 0.0, -20.0],
        [30.0, 40.0, 20.0],
        [-30.0, -40.0, -20.0],
    ];
    let errors: Vec<(V3, f64)> = targets
        .par_iter()
        .map(|d| {
            let target = HeadPose::from_degrees(d[0], d[1], d[2]);
            let run = simulate(
                &neck,
                &mut Teacher::default(),
                &PoseSequence::hold(target),
                BodyState::rest(),
                2.0,
                40,
            )
            .unwrap();
            let worst = run
                .time
                .iter()
                .zip(&run.pose)
                .filter(|(t, _)| **t >= 1.5)
                .map(|(_, p)| p.error_degrees(target))
                .fold(0.0, f64::max);
            (*d, worst)
        })
        .collect();
    for (d, worst) in errors {
        assert!(
            worst < 2.0,
            "target {d:?}: {worst:.2} deg off over the last 0.5 s"
        );
    }
}

#[test]
fn same_inputs_give_bit_identical_trajectories() {
    let neck = Neck::new(NeckParams::default());
    let targets = PoseSequence {
        fps: 10.0,
        poses: (0..4)
            .map(|k| HeadPose::from_degrees(5.0 * k as f64, -8.0 * k as f64, 3.0))
            .collect(),
    };
    let run = || {
        simulate(
            &neck,
            &mut Teacher::default(),
            &targets,
            BodyState::rest(),
            0.4,
            8,
        )
        .unwrap()
    };
    let (a, b) = (run(), run());
    let bits = |t: &Trajectory| -> Vec<u64> {
        t.pose
            .iter()
            .flat_map(|p| p.to_array().map(f64::to_bits))
            .chain(t.final_state.velocity.iter().map(|v| v.to_bits()))
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
}

#[test]
fn targets_beyond_the_range_are_clamped_with_a_warning_and_nan_is_an_error() {
    let neck = Neck::new(NeckParams::default());
    let seq = PoseSequence {
        fps: 30.0,
        poses: vec![HeadPose::default(), HeadPose::from_degrees(10.0, 80.0, 0.0)],
    };
    let (clamped, warnings) = seq.checked(&neck).unwrap();
    assert_eq!(warnings.len(), 1);
    assert!(
        warnings[0].0 == 1 && warnings[0].1.contains("yaw 80.0 -> 50.0"),
        "{warnings:?}"
    );
    assert!((clamped.poses[1].degrees()[1] - 50.0).abs() < 1e-9);
    let bad = PoseSequence {
        fps: 30.0,
        poses: vec![
            HeadPose::default(),
            HeadPose::default(),
            HeadPose::from_degrees(0.0, 0.0, f64::NAN),
        ],
    };
    let err = simulate(
        &neck,
        &mut Teacher::default(),
        &bad,
        BodyState::rest(),
        0.1,
        10,
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "head pose of frame 2 is not a number (roll)"
    );
}

#[test]
fn fit_holds_the_target_at_equilibrium() {
    let neck = Neck::new(NeckParams::default());
    let target = HeadPose::from_degrees(-20.0, 25.0, 10.0);
    let fit = neck.fit(target).unwrap();
    assert!(fit.error_degrees < 0.1, "{fit:?}");
    assert!(fit.activation.iter().all(|a| (0.0..=1.0).contains(a)));
    // Released at the fitted posture with the fitted activations, it stays.
    let mut s = BodyState::from_angles(&fit.angles);
    let command = Command {
        activation: fit.activation.clone(),
        strain: fit.strain.clone(),
        strain_rate: vec![0.0; MUSCLES],
    };
    for n in 0..2000 {
        neck.step(&mut s, &command, true, n as f64 / 4000.0)
            .unwrap();
    }
    let err = neck.observe(&s).pose.error_degrees(target);
    assert!(err < 0.2, "drifted {err} deg");
}
