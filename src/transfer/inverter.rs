//! The inverter: the base model, its linear basis and observer, and the landmark matrix of
//! the basis; the landmark-space fits (Choe et al.'s eq. 10 with the box, and the same fit
//! corrected through the nonlinear face) that the inversion table, the photo table and
//! `facelab transfer --method landmarks` share.

use anyhow::Result;

use crate::boxqp::{accelerated, au_fit, projected_newton, Bound, BoxQp, Solution};
use crate::observe::model_observer;
use crate::observe::{landmarks, Calibration, Observer, AU_COUNT, LANDMARK_COUNT};
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{CONTROL_COUNT, JAW_ROTATION, JAW_SLIDE, JAW_TWIST, MUSCLE_COUNT};
use crate::sim::solver::solve_predicted;
use crate::sim::{Activations, FaceModel, SolveParams, Workspace};

/// The optimization variables: the 52 muscles and the jaw rotation.
pub(crate) fn variables() -> Vec<usize> {
    (0..MUSCLE_COUNT).chain([JAW_ROTATION]).collect()
}

pub(crate) fn activations(x: &[f64]) -> Activations {
    let mut v = [0.0; CONTROL_COUNT];
    for (&c, &value) in variables().iter().zip(x) {
        v[c] = value.clamp(0.0, 1.0);
    }
    v[JAW_SLIDE] = 0.5;
    v[JAW_TWIST] = 0.5;
    Activations::from_values(&v).expect("clamped")
}

/// Landmark displacements flattened (x, y, z per landmark), as the landmark fit takes them.
pub(crate) fn flat(d: &[[f64; 3]; LANDMARK_COUNT]) -> Vec<f64> {
    d.iter().flatten().copied().collect()
}

/// The base model, its basis and observer, and the landmark matrix M (one column per
/// variable: the landmark displacements of its basis field, IOD units).
pub struct Inverter<'a> {
    pub model: &'a FaceModel,
    pub basis: &'a LinearBasis,
    pub observer: Observer,
    pub columns: Vec<Vec<f64>>,
}

impl<'a> Inverter<'a> {
    pub fn new(
        model: &'a FaceModel,
        basis: &'a LinearBasis,
        calibration: &Calibration,
    ) -> Result<Self> {
        let observer = model_observer(model, calibration.clone())?;
        let rest = landmarks(&basis.rest[..basis.vertex_count]);
        let base = observer.displacements(&rest)?;
        let mut columns = Vec::new();
        for c in variables() {
            let mut a = Activations::neutral();
            a.set_index(c, 1.0)?;
            let mut surface = Vec::new();
            basis.evaluate(&a, &mut surface);
            let d = observer.displacements(&landmarks(&surface))?;
            columns.push(
                flat(&d)
                    .iter()
                    .zip(flat(&base))
                    .map(|(x, y)| x - y)
                    .collect(),
            );
        }
        Ok(Inverter {
            model,
            basis,
            observer,
            columns,
        })
    }

    /// AUs of the basis face for variables `x`.
    pub fn basis_aus(&self, x: &[f64], surface: &mut Vec<[f64; 3]>) -> Vec<f64> {
        self.basis.evaluate(&activations(x), surface);
        match self.observer.observe(&landmarks(surface)) {
            Ok(o) => o.aus.to_vec(),
            Err(_) => vec![f64::NAN; AU_COUNT],
        }
    }

    /// The nonlinear face for `a` (from the basis prediction) and its AUs and landmark
    /// displacements.
    pub fn solve(
        &self,
        a: &Activations,
        ws: &mut Workspace,
        params: &SolveParams,
    ) -> Result<([f64; AU_COUNT], Vec<f64>)> {
        let (state, _) = solve_predicted(self.model, self.basis, a, ws, params)?;
        self.read(&state)
    }

    /// The AUs and landmark displacements of a solved face.
    fn read(&self, state: &crate::sim::State) -> Result<([f64; AU_COUNT], Vec<f64>)> {
        let l = landmarks(state.surface(self.model.vertex_count()));
        let o = self.observer.observe(&l)?;
        Ok((o.aus, flat(&self.observer.displacements(&l)?)))
    }

    /// Landmark-space fit of displacements `d` (projected gradient).
    pub fn landmarks_pg(&self, d: &[f64]) -> (Activations, usize) {
        let (s, _) = self.landmarks(d, Bound::Box);
        (activations(&s.a), s.iterations)
    }

    /// Landmark-space fit of displacements `d` corrected through the nonlinear face
    /// (defect correction, as `aus_refined` does in AU space): the box fit on the basis,
    /// then `refinements` times the nonlinear face is solved at the fit, its landmark
    /// displacements' departure from the basis' prediction (`f_nl(x) - M x`) is subtracted
    /// from the target and the box fit repeated from `x`. The basis is stiffer or softer
    /// than the face where muscles bunch or the lips meet, so the basis fit under- or
    /// overshoots there; each correction moves the fit toward what the face itself makes.
    /// Keeps the iterate whose nonlinear face is closest to `d` (RMS over the 68 landmarks);
    /// an iterate the face cannot be solved at ends the corrections. The first fit's face is
    /// solved from the basis prediction, each corrected one from the face before it (a
    /// nearby equilibrium, so Newton needs few steps; from the basis prediction where that
    /// fails), so the answer is a function of `d` alone. The box fits are solved by
    /// projected Newton ([`projected_newton`]), which meets the landmark fits' stationarity
    /// test (1e-6 relative) in a handful of iterations where FISTA takes thousands. With no
    /// corrections nothing is solved and the RMS are `None`.
    pub fn landmarks_refined(
        &self,
        d: &[f64],
        refinements: usize,
        ws: &mut Workspace,
        params: &SolveParams,
    ) -> Result<Refined> {
        let fit = |target: &[f64], start: &[f64]| {
            let qp = BoxQp::least_squares(&self.columns, target);
            projected_newton(&qp, start, 1e-6, 200).a
        };
        let x = fit(d, &vec![0.0; self.columns.len()]);
        if refinements == 0 {
            return Ok(Refined {
                activations: activations(&x),
                rms: None,
                first_rms: None,
                state: None,
            });
        }
        self.corrected(
            x,
            refinements,
            ws,
            params,
            |_, state| {
                let (_, nl) = self.read(state)?;
                let e = rms(&nl, d);
                Ok((e, e, nl))
            },
            |x, nl| {
                let target: Vec<f64> = d
                    .iter()
                    .zip(nl)
                    .enumerate()
                    .map(|(i, (t, n))| {
                        let linear: f64 = self.columns.iter().zip(x).map(|(c, v)| c[i] * v).sum();
                        t - (n - linear)
                    })
                    .collect();
                fit(&target, x)
            },
        )
    }

    /// AU-space fit of readings `r` through the basis: projected Gauss-Newton
    /// ([`au_fit`], forward-difference Jacobian, step test 1e-4, at most 30 iterations) from
    /// `start`, minimizing `|AU(x) - r|^2 + prior |x|^2`. The prior picks, among activations
    /// whose faces read alike, the smallest, and keeps muscles the reading does not ask for
    /// at rest; `prior = 0` is the plain least squares of the inversion table.
    pub fn aus_basis(&self, r: &[f64], start: &[f64], prior: f64) -> Solution {
        let mut surface = Vec::new();
        let w = prior.sqrt();
        let mut f = |x: &[f64]| {
            let mut v = self.basis_aus(x, &mut surface);
            if prior > 0.0 {
                v.extend(x.iter().map(|a| w * a));
            }
            v
        };
        let mut target = r.to_vec();
        if prior > 0.0 {
            target.resize(r.len() + start.len(), 0.0);
        }
        au_fit(&mut f, &target, start, 1e-4, 1e-4, 30)
    }

    /// AU-space fit of readings `r` corrected through the nonlinear face, as
    /// [`Inverter::landmarks_refined`] corrects the landmark fit: the basis fit
    /// ([`Inverter::aus_basis`] from rest), then `refinements` times the nonlinear face is
    /// solved at the fit, its AUs' departure from the basis' reading is subtracted from the
    /// target and the basis fit repeated from `x`. Keeps the iterate whose face's misfit
    /// (`|AU - r|^2 + prior |x|^2`) is least; `rms` is that face's RMS AU error. The faces
    /// are solved at a loosened tolerance, each from the one before it (from the basis
    /// prediction where that fails), so the answer is a function of `r` alone.
    pub fn aus_refined(
        &self,
        r: &[f64],
        prior: f64,
        refinements: usize,
        ws: &mut Workspace,
        params: &SolveParams,
    ) -> Result<Refined> {
        let x = self.aus_basis(r, &vec![0.0; self.columns.len()], prior).a;
        let mut surface = Vec::new();
        self.corrected(
            x,
            refinements,
            ws,
            params,
            |x, state| {
                let (nl, _) = self.read(state)?;
                let squares = nl.iter().zip(r).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
                let cost = squares + prior * x.iter().map(|v| v * v).sum::<f64>();
                Ok((cost, (squares / AU_COUNT as f64).sqrt(), nl))
            },
            |x, nl| {
                let bl = self.basis_aus(x, &mut surface);
                let target: Vec<f64> = (0..AU_COUNT).map(|k| r[k] - (nl[k] - bl[k])).collect();
                self.aus_basis(&target, x, prior).a
            },
        )
    }

    /// Defect correction through the nonlinear face, shared by the landmark and AU fits:
    /// `refinements + 1` times the face is solved at `x` (at the loosened tolerance, from the
    /// face before it, else from the basis prediction), `judge` gives its ranking cost, its
    /// RMS misfit and its reading, and `refit` the next `x` from that reading. Keeps the
    /// iterate of least cost; a face that does not solve ends the corrections (the first must
    /// solve for there to be anything to correct).
    fn corrected<R>(
        &self,
        mut x: Vec<f64>,
        refinements: usize,
        ws: &mut Workspace,
        params: &SolveParams,
        judge: impl Fn(&[f64], &crate::sim::State) -> Result<(f64, f64, R)>,
        mut refit: impl FnMut(&[f64], &R) -> Vec<f64>,
    ) -> Result<Refined> {
        // The faces here only estimate the basis' defect and rank the iterates; whoever
        // takes the activations solves them again at the full tolerance.
        let params = &SolveParams {
            tolerance: params.tolerance * CORRECTION_LOOSENING,
            ..*params
        };
        let mut best: Option<(f64, f64, Vec<f64>, crate::sim::State)> = None;
        let mut first_rms = None;
        let mut last: Option<crate::sim::State> = None;
        for step in 0..=refinements {
            let a = activations(&x);
            let warm = last.take().and_then(|mut state| {
                crate::sim::solve(self.model, &a, &mut state, ws, params)
                    .ok()
                    .map(|_| state)
            });
            let solved = match warm {
                Some(state) => Ok(state),
                None => solve_predicted(self.model, self.basis, &a, ws, params).map(|r| r.0),
            };
            let state = match solved {
                Ok(state) => state,
                Err(e) if step == 0 => return Err(e.into()),
                Err(_) => break,
            };
            let (cost, e, reading) = judge(&x, &state)?;
            first_rms.get_or_insert(e);
            if best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, e, x.clone(), state.clone()));
            }
            last = Some(state);
            if step == refinements {
                break;
            }
            x = refit(&x, &reading);
        }
        let (_, e, x, state) = best.expect("the first step either solved or returned");
        Ok(Refined {
            activations: activations(&x),
            rms: Some(e),
            first_rms,
            state: Some(state),
        })
    }

    /// Landmark-space fit of displacements `d` under `bound`, from rest, to a proximal
    /// gradient of 1e-6 relative (at most 20,000 iterations). Also returns the final
    /// proximal gradient's norm relative to `|M^T d|`, the unit of that test.
    pub fn landmarks(&self, d: &[f64], bound: Bound) -> (Solution, f64) {
        let qp = BoxQp::least_squares(&self.columns, d);
        let s = accelerated(&qp, bound, &vec![0.0; qp.n], 1e-6, 20_000);
        let relative = s.gradient_norm / qp.gradient_scale();
        (s, relative)
    }
}

/// Weight of the squared activations in a transfer's AU-space fit ([`Inverter::aus_refined`]),
/// in squared AU per squared activation: a muscle at full activation costs what a 0.1 AU
/// misfit does, so among activations whose faces read alike the fit takes the smallest and
/// leaves at rest what the reading does not ask for.
pub const AU_PRIOR: f64 = 0.01;

/// How much looser than the caller's the tolerance of [`Inverter::landmarks_refined`]'s
/// solves is: their faces only estimate the basis' defect and rank the iterates, and the
/// kept activations are solved again at the caller's tolerance by whoever takes them.
const CORRECTION_LOOSENING: f64 = 10.0;

/// What [`Inverter::landmarks_refined`] or [`Inverter::aus_refined`] found: the kept
/// activations and the misfit of their nonlinear face and of the uncorrected fit's (RMS over
/// the landmarks in IOD units, or over the AUs).
#[derive(Clone, Debug)]
pub struct Refined {
    pub activations: Activations,
    pub rms: Option<f64>,
    pub first_rms: Option<f64>,
    /// The kept activations' face, solved at the loosened tolerance (a near start for a
    /// solve at the full one).
    pub state: Option<crate::sim::State>,
}

/// The RMS over landmarks of the distance between two landmark sets given as flattened
/// `x, y, z` coordinates: the root of the summed squared coordinate differences per landmark.
pub(crate) fn rms(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), 3 * LANDMARK_COUNT);
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / LANDMARK_COUNT as f64).sqrt()
}
