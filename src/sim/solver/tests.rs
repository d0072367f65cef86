//! The solver's tests: equilibrium, residual, continuation, determinism.

use super::*;
use crate::io::mesh::read_obj;
use crate::rng::stream;
use crate::sim::geom::{norm, scale, sub, V3};
use crate::sim::model::FaceParams;

fn model() -> FaceModel {
    let mesh = read_obj(&crate::io::Layout::here().mesh()).unwrap();
    FaceModel::new(&mesh, FaceParams::default()).unwrap()
}

/// LTW95's springs without the prisms' shear term.
fn springs_only_model() -> FaceModel {
    let mesh = read_obj(&crate::io::Layout::here().mesh()).unwrap();
    let mut params = FaceParams::default();
    params.tissue.shear_modulus_fraction = 0.0;
    FaceModel::new(&mesh, params).unwrap()
}

#[test]
fn softest_mode_is_an_eigenpair_below_every_rayleigh_quotient() {
    let m = model();
    let mut a = Activations::neutral();
    for (name, v) in [
        ("zygomaticus_major_left", 0.9),
        ("zygomaticus_major_right", 0.9),
        ("jaw_rotation", 0.3),
    ] {
        a.set(name, v).unwrap();
    }
    let mut ws = Workspace::new(&m).unwrap();
    let (state, _) = solve_from_rest(&m, &a, &mut ws, &SolveParams::default()).unwrap();
    let mut rng = stream(3, "test/softest_mode");
    for exact in [true, false] {
        let mode = softest_mode(&m, &state, &mut ws, exact, 200).expect("a finite Hessian");
        assert!(mode.stiffness > 0.0, "{mode:?}");
        assert!(mode.eigen_residual < 1e-2, "{mode:?}");
        assert!((0.0..=1.0 + 1e-12).contains(&mode.vertex_share), "{mode:?}");
        assert!(m.free[mode.vertex], "{mode:?}");
        // The smallest eigenvalue bounds the Rayleigh quotient of every direction.
        for _ in 0..20 {
            let v: Vec<f64> = (0..ws.dof()).map(|_| rng.normal()).collect();
            let q = dot_slices(&ws.hessian_times(&v), &v) / dot_slices(&v, &v);
            assert!(
                mode.stiffness <= q,
                "{} > Rayleigh quotient {q}",
                mode.stiffness
            );
        }
    }
}

#[test]
fn a_negative_softest_mode_is_negative_curvature_of_the_energy() {
    // Every free node drawn 2% toward the face's centre compresses the springs; their
    // geometric stiffness then makes the exact Hessian indefinite (without the prisms'
    // shear term, which holds the compressed columns upright).
    let m = springs_only_model();
    let mut state = m.rest_state();
    let count = state.positions.len() as f64;
    let centre = state.positions.iter().fold([0.0; 3], |c, p| {
        [
            c[0] + p[0] / count,
            c[1] + p[1] / count,
            c[2] + p[2] / count,
        ]
    });
    for (node, p) in state.positions.iter_mut().enumerate() {
        if m.free[node] {
            *p = [0, 1, 2].map(|c| centre[c] + 0.98 * (p[c] - centre[c]));
        }
    }
    let pose = m.pose(&state.activations);
    let mut ws = Workspace::new(&m).unwrap();
    assemble(&m, &pose, &state.positions, &mut ws, true, true);
    let (lambda, v, residual) = lowest_eigenpair(&mut ws, 80).expect("a finite Hessian");
    assert!(lambda < 0.0, "smallest eigenvalue {lambda}");
    assert!(residual < 1e-2, "eigen residual {residual}");
    let mode = softest_mode(&m, &state, &mut ws, true, 80).unwrap();
    assert_eq!(mode.stiffness, lambda);
    // The energy's second difference along the mode is its eigenvalue.
    let along = |t: f64| {
        let mut y = state.positions.clone();
        for (node, p) in y.iter_mut().enumerate() {
            let f = ws.pattern.free_index[node];
            if f != NONE {
                for c in 0..3 {
                    p[c] += t * v[3 * f as usize + c];
                }
            }
        }
        energy(&m, &pose, &y)
    };
    let t = 1e-6;
    let curvature = (along(t) - 2.0 * along(0.0) + along(-t)) / (t * t);
    assert!(
        (curvature - lambda).abs() <= 1e-3 * lambda.abs(),
        "energy curvature {curvature} against eigenvalue {lambda}"
    );
}

#[test]
fn gradient_and_hessian_match_finite_differences() {
    check_derivatives(&model(), false);
}

#[test]
fn gradient_and_hessian_match_finite_differences_without_prism_shear() {
    check_derivatives(&springs_only_model(), false);
}

#[test]
fn gradient_and_hessian_match_finite_differences_with_the_lips_in_contact() {
    check_derivatives(&model(), true);
}

#[test]
fn lip_contact_keeps_the_lips_from_passing_through_each_other() {
    // Zygomaticus major and levator anguli oris with the lower half of orbicularis oris
    // drive the lower lip up behind the upper one near the corners; without contact it
    // passes 2.4 mm through.
    let a = crossing_activations();
    let with = model();
    let without = no_lip_contact_model();
    let gap = |m: &FaceModel| {
        let mut ws = Workspace::new(m).unwrap();
        let (s, _) = solve_from_rest(m, &a, &mut ws, &SolveParams::default()).unwrap();
        crate::sim::validity::defects(m, &s).min_lip_gap
    };
    let (open, contact) = (gap(&without), gap(&with));
    assert!(
        open < -1e-3,
        "without contact the lips overlap {:.2} mm",
        open * 1e3
    );
    assert!(
        contact > -crate::sim::validity::CROSSING_TOLERANCE,
        "with contact they overlap {:.2} mm",
        contact * 1e3
    );
}

fn crossing_activations() -> Activations {
    let mut a = Activations::neutral();
    for name in [
        "zygomaticus_major_left",
        "zygomaticus_major_right",
        "levator_anguli_oris_left",
        "levator_anguli_oris_right",
        "orbicularis_oris_lower_left",
        "orbicularis_oris_lower_right",
    ] {
        a.set(name, 1.0).unwrap();
    }
    a
}

fn no_lip_contact_model() -> FaceModel {
    let mesh = read_obj(&crate::io::Layout::here().mesh()).unwrap();
    let mut params = FaceParams::default();
    params.tissue.lip_contact_stiffness = 0.0;
    FaceModel::new(&mesh, params).unwrap()
}

#[test]
fn prism_shear_leaves_the_rest_face_unstressed_and_stiffens_it() {
    let (plain, sheared) = (springs_only_model(), model());
    let a = Activations::neutral();
    let pose = sheared.pose(&a);
    let rest = rest_under(&sheared, &pose);
    let mut ws = Workspace::new(&sheared).unwrap();
    assemble(&sheared, &pose, &rest, &mut ws, false, false);
    // A single muscle at 1e-3 pulls with ~1e-3 N; the rest face must be far below that.
    assert!(
        gradient_norm(&ws) < 1e-12,
        "rest force {:e} N",
        gradient_norm(&ws)
    );
    // Sliding the surface sheet over the dermis (10 um, upward along the surface) costs
    // far more with the shear term: the crossing springs barely resist it. The thinned
    // lips stay put.
    let n = sheared.vertex_count();
    let mut slid = rest.clone();
    let tissue = &sheared.tissue;
    for (v, p) in slid[..n].iter_mut().enumerate() {
        if tissue.thickness_scale[v] < 1.0 {
            continue;
        }
        let normal = tissue.normals[v];
        let up = sub([0.0, 1.0, 0.0], scale(normal, normal[1]));
        let along = scale(up, 1e-5 / norm(up));
        *p = [p[0] + along[0], p[1] + along[1], p[2] + along[2]];
    }
    let cost = |m: &FaceModel| energy(m, &pose, &slid) - energy(m, &pose, &rest);
    assert!(
        cost(&sheared) > 5.0 * cost(&plain),
        "{} J against {} J",
        cost(&sheared),
        cost(&plain)
    );
}

/// With `lips_crossed`, the derivatives are taken at the equilibrium of the model without
/// lip contact for activations that push the lips through each other, so the contact
/// term is active.
fn check_derivatives(m: &FaceModel, lips_crossed: bool) {
    let mut a = Activations::neutral();
    for (name, v) in [
        ("zygomaticus_major_left", 0.8),
        ("orbicularis_oris_upper_left", 0.5),
        ("orbicularis_oculi_orbital_right", 0.5),
        ("frontalis_medial_right", 0.6),
        ("jaw_rotation", 0.27),
    ] {
        a.set(name, v).unwrap();
    }
    if lips_crossed {
        a = crossing_activations();
    }
    let pose = m.pose(&a);
    let mut ws = Workspace::new(m).unwrap();
    let mut rng = stream(7, "test/derivatives");
    let mut x = rest_under(m, &pose);
    if lips_crossed {
        let open = no_lip_contact_model();
        let mut ws = Workspace::new(&open).unwrap();
        x = solve_from_rest(&open, &a, &mut ws, &SolveParams::default())
            .unwrap()
            .0
            .positions;
        let active = m.lips.active(&x);
        assert!(active.len() >= 2, "{} contacts", active.len());
        // Every contact is crossed by far more than the probe below moves a node (noise
        // 2e-6 m, difference steps 1e-7 m times a unit direction), so none switches on or
        // off inside the finite differences.
        let gaps: Vec<f64> = active.iter().map(|c| c.gap).collect();
        assert!(
            gaps.iter().all(|&g| g < -1e-4),
            "contact gaps (m): {gaps:?}"
        );
    }
    // Off equilibrium, so the gradient is large against the difference's error; less so
    // on the crossed lips, whose thin prisms would invert.
    let noise = if lips_crossed { 2e-6 } else { 2e-5 };
    for (node, p) in x.iter_mut().enumerate() {
        if m.free[node] {
            for c in p.iter_mut() {
                *c += noise * rng.normal();
            }
        }
    }
    let dir: Vec<f64> = (0..ws.dof()).map(|_| rng.normal()).collect();
    let free_index = ws.pattern.free_index.clone();
    let moved = |t: f64| {
        let mut y = x.clone();
        for (node, p) in y.iter_mut().enumerate() {
            let f = free_index[node];
            if f != NONE {
                for c in 0..3 {
                    p[c] += t * dir[3 * f as usize + c];
                }
            }
        }
        y
    };
    // With crossed lips only the contact term is checked: the model without it is
    // subtracted, so the stiff tissue terms' difference error on the deformed lips does
    // not hide it.
    let reference = lips_crossed.then(no_lip_contact_model);
    let mut ws_ref = reference.as_ref().map(|r| Workspace::new(r).unwrap());
    let energy_of =
        |y: &[V3]| energy(m, &pose, y) - reference.as_ref().map_or(0.0, |r| energy(r, &pose, y));
    let mut gradient_of = |y: &[V3], ws: &mut Workspace, hessian: bool| -> (Vec<f64>, Vec<f64>) {
        assemble(m, &pose, y, ws, hessian, true);
        let (mut g, mut hv) = (ws.gradient.clone(), ws.hessian_times(&dir));
        if let (Some(r), Some(w)) = (reference.as_ref(), ws_ref.as_mut()) {
            assemble(r, &pose, y, w, hessian, true);
            let hr = w.hessian_times(&dir);
            for i in 0..g.len() {
                g[i] -= w.gradient[i];
                hv[i] -= hr[i];
            }
        }
        (g, hv)
    };
    let h = 1e-7;
    // The contact gap is a ratio over 5 mm segments: its third derivative makes the
    // central difference's own error about 3e-6 of the contact's directional derivative
    // at the best step (measured 2e-8 of 7.4e-3 at 1e-7, 1.3e-6 at 1e-6, 6e-8 at 1e-8).
    let tolerance = if lips_crossed { 1e-5 } else { 1e-6 };
    let (g0, hv) = gradient_of(&x, &mut ws, true);
    let analytic: f64 = g0.iter().zip(&dir).map(|(g, d)| g * d).sum();
    let numeric = (energy_of(&moved(h)) - energy_of(&moved(-h))) / (2.0 * h);
    assert!(
        analytic.abs() > 1e-3,
        "the checked terms are active: {analytic}"
    );
    assert!(
        (analytic - numeric).abs() <= tolerance * analytic.abs().max(1e-9),
        "directional derivative {analytic} vs finite difference {numeric}"
    );
    let (gp, _) = gradient_of(&moved(h), &mut ws, false);
    let (gm, _) = gradient_of(&moved(-h), &mut ws, false);
    let mut err = 0.0f64;
    let mut size = 0.0f64;
    for i in 0..hv.len() {
        let fd = (gp[i] - gm[i]) / (2.0 * h);
        err = err.max((fd - hv[i]).abs());
        size = size.max(fd.abs());
    }
    assert!(
        err <= 1e-5 * size,
        "Hessian-vector product off by {err} of {size}"
    );
}
