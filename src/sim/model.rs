//! `FaceModel`: the static face (surface, tissue sheets, muscles, rig) and `Pose`, the
//! kinematic configuration it takes for a set of activations.
//!
//! Pure: builds from an in-memory mesh (metres); file loading lives in `io::mesh`.

use super::controls::{muscle_index, Activations, JAW_ROTATION, JAW_SLIDE, JAW_TWIST};
use super::geom::{norm, sub, Rigid, V3};
use super::lips::LipMargins;
use super::mesh::{Mesh, MeshError};
use super::muscles::{attach, Bone, LidAction, Muscle, MuscleKind, Side, MUSCLE_PAIRS};
use super::rig::{JawParams, LidParams, Rig, RigError};
use super::tissue::{Tissue, TissueParams, FASCIA, SHEETS, SKULL};

/// Everything that shapes a face model. `Default` is the paper's model at subdivision 0.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FaceParams {
    /// Loop subdivision levels applied to the base mesh: 0, 1 or 2.
    pub subdivisions: u8,
    pub tissue: TissueParams,
    pub jaw: JawParams,
    pub lids: LidParams,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ModelError {
    #[error("face.subdivisions = {0}; must be 0, 1 or 2")]
    Subdivisions(u8),
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Rig(#[from] RigError),
}

/// A fascia node kept off the skull.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    pub node: usize,
    pub vertex: usize,
    /// Smallest allowed distance from the skull node along its normal (m).
    pub clearance: f64,
}

#[derive(Clone, Debug)]
pub struct FaceModel {
    pub params: FaceParams,
    /// The rest surface after subdivision (m).
    pub surface: Mesh,
    pub tissue: Tissue,
    pub rig: Rig,
    /// The 52 muscles in control order.
    pub muscles: Vec<Muscle>,
    /// Per node: solved for (true) or set by the rig (false).
    pub free: Vec<bool>,
    pub contacts: Vec<Contact>,
    /// The lips' inner margins, kept from passing through each other by the solver's lip
    /// contact term (`sim::lips`).
    pub lips: LipMargins,
    /// Per surface vertex: its mirror image across x = 0.
    pub mirror: Vec<usize>,
    /// Width of the face (max x - min x of the surface), the scale for tolerances (m).
    pub face_width: f64,
}

/// The kinematic configuration for one set of activations: where the rig puts the fixed
/// nodes, where the muscle origins are, and where the skull is under each contact.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    pub activations: Activations,
    pub jaw: Rigid,
    /// Positions of all nodes that are not free (entries of free nodes are unused).
    pub fixed: Vec<V3>,
    /// Per muscle: the origin (linear) or centre (sphincter) it pulls toward.
    pub targets: Vec<V3>,
    /// Per contact: skull point and outward normal.
    pub skull: Vec<(V3, V3)>,
}

/// Node positions of a face: all four sheets, `sheet * vertex_count + vertex`.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    pub positions: Vec<V3>,
    /// The activations this state is the equilibrium of.
    pub activations: Activations,
}

impl State {
    /// The outer (epidermal) surface.
    pub fn surface(&self, vertex_count: usize) -> &[V3] {
        &self.positions[..vertex_count]
    }
}

impl FaceModel {
    /// Builds the model from a base mesh in metres (the MediaPipe canonical face with its
    /// eye and mouth holes open).
    pub fn new(base: &Mesh, params: FaceParams) -> Result<FaceModel, ModelError> {
        if params.subdivisions > 2 {
            return Err(ModelError::Subdivisions(params.subdivisions));
        }
        let mut surface = super::rig::open_eyes(base, &params.lids)?;
        for _ in 0..params.subdivisions {
            surface = surface.loop_subdivide();
        }
        let mirror = surface.mirror_map()?;
        let rig = Rig::build(&surface, params.jaw, params.lids)?;
        let tissue = Tissue::build(&surface, &params.tissue);
        let n = surface.vertex_count();

        let mut free = vec![true; SHEETS * n];
        for v in 0..n {
            free[SKULL * n + v] = false;
        }
        let held = rig
            .outer
            .iter()
            .copied()
            .chain(rig.eyes.iter().flat_map(|e| {
                e.upper
                    .iter()
                    .chain(&e.lower)
                    .map(|m| m.vertex)
                    .chain(e.corners)
            }));
        for v in held {
            for sheet in 0..SHEETS {
                free[sheet * n + v] = false;
            }
        }

        let mouth_centre = super::rig::mean(rig.mouth.iter().map(|&v| surface.positions[v]));
        let mut muscles = Vec::with_capacity(2 * MUSCLE_PAIRS.len());
        for pair in 0..MUSCLE_PAIRS.len() {
            for side in [Side::Left, Side::Right] {
                let eye = match side {
                    Side::Right => &rig.eyes[0],
                    Side::Left => &rig.eyes[1],
                };
                let centres = (mouth_centre, eye.contour_centre(&surface.positions));
                let muscle = match side {
                    Side::Right => attach(pair, side, &tissue, |v| v, centres, &free),
                    Side::Left => attach(pair, side, &tissue, |v| mirror[v], centres, &free),
                };
                debug_assert_eq!(muscles.len(), muscle_index(pair, side));
                muscles.push(muscle);
            }
        }

        let contacts = (0..n)
            .filter(|&v| free[FASCIA * n + v])
            .map(|v| Contact {
                node: FASCIA * n + v,
                vertex: v,
                clearance: params.tissue.skull_clearance_fraction * tissue.muscle_layer_depth(v),
            })
            .collect();
        let lips = LipMargins::new(&rig.mouth, &surface.positions);
        let xs = surface.positions.iter().map(|p| p[0]);
        let face_width =
            xs.clone().fold(f64::NEG_INFINITY, f64::max) - xs.fold(f64::INFINITY, f64::min);
        Ok(FaceModel {
            params,
            surface,
            tissue,
            rig,
            muscles,
            free,
            contacts,
            lips,
            mirror,
            face_width,
        })
    }

    pub fn vertex_count(&self) -> usize {
        self.surface.vertex_count()
    }

    pub fn node_count(&self) -> usize {
        self.free.len()
    }

    /// The rest state (all activations neutral).
    pub fn rest_state(&self) -> State {
        State {
            positions: self.tissue.rest.clone(),
            activations: Activations::neutral(),
        }
    }

    /// Where the rig puts vertex `v` of every sheet: its rest position moved by the lids or
    /// blended between skull and mandible.
    fn place(&self, v: usize, rest: V3, jaw: &Rigid) -> V3 {
        let w = self.rig.jaw_weight[v];
        if w == 0.0 {
            rest
        } else {
            super::geom::add(rest, super::geom::scale(jaw.displacement(rest), w))
        }
    }

    /// The kinematic configuration for `a`.
    pub fn pose(&self, a: &Activations) -> Pose {
        let n = self.vertex_count();
        let jaw =
            self.params
                .jaw
                .transform(a.get(JAW_ROTATION), a.get(JAW_SLIDE), a.get(JAW_TWIST));
        let mut fixed = vec![[0.0; 3]; self.node_count()];
        for node in 0..self.node_count() {
            if !self.free[node] {
                fixed[node] = self.place(node % n, self.tissue.rest[node], &jaw);
            }
        }
        for (eye, side) in [(0, Side::Right), (1, Side::Left)] {
            let lid = |action: LidAction| {
                let pair = MUSCLE_PAIRS
                    .iter()
                    .position(|m| m.action == super::muscles::Action::Lid(action))
                    .expect("every lid action has a muscle");
                a.muscle(pair, side)
            };
            let orbital = MUSCLE_PAIRS
                .iter()
                .position(|m| m.au == 6)
                .expect("orbicularis oculi pars orbitalis drives AU06");
            let fractions = self.rig.lid_fractions(
                lid(LidAction::Close),
                lid(LidAction::Tighten),
                lid(LidAction::Raise),
                a.muscle(orbital, side),
            );
            let e = &self.rig.eyes[eye];
            let margins = e
                .upper
                .iter()
                .map(|m| (m, true))
                .chain(e.lower.iter().map(|m| (m, false)));
            for (m, upper) in margins {
                for sheet in 0..SHEETS {
                    let node = sheet * n + m.vertex;
                    fixed[node] =
                        self.rig
                            .lid_motion(eye, m, upper, fractions, self.tissue.rest[node]);
                }
            }
        }
        let targets = self
            .muscles
            .iter()
            .map(|m| match m.kind {
                MuscleKind::Linear { origin, bone, .. } => match bone {
                    Bone::Skull => origin,
                    Bone::Mandible => jaw.apply(origin),
                },
                MuscleKind::Sphincter { centre, .. } => centre,
                MuscleKind::Lid(_) => [0.0; 3],
            })
            .collect();
        let skull = self
            .contacts
            .iter()
            .map(|c| {
                let w = self.rig.jaw_weight[c.vertex];
                (
                    fixed[SKULL * n + c.vertex],
                    Rig::blend_normal(&jaw, w, self.tissue.normals[c.vertex]),
                )
            })
            .collect();
        Pose {
            activations: a.clone(),
            jaw,
            fixed,
            targets,
            skull,
        }
    }

    /// Moves `state` toward `pose`: fixed nodes are set, and free nodes are carried along with
    /// the change of the jaw blend at their vertex (a predictor for warm starts).
    pub fn carry(&self, state: &mut State, from: &Pose, to: &Pose) {
        let n = self.vertex_count();
        for node in 0..self.node_count() {
            if self.free[node] {
                let rest = self.tissue.rest[node];
                let v = node % n;
                let before = self.place(v, rest, &from.jaw);
                let after = self.place(v, rest, &to.jaw);
                let p = state.positions[node];
                state.positions[node] = [
                    p[0] + after[0] - before[0],
                    p[1] + after[1] - before[1],
                    p[2] + after[2] - before[2],
                ];
            } else {
                state.positions[node] = to.fixed[node];
            }
        }
        state.activations = to.activations.clone();
    }

    /// Largest distance of any surface vertex from its rest position (m).
    pub fn max_surface_displacement(&self, state: &State) -> f64 {
        let n = self.vertex_count();
        (0..n)
            .map(|v| norm(sub(state.positions[v], self.tissue.rest[v])))
            .fold(0.0, f64::max)
    }
}
