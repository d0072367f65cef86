//! Choe et al. 2001 in facelab: landmark-space inversion over the linear basis, keyframe
//! editing and retargeting from the command line.

use std::path::PathBuf;
use std::sync::OnceLock;

use facelab::boxqp::{accelerated, projected_gradient, projected_newton, Bound, BoxQp};
use facelab::io::calibration::read_calibration;
use facelab::observe::landmarks;
use facelab::sim::basis::LinearBasis;
use facelab::sim::controls::{JAW_ROTATION, MUSCLE_COUNT};
use facelab::sim::{solve_from_rest, Activations, SolveParams, Workspace};
use facelab::transfer::inverter::Inverter;

fn basis() -> &'static LinearBasis {
    static BASIS: OnceLock<LinearBasis> = OnceLock::new();
    BASIS.get_or_init(|| LinearBasis::build(crate::model(), &SolveParams::default()).unwrap())
}

fn inverter() -> Inverter<'static> {
    let calibration = read_calibration(&facelab::io::Layout::here().calibration())
        .unwrap()
        .calibration();
    Inverter::new(crate::model(), basis(), &calibration).unwrap()
}

/// Joy at s = 0.7 with the jaw a little open: the variables (52 muscles, jaw rotation).
fn known() -> (Activations, Vec<f64>) {
    let weights = facelab::io::face::FaceSource::of(&facelab::io::Layout::here())
        .weights()
        .unwrap();
    let a = weights.sample(facelab::sim::expression::Expression::Joy, 0.7, 0.2);
    let x = (0..MUSCLE_COUNT)
        .chain([JAW_ROTATION])
        .map(|c| a.get(c))
        .collect();
    (a, x)
}

/// The landmark displacements of the nonlinear face for `a`, solved from rest (the target a
/// landmark fit takes, flattened).
fn solved_displacements(inv: &Inverter, a: &Activations, ws: &mut Workspace) -> Vec<f64> {
    let (state, _) = solve_from_rest(crate::model(), a, ws, &SolveParams::default()).unwrap();
    let l = landmarks(state.surface(crate::model().vertex_count()));
    inv.observer
        .displacements(&l)
        .unwrap()
        .iter()
        .flatten()
        .copied()
        .collect()
}

#[test]
fn landmark_inversion_recovers_the_models_own_activations() {
    let inv = inverter();
    let (a, truth) = known();
    // The basis face's own displacements: exactly representable.
    let d: Vec<f64> = (0..inv.columns[0].len())
        .map(|i| inv.columns.iter().zip(&truth).map(|(c, t)| c[i] * t).sum())
        .collect();
    let (got, iterations) = inv.landmarks_pg(&d);
    let x: Vec<f64> = (0..MUSCLE_COUNT)
        .chain([JAW_ROTATION])
        .map(|c| got.get(c))
        .collect();
    let qp = BoxQp::least_squares(&inv.columns, &d);
    let rms = (qp.residual(&x) / 68.0).sqrt();
    let worst = x
        .iter()
        .zip(&truth)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    println!("basis landmarks: {iterations} iterations, landmark RMS {rms:.2e} IOD, largest activation error {worst:.3}");
    assert!(rms < 1e-4, "landmark RMS {rms}");
    assert!(got.values().iter().all(|v| (0.0..=1.0).contains(v)));

    // From the nonlinear face: the basis is an approximation, so the fit is too.
    let mut ws = Workspace::new(crate::model()).unwrap();
    let d = solved_displacements(&inv, &a, &mut ws);
    let (got, _) = inv.landmarks_pg(&d);
    let (_, solved) = inv.solve(&got, &mut ws, &SolveParams::default()).unwrap();
    let rms = (solved
        .iter()
        .zip(&d)
        .map(|(p, q)| (p - q).powi(2))
        .sum::<f64>()
        / 68.0)
        .sqrt();
    let mean_error = (0..MUSCLE_COUNT)
        .chain([JAW_ROTATION])
        .map(|c| (got.get(c) - a.get(c)).abs())
        .sum::<f64>()
        / (MUSCLE_COUNT + 1) as f64;
    println!(
        "nonlinear landmarks: landmark RMS {rms:.4} IOD, mean activation error {mean_error:.3}"
    );
    assert!(rms < 0.01, "landmark RMS {rms}");

    // Choe's eq. 10 with its linear penalty converges, on the real basis, to the box
    // solution: c = 100 is far above the fit's largest gradient.
    let qp = BoxQp::least_squares(&inv.columns, &d);
    let boxed = projected_gradient(&qp, &vec![0.0; qp.n], 1e-6, 20_000);
    let penalty = accelerated(&qp, Bound::Penalty(100.0), &vec![0.0; qp.n], 1e-6, 20_000);
    println!(
        "Choe's penalty: {} iterations, proximal gradient {:.1e}; box: {} iterations",
        penalty.iterations, penalty.gradient_norm, boxed.iterations
    );
    assert!(boxed.converged && penalty.converged);
    // The same fit (the activations may differ along the basis' near-flat directions).
    let gap = (penalty.residual - boxed.residual).abs() / boxed.residual.max(1e-12);
    assert!(
        gap < 1e-3,
        "residual {} vs box {}",
        penalty.residual,
        boxed.residual
    );
    assert!(penalty.a.iter().all(|v| (-1e-9..=1.0 + 1e-9).contains(v)));
}

use crate::facelab;

#[test]
fn edit_command_meets_keys_and_names_bad_ones() {
    let dir = crate::temp("choe", "edit");
    let input = dir.join("curves.csv");
    let mut text = String::from("frame,zygomaticus_major_left,jaw_rotation\n");
    for f in 0..60 {
        let t = f as f64;
        text.push_str(&format!(
            "{f},{:.4},{:.4}\n",
            0.4 + 0.2 * (0.5 * t).sin(),
            0.1
        ));
    }
    std::fs::write(&input, text).unwrap();
    let out: PathBuf = dir.join("edited.csv");
    let o = facelab(&[
        "edit",
        "--curves",
        input.to_str().unwrap(),
        "--key",
        "20:zygomaticus_major_left=0.95",
        "--knot-spacing",
        "4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let edited = std::fs::read_to_string(&out).unwrap();
    let rows: Vec<Vec<f64>> = edited
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    let original: Vec<Vec<f64>> = std::fs::read_to_string(&input)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    assert!((rows[20][1] - 0.95).abs() < 1e-6, "{:?}", rows[20]);
    for (f, (e, o)) in rows.iter().zip(&original).enumerate() {
        assert!((e[2] - o[2]).abs() < 1e-9, "jaw changed at {f}");
        if (f as f64 - 20.0).abs() >= 16.0 {
            assert!((e[1] - o[1]).abs() < 1e-9, "frame {f} changed");
        }
    }

    for (key, expect) in [
        (
            "20:zygomaticus_mayor_left=0.5",
            "did you mean `zygomaticus_major_left`",
        ),
        ("20:zygomaticus_major_left=1.5", "outside [0, 1]"),
        ("200:zygomaticus_major_left=0.5", "no such frame"),
    ] {
        let o = facelab(&[
            "edit",
            "--curves",
            input.to_str().unwrap(),
            "--key",
            key,
            "--out",
            dir.join("bad.csv").to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(expect), "{key}: {err}");
        assert!(!dir.join("bad.csv").exists());
    }
}

/// A frame the warm solve cannot reach (on subject 1, frame 15's equilibrium carried to frame
/// 16's activations inverts a prism) is solved again from rest, as a transfer's frames are,
/// instead of ending the retarget: it used to stop with "subject 1: frame 16: the activation
/// path could not be followed".
#[test]
fn retarget_solves_a_frame_from_rest_where_the_warm_start_inverts() {
    let dir = crate::temp("choe", "retarget");
    let curves = crate::root().join("tests/data/retarget/warm_start_inverts.csv");
    let o = facelab(&[
        "retarget",
        "--curves",
        curves.to_str().unwrap(),
        "--subjects",
        "2",
        "--frames",
        "16",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let grid = image::open(dir.join("retarget.png")).unwrap();
    assert!(grid.width() > 3 * 240, "{}", grid.width());
    assert!(dir.join("retarget.gif").exists());
}

/// Where the basis' prediction of a strong expression inverts prisms, `solve_predicted`
/// starts from the prediction of a fraction of it and continues along the ray from neutral:
/// it reaches the equilibrium the solve from rest reaches, within the landmark slack of the
/// solver's tolerance (`bench solve`: up to 0.07 mm).
#[test]
fn a_predicted_solve_reaches_the_equilibrium_of_the_solve_from_rest() {
    use facelab::sim::geom::{norm, sub};
    use facelab::sim::solver::solve_predicted;
    let model = crate::model();
    let weights = facelab::io::face::FaceSource::of(&facelab::io::Layout::here())
        .weights()
        .unwrap();
    let mut ws = Workspace::new(model).unwrap();
    let params = SolveParams::default();
    let n = model.vertex_count();
    let mut continued = 0;
    for (e, jaw) in facelab::sim::expression::Expression::ALL
        .into_iter()
        .flat_map(|e| [0.4, 1.0].map(|j| (e, j)))
    {
        let a = weights.sample(e, 1.0, jaw);
        let (predicted, report) = solve_predicted(model, basis(), &a, &mut ws, &params).unwrap();
        continued += usize::from(report.pieces > 1);
        let (rest, _) = solve_from_rest(model, &a, &mut ws, &params).unwrap();
        let apart = predicted.positions[..n]
            .iter()
            .zip(&rest.positions[..n])
            .map(|(&p, &q)| norm(sub(p, q)))
            .fold(0.0, f64::max);
        println!(
            "{e} at jaw {jaw}: {} pieces, {:.4} mm from the solve from rest",
            report.pieces,
            apart * 1e3
        );
        assert!(
            apart < 1e-4,
            "{e} at jaw {jaw}: {:.4} mm apart",
            apart * 1e3
        );
    }
    assert!(
        continued > 0,
        "every prediction converged: nothing continued"
    );
}

/// The landmark fit corrected through the nonlinear face: on the nonlinear face's own joy at
/// s = 1 with the jaw open (where the basis, the face linearized at rest, is furthest off),
/// two corrections bring the solved face's landmarks closer to the target than the fit on the
/// basis alone, and hand back the kept face; with none, nothing is solved.
#[test]
fn correcting_the_landmark_fit_through_the_face_brings_its_landmarks_closer() {
    let inv = inverter();
    let weights = facelab::io::face::FaceSource::of(&facelab::io::Layout::here())
        .weights()
        .unwrap();
    let a = weights.sample(facelab::sim::expression::Expression::Joy, 1.0, 0.4);
    let params = SolveParams::default();
    let mut ws = Workspace::new(crate::model()).unwrap();
    let d = solved_displacements(&inv, &a, &mut ws);
    let plain = inv.landmarks_refined(&d, 0, &mut ws, &params).unwrap();
    assert!(plain.rms.is_none() && plain.state.is_none());
    let refined = inv.landmarks_refined(&d, 2, &mut ws, &params).unwrap();
    let (rms, first) = (refined.rms.unwrap(), refined.first_rms.unwrap());
    println!(
        "landmark RMS of the solved face: {first:.5} IOD fitted on the basis, {rms:.5} corrected"
    );
    assert!(rms < 0.3 * first, "{first} -> {rms}");
    assert!(refined.state.is_some());
    // The uncorrected fit is the box fit on the basis the other methods use.
    let (pg, _) = inv.landmarks_pg(&d);
    let gap = pg
        .values()
        .iter()
        .zip(plain.activations.values())
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    assert!(gap < 0.05, "projected Newton and FISTA differ by {gap}");
    // Projected Newton meets the landmark fits' stationarity test within its 200 iterations.
    let qp = BoxQp::least_squares(&inv.columns, &d);
    let newton = projected_newton(&qp, &vec![0.0; qp.n], 1e-6, 200);
    let fista = projected_gradient(&qp, &vec![0.0; qp.n], 1e-6, 20_000);
    println!(
        "box fit: projected Newton {} iterations, FISTA {}",
        newton.iterations, fista.iterations
    );
    assert!(newton.converged, "{} iterations", newton.iterations);
}
