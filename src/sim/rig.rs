//! Kinematic parts of the face: the mandible (rotation about the temporomandibular axis,
//! forward slide, twist) and the eyelid margins (rotation about the eyeball centre).
//!
//! The skull sheet under the lower face moves with the mandible, blended by a per-vertex jaw
//! weight (1 on the mandible, 0 on the maxilla and cranium, a harmonic blend between), so the
//! soft tissue is dragged by the bone as in a real jaw opening. The lid margins stand for the
//! tarsal plates, stiff plates that slide over the globe; they rotate rigidly about an axis
//! through the eyeball centre, driven by the lid muscles. Depends on `geom`, `mesh`.

use super::geom::{add, lerp, norm, normalize, scale, sub, Rigid, Rot3, V3};
use super::mesh::Mesh;

/// Mandible kinematics. Defaults from adult anatomy: the condyles sit ~1 cm in front of the
/// tragus at about the level of the nasal floor; maximal rotation of the mandible in normal
/// opening is 15-20 degrees before translation dominates; protrusion reaches ~8 mm and
/// lateral excursion ~10 mm at the incisors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JawParams {
    /// A point on the temporomandibular axis (m); the axis runs along x through it.
    pub pivot: V3,
    /// Opening angle at `jaw_rotation = 1` (rad). Default 24 degrees: the maximal opening,
    /// which moves the lower lip's midpoint 40 mm (42-46 mm in forceful depression, a PUMCH
    /// motion-capture thesis in shared/facs-magnitudes.md; interincisal 44-57 mm).
    pub max_rotation: f64,
    /// Forward (+z) translation at `jaw_slide = 1`, backward at 0 (m). Default 4 mm.
    pub slide_range: f64,
    /// Rotation about the vertical axis at `jaw_twist = 1` (toward the subject's left),
    /// opposite at 0 (rad). Default 6 degrees.
    pub twist_range: f64,
    /// Width of the blend between mandible and maxilla above and below the occlusal line (m).
    /// Default 1 cm.
    pub blend_width: f64,
}

impl Default for JawParams {
    fn default() -> Self {
        JawParams {
            pivot: [0.0, 0.003, -0.026],
            max_rotation: 24f64.to_radians(),
            slide_range: 0.004,
            twist_range: 6f64.to_radians(),
            blend_width: 0.01,
        }
    }
}

impl JawParams {
    /// The mandible's rigid motion for the three jaw inputs (each in [0, 1]).
    pub fn transform(&self, rotation: f64, slide: f64, twist: f64) -> Rigid {
        let open = Rot3::about_axis([1.0, 0.0, 0.0], rotation * self.max_rotation);
        let turn = Rot3::about_axis([0.0, 1.0, 0.0], (2.0 * twist - 1.0) * self.twist_range);
        Rigid {
            rotation: turn.mul(&open),
            pivot: self.pivot,
            translation: [0.0, 0.0, (2.0 * slide - 1.0) * self.slide_range],
        }
    }
}

/// How far each lid muscle turns the margins, as fractions of the angle that would bring the
/// upper and lower margins together. The pretarsal part alone closes the eye until the lids
/// meet (a blink: the upper lid travels 8.2 mm, inside the 8-12 mm of a full closure), the
/// preseptal part narrows it by about a third (lid tightener, lower lid up 3.3 mm), and the
/// levator raises the upper lid by 3.5 mm (a few mm above primary gaze). The orbital part of
/// orbicularis oculi raises the cheek, which pushes the lower lid up (FACS AU6: the
/// infraorbital triangle and lower lid rise): `cheek_lower` per unit of its activation, set
/// so the lower lid rises 5 mm (2.5-6 mm published for a grin). Distances from
/// `facelab face reach`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LidParams {
    /// Depth of the eyeball centre behind the line joining the eye corners (m). Default 12 mm
    /// (the globe's radius).
    pub eyeball_depth: f64,
    pub close_upper: f64,
    pub close_lower: f64,
    pub tighten_upper: f64,
    pub tighten_lower: f64,
    pub raise_upper: f64,
    pub cheek_lower: f64,
    /// Largest closed fraction; at 1 the margins meet.
    pub max_closure: f64,
    /// Palpebral aperture the rest face is opened to where the mesh's is narrower (m).
    /// Default 10.5 mm, within adults' 9.7 +/- 1.2 mm in primary gaze (Read et al. 2006); the
    /// canonical face has 6.7 mm, too narrow for the upper lid to travel the 8-12 mm of a
    /// full closure. Toward the wide end so it does with the lower lid taking 15%.
    pub rest_aperture: f64,
    /// How far from the eyeball centre the opening of the upper lid reaches (m). Default
    /// 22 mm, below the brow.
    pub upper_lid_reach: f64,
}

impl Default for LidParams {
    fn default() -> Self {
        LidParams {
            eyeball_depth: 0.012,
            close_upper: 0.85,
            close_lower: 0.15,
            tighten_upper: 0.15,
            tighten_lower: 0.35,
            raise_upper: 0.35,
            cheek_lower: 0.35,
            max_closure: 1.0,
            rest_aperture: 10.5e-3,
            upper_lid_reach: 0.022,
        }
    }
}

/// A lid margin vertex: the angle (rad) about the eye axis that would bring it to the
/// opposite margin, and the radial scale (distance from the axis, meeting point over rest) it
/// reaches when the eye is closed, so the margins meet although they lie at different depths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Margin {
    pub vertex: usize,
    pub angle: f64,
    pub closed_scale: f64,
}

/// Fraction of the closing angle turned by the margin vertices next to the eye corners.
const CANTHUS_TAPER: f64 = 0.6;

/// One eye's lid margins, turning about an x-parallel axis through `centre`.
#[derive(Clone, Debug, PartialEq)]
pub struct Eye {
    pub centre: V3,
    pub upper: Vec<Margin>,
    pub lower: Vec<Margin>,
    /// The eye's boundary loop (with the corners), for rendering and the sphincter.
    pub contour: Vec<usize>,
    /// The eye corners (canthi), held to the skull by the canthal tendons.
    pub corners: [usize; 2],
}

impl Eye {
    /// Mean position of the contour at rest.
    pub fn contour_centre(&self, positions: &[V3]) -> V3 {
        mean(self.contour.iter().map(|&v| positions[v]))
    }
}

/// The face's holes and kinematic parts.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    pub jaw: JawParams,
    pub lids: LidParams,
    /// Per surface vertex: 1 = moves with the mandible, 0 = fixed to the skull.
    pub jaw_weight: Vec<f64>,
    /// Outer boundary of the face mesh; all its sheets are held by the skull or mandible.
    pub outer: Vec<usize>,
    pub mouth: Vec<usize>,
    /// Right eye (subject's right, -x) first.
    pub eyes: [Eye; 2],
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RigError {
    #[error("the face mesh has {0} boundary loops; expected 4 (outline, mouth, two eyes)")]
    LoopCount(usize),
    #[error("the face mesh is not mirror-symmetric, so its eyes cannot be opened alike")]
    Asymmetric,
}

/// Mean of a set of points.
pub fn mean(points: impl Iterator<Item = V3>) -> V3 {
    let mut sum = [0.0; 3];
    let mut count = 0usize;
    for p in points {
        sum = add(sum, p);
        count += 1;
    }
    scale(sum, 1.0 / count.max(1) as f64)
}

/// Splits a closed contour at its leftmost and rightmost vertices into its upper and lower
/// paths (corners excluded) and returns (corner_min_x, corner_max_x, upper, lower).
pub fn split_contour(contour: &[usize], p: &[V3]) -> (usize, usize, Vec<usize>, Vec<usize>) {
    let by_x = |a: &&usize, b: &&usize| p[**a][0].total_cmp(&p[**b][0]).then(a.cmp(b));
    let c0 = *contour.iter().min_by(by_x).unwrap();
    let c1 = *contour.iter().max_by(by_x).unwrap();
    let n = contour.len();
    let i0 = contour.iter().position(|&v| v == c0).unwrap();
    let i1 = contour.iter().position(|&v| v == c1).unwrap();
    let walk = |from: usize, to: usize| -> Vec<usize> {
        let mut out = Vec::new();
        let mut i = (from + 1) % n;
        while i != to {
            out.push(contour[i]);
            i = (i + 1) % n;
        }
        out
    };
    let a = walk(i0, i1);
    let b = walk(i1, i0);
    let mean_y = |path: &[usize]| path.iter().map(|&v| p[v][1]).sum::<f64>() / path.len() as f64;
    if mean_y(&a) > mean_y(&b) {
        (c0, c1, a, b)
    } else {
        (c0, c1, b, a)
    }
}

/// Position along `path` (plus its corners) at abscissa `x`, linear in x.
fn at_x(path: &[usize], corners: (usize, usize), x: f64, p: &[V3]) -> V3 {
    let mut pts: Vec<V3> = path.iter().map(|&v| p[v]).collect();
    pts.push(p[corners.0]);
    pts.push(p[corners.1]);
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]));
    for w in pts.windows(2) {
        if x >= w[0][0] && x <= w[1][0] {
            let t = if w[1][0] > w[0][0] {
                (x - w[0][0]) / (w[1][0] - w[0][0])
            } else {
                0.0
            };
            return lerp(w[0], w[1], t);
        }
    }
    pts[0]
}

/// Angle of `q - c` in the y-z plane, measured from +z toward +y.
fn elevation(q: V3, c: V3) -> f64 {
    let d = sub(q, c);
    d[1].atan2(d[2])
}

/// Laplace smoothing of `weight` on the mesh graph, holding the `fixed` vertices (500 Jacobi
/// sweeps, enough for the face mesh's graph diameter at every subdivision level used).
fn harmonic(mesh: &Mesh, mut weight: Vec<f64>, fixed: &[bool]) -> Vec<f64> {
    let neighbours = mesh.neighbours();
    for _ in 0..500 {
        let next: Vec<f64> = (0..weight.len())
            .map(|v| {
                if fixed[v] || neighbours[v].is_empty() {
                    weight[v]
                } else {
                    neighbours[v].iter().map(|&u| weight[u]).sum::<f64>()
                        / neighbours[v].len() as f64
                }
            })
            .collect();
        weight = next;
    }
    weight
}

/// Rest aperture of an eye: the vertical gap between its upper and lower margins at the
/// middle of the eye (m).
pub fn eye_aperture(contour: &[usize], p: &[V3]) -> f64 {
    let (c0, c1, upper, lower) = split_contour(contour, p);
    let x = 0.5 * (p[c0][0] + p[c1][0]);
    at_x(&upper, (c0, c1), x, p)[1] - at_x(&lower, (c0, c1), x, p)[1]
}

/// Opens the eyes of a rest surface to `lids.rest_aperture` where they are narrower: the
/// upper lid turns up about the eye axis (as the tarsal plate does), by the angle that
/// lifts the margin's middle to the target, blended harmonically to nothing at the lower
/// margin, the corners and `lids.upper_lid_reach` from the eye centre. The subject's left
/// eye gets the mirror image of the right one's change, so the face stays symmetric.
pub fn open_eyes(mesh: &Mesh, lids: &LidParams) -> Result<Mesh, RigError> {
    let rig = Rig::build(mesh, JawParams::default(), *lids)?;
    let mirror = mesh.mirror_map().map_err(|_| RigError::Asymmetric)?;
    let p = &mesh.positions;
    let eye = &rig.eyes[0];
    let aperture = eye_aperture(&eye.contour, p);
    let mut out = mesh.clone();
    if aperture >= lids.rest_aperture {
        return Ok(out);
    }
    let (c0, c1, upper, lower) = split_contour(&eye.contour, p);
    let mid = at_x(&upper, (c0, c1), 0.5 * (p[c0][0] + p[c1][0]), p);
    let radius = (mid[1] - eye.centre[1]).hypot(mid[2] - eye.centre[2]);
    let angle = (lids.rest_aperture - aperture) / radius;
    let n = mesh.vertex_count();
    let mut weight = vec![0.0; n];
    let mut fixed = vec![false; n];
    for v in 0..n {
        if norm(sub(p[v], eye.centre)) > lids.upper_lid_reach || p[v][0] > 0.0 {
            fixed[v] = true;
        }
    }
    for &v in &upper {
        weight[v] = 1.0;
        fixed[v] = true;
    }
    for &v in lower.iter().chain([&c0, &c1]) {
        fixed[v] = true;
    }
    let weight = harmonic(mesh, weight, &fixed);
    for v in 0..n {
        // Only the upper lid moves: vertices below the eye's corner line keep their place.
        if weight[v] <= 0.0 || p[v][1] < 0.5 * (p[c0][1] + p[c1][1]) {
            continue;
        }
        let r = sub(p[v], eye.centre);
        let turned = Rot3::about_axis([1.0, 0.0, 0.0], -angle * weight[v]).apply(r);
        let q = add(eye.centre, turned);
        out.positions[v] = q;
        out.positions[mirror[v]] = [-q[0], q[1], q[2]];
    }
    Ok(out)
}

impl Rig {
    /// Finds the holes of `mesh` and builds the jaw weights and lid margins.
    pub fn build(mesh: &Mesh, jaw: JawParams, lids: LidParams) -> Result<Rig, RigError> {
        let p = &mesh.positions;
        let mut loops = mesh.boundary_loops();
        if loops.len() != 4 {
            return Err(RigError::LoopCount(loops.len()));
        }
        let outer = loops.remove(0);
        let centre_y = |l: &Vec<usize>| mean(l.iter().map(|&v| p[v]))[1];
        loops.sort_by(|a, b| centre_y(a).total_cmp(&centre_y(b)));
        let mouth = loops.remove(0);
        loops.sort_by(|a, b| {
            mean(a.iter().map(|&v| p[v]))[0].total_cmp(&mean(b.iter().map(|&v| p[v]))[0])
        });
        let eyes = [0, 1].map(|i| Self::eye(&loops[i], p, &lids));
        let jaw_weight = Self::jaw_weights(mesh, &mouth, &jaw);
        Ok(Rig {
            jaw,
            lids,
            jaw_weight,
            outer,
            mouth,
            eyes,
        })
    }

    fn eye(contour: &[usize], p: &[V3], params: &LidParams) -> Eye {
        let (c0, c1, upper, lower) = split_contour(contour, p);
        let mid = lerp(p[c0], p[c1], 0.5);
        let centre = add(mid, [0.0, 0.0, -params.eyeball_depth]);
        let radius = |q: V3| (q[1] - centre[1]).hypot(q[2] - centre[2]);
        let angles = |path: &[usize], other: &[usize]| -> Vec<Margin> {
            path.iter()
                .enumerate()
                .map(|(i, &v)| {
                    let q = at_x(other, (c0, c1), p[v][0], p);
                    // The margin vertices next to a canthus turn less, so the skin triangle
                    // between the fixed corner and the lid does not fold over it.
                    let taper = if i == 0 || i + 1 == path.len() {
                        CANTHUS_TAPER
                    } else {
                        1.0
                    };
                    Margin {
                        vertex: v,
                        angle: taper * (elevation(p[v], centre) - elevation(q, centre)).abs(),
                        closed_scale: 0.5 * (radius(p[v]) + radius(q)) / radius(p[v]),
                    }
                })
                .collect()
        };
        Eye {
            centre,
            upper: angles(&upper, &lower),
            lower: angles(&lower, &upper),
            contour: contour.to_vec(),
            corners: [c0, c1],
        }
    }

    /// Harmonic jaw weights: 1 on the lower lip margin and well below the occlusal line, 0 on
    /// the upper lip margin and well above it, Laplace-smoothed on the mesh graph between.
    /// The occlusal line runs level through the mouth corners and rises behind them toward the
    /// temporomandibular joint.
    fn jaw_weights(mesh: &Mesh, mouth: &[usize], jaw: &JawParams) -> Vec<f64> {
        let p = &mesh.positions;
        let n = mesh.vertex_count();
        let (c0, c1, upper, lower) = split_contour(mouth, p);
        let corner_x = 0.5 * (p[c1][0] - p[c0][0]);
        let corner_y = 0.5 * (p[c0][1] + p[c1][1]);
        let tmj_x = mesh
            .positions
            .iter()
            .map(|q| q[0].abs())
            .fold(0.0, f64::max);
        let line = |x: f64| -> f64 {
            let ax = x.abs();
            if ax <= corner_x {
                corner_y
            } else {
                corner_y + (ax - corner_x) / (tmj_x - corner_x) * (jaw.pivot[1] - corner_y)
            }
        };
        let mut weight = vec![0.5; n];
        let mut fixed = vec![false; n];
        for v in 0..n {
            let d = p[v][1] - line(p[v][0]);
            if d > jaw.blend_width {
                weight[v] = 0.0;
                fixed[v] = true;
            } else if d < -jaw.blend_width {
                weight[v] = 1.0;
                fixed[v] = true;
            }
        }
        for &v in &upper {
            weight[v] = 0.0;
            fixed[v] = true;
        }
        for &v in &lower {
            weight[v] = 1.0;
            fixed[v] = true;
        }
        harmonic(mesh, weight, &fixed)
    }

    /// Lid rotation angles (upper, lower) as fractions of the closing angle for the three lid
    /// muscle activations of one eye and its orbital orbicularis (`cheek`); positive closes.
    pub fn lid_fractions(&self, close: f64, tighten: f64, raise: f64, cheek: f64) -> (f64, f64) {
        let l = &self.lids;
        let mut upper = l.close_upper * close + l.tighten_upper * tighten - l.raise_upper * raise;
        let mut lower = l.close_lower * close + l.tighten_lower * tighten + l.cheek_lower * cheek;
        let total = upper + lower;
        if total > l.max_closure {
            upper *= l.max_closure / total;
            lower *= l.max_closure / total;
        }
        (upper, lower)
    }

    /// Where the lid moves a point `x` of margin `m` (any sheet): turned about the eye axis by
    /// its fraction of the closing angle (upper margins down, lower up) and drawn toward the
    /// meeting radius in proportion to how closed the eye is.
    pub fn lid_motion(
        &self,
        eye: usize,
        m: &Margin,
        upper: bool,
        fractions: (f64, f64),
        x: V3,
    ) -> V3 {
        let e = &self.eyes[eye];
        let angle = if upper { fractions.0 } else { -fractions.1 } * m.angle;
        let closure = (fractions.0 + fractions.1).max(0.0);
        let radial = 1.0 + closure * (m.closed_scale - 1.0);
        let r = sub(x, e.centre);
        let turned =
            Rot3::about_axis([1.0, 0.0, 0.0], angle).apply([r[0], radial * r[1], radial * r[2]]);
        add(e.centre, turned)
    }

    /// Normal of a skull-sheet point moved by the jaw blend with weight `w`.
    pub fn blend_normal(jaw: &Rigid, w: f64, n: V3) -> V3 {
        normalize(lerp(n, jaw.rotation.apply(n), w))
    }
}
