//! What the renderer draws beside the simulated skin, so a render reads as a head: eyeballs
//! (sclera, iris, pupil) behind the lids, upper teeth fixed to the skull and lower teeth on the
//! mandible, the cranium with hair, the ears and a neck on shoulders. None of it is
//! simulated; each part is built in the head frame from the rest face, then carried by the
//! head's rigid motion (fitted to the skull sheet, so a head turned by the neck carries them)
//! and, for the lower teeth, by the mandible's. The shoulders stay put and the neck's top
//! follows the head, so the head turns on a neck whose front lies behind the chin. Colours per
//! vertex; the rasteriser shades them.

use crate::observe::pose::align;
use crate::sim::geom::{
    add, cross, dot, lerp, norm, normalize, scale, smoothstep, sub, Rigid, Rot3, V3,
};
use crate::sim::model::{FaceModel, State};
use crate::sim::tissue::SKULL;

/// A triangle soup with per-vertex normals and colours.
#[derive(Clone, Debug, Default)]
pub struct Part {
    pub positions: Vec<V3>,
    pub normals: Vec<V3>,
    pub colours: Vec<[f64; 3]>,
    pub triangles: Vec<[usize; 3]>,
}

impl Part {
    fn moved(mut self, f: impl Fn(V3) -> V3, r: &Rot3) -> Part {
        self.positions = self.positions.into_iter().map(f).collect();
        self.normals = self.normals.into_iter().map(|n| r.apply(n)).collect();
        self
    }

    /// A grid of `rows x cols` vertices from `point(u, v)` (u, v in [0, 1]), closed in u when
    /// `wrap`; normals point along `outward(p)` or are computed from the grid.
    fn grid(
        rows: usize,
        cols: usize,
        wrap: bool,
        point: impl Fn(f64, f64) -> V3,
        colour: impl Fn(V3, f64, f64) -> [f64; 3],
    ) -> Part {
        let mut part = Part::default();
        let cu = if wrap { cols } else { cols - 1 };
        for i in 0..rows {
            for j in 0..cols {
                let (u, v) = (j as f64 / cu as f64, i as f64 / (rows - 1) as f64);
                let p = point(u, v);
                part.colours.push(colour(p, u, v));
                part.positions.push(p);
            }
        }
        let index = |i: usize, j: usize| i * cols + (j % cols);
        let last = if wrap { cols } else { cols - 1 };
        for i in 0..rows - 1 {
            for j in 0..last {
                let (a, b, c, d) = (
                    index(i, j),
                    index(i, j + 1),
                    index(i + 1, j + 1),
                    index(i + 1, j),
                );
                part.triangles.push([a, b, c]);
                part.triangles.push([a, c, d]);
            }
        }
        part.normals = vertex_normals(&part.positions, &part.triangles);
        part
    }
}

/// Area-weighted vertex normals.
pub fn vertex_normals(positions: &[V3], triangles: &[[usize; 3]]) -> Vec<V3> {
    let mut normals = vec![[0.0; 3]; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|v| positions[v]);
        let n = cross(sub(b, a), sub(c, a));
        for &v in t {
            normals[v] = add(normals[v], n);
        }
    }
    normals.into_iter().map(normalize).collect()
}

const SCLERA: [f64; 3] = [0.94, 0.93, 0.90];
const IRIS: [f64; 3] = [0.33, 0.22, 0.13];
const IRIS_RIM: [f64; 3] = [0.17, 0.11, 0.07];
const PUPIL: [f64; 3] = [0.03, 0.03, 0.03];
const TOOTH: [f64; 3] = [0.88, 0.85, 0.76];
const GUM: [f64; 3] = [0.72, 0.36, 0.38];
pub const SKIN: [f64; 3] = [0.86, 0.66, 0.56];
const EAR: [f64; 3] = [0.85, 0.62, 0.53];
const HAIR: [f64; 3] = [0.22, 0.15, 0.11];

/// The head's rigid motion from rest: the skull-sheet nodes away from the mandible, fitted.
pub fn head_motion(model: &FaceModel, state: &State) -> (Rot3, V3) {
    let n = model.vertex_count();
    let idx: Vec<usize> = (0..n).filter(|&v| model.rig.jaw_weight[v] == 0.0).collect();
    let rest: Vec<V3> = idx
        .iter()
        .map(|&v| model.tissue.rest[SKULL * n + v])
        .collect();
    let now: Vec<V3> = idx
        .iter()
        .map(|&v| state.positions[SKULL * n + v])
        .collect();
    align(&rest, &now)
}

/// The iris's radius (m).
const IRIS_RADIUS: f64 = 5.9e-3;

/// A sphere's eye: white, with the iris and pupil around `+z` (looking ahead).
fn eyeball(centre: V3, radius: f64) -> Part {
    let iris = (IRIS_RADIUS / radius).min(0.9).asin();
    let pupil = (1.8e-3 / radius).min(0.5).asin();
    Part::grid(
        33,
        48,
        true,
        |u, v| {
            // v = 0 at the front pole (+z), 1 at the back.
            let (theta, phi) = (v * std::f64::consts::PI, u * std::f64::consts::TAU);
            add(
                centre,
                scale(
                    [
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ],
                    radius,
                ),
            )
        },
        move |_, _, v| {
            let theta = v * std::f64::consts::PI;
            if theta < pupil {
                PUPIL
            } else if theta < 0.85 * iris {
                IRIS
            } else if theta < iris {
                IRIS_RIM
            } else {
                SCLERA
            }
        },
    )
}

/// A dental arch: teeth as panels along a parabola in x-z from `edge_y` (the biting edge)
/// to `edge_y + height` (negative height goes down), gums beyond them.
fn arch(front: V3, half_width: f64, depth: f64, edge_y: f64, height: f64) -> Part {
    let teeth = 14usize;
    let mut part = Part::default();
    let at = |s: f64| -> V3 {
        // s in [-1, 1] across the arch.
        let x = s * half_width;
        [front[0] + x, 0.0, front[2] - depth * s * s]
    };
    for k in 0..teeth {
        // Narrow gaps between teeth; incisors at the middle.
        let s0 = -1.0 + 2.0 * k as f64 / teeth as f64;
        let s1 = -1.0 + 2.0 * (k + 1) as f64 / teeth as f64;
        let gap = 0.06 * (s1 - s0);
        let (a, b) = (at(s0 + gap), at(s1 - gap));
        // Back teeth are shorter and further in.
        let h = height * (1.0 - 0.35 * (0.5 * (s0 + s1)).abs());
        let base = part.positions.len();
        for (p, y) in [(a, edge_y), (b, edge_y), (b, edge_y + h), (a, edge_y + h)] {
            part.positions.push([p[0], y, p[2]]);
            part.colours.push(TOOTH);
        }
        part.triangles.push([base, base + 1, base + 2]);
        part.triangles.push([base, base + 2, base + 3]);
    }
    // The gum band beyond the teeth, continuous.
    let steps = 28usize;
    let base = part.positions.len();
    for k in 0..=steps {
        let p = at(-1.0 + 2.0 * k as f64 / steps as f64);
        let h = height * (1.0 - 0.35 * (-1.0 + 2.0 * k as f64 / steps as f64).abs());
        for y in [edge_y + h, edge_y + h * 1.45] {
            part.positions.push([p[0], y, p[2] - 1e-4]);
            part.colours.push(GUM);
        }
    }
    for k in 0..steps {
        let (a, b, c, d) = (
            base + 2 * k,
            base + 2 * k + 2,
            base + 2 * k + 3,
            base + 2 * k + 1,
        );
        part.triangles.push([a, b, c]);
        part.triangles.push([a, c, d]);
    }
    part.normals = part
        .positions
        .iter()
        .map(|p| normalize([p[0] - front[0], 0.0, (p[2] - front[2] + depth).max(1e-4)]))
        .collect();
    part
}

/// An ellipsoid with a colour rule.
fn ellipsoid(centre: V3, axes: V3, rows: usize, colour: impl Fn(V3) -> [f64; 3]) -> Part {
    Part::grid(
        rows,
        2 * rows,
        true,
        |u, v| {
            let (theta, phi) = (v * std::f64::consts::PI, u * std::f64::consts::TAU);
            // Poles on y.
            [
                centre[0] + axes[0] * theta.sin() * phi.cos(),
                centre[1] + axes[1] * theta.cos(),
                centre[2] + axes[2] * theta.sin() * phi.sin(),
            ]
        },
        move |p, _, _| colour(p),
    )
}

/// Where an eye looks at rest: the rotation taking `+z` to the direction that puts the iris
/// centre in front of the middle of the lid opening (its contour's bounding box in the face
/// plane), so the eye looks straight ahead out of the opening. The eyeball's centre lies 12 mm
/// behind the corners' midpoint, which sits below the middle of the opening (the upper lid
/// arches higher than the lower lid dips); an iris on `+z` sat low in the opening, and
/// MediaPipe read the rest face as looking down (eyeLookDown 0.35).
fn gaze(eye: &crate::sim::rig::Eye, surface: &[V3], radius: f64) -> Rot3 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &v in &eye.contour {
        for k in 0..2 {
            lo[k] = lo[k].min(surface[v][k]);
            hi[k] = hi[k].max(surface[v][k]);
        }
    }
    let dx = 0.5 * (lo[0] + hi[0]) - eye.centre[0];
    let dy = 0.5 * (lo[1] + hi[1]) - eye.centre[1];
    let dz = (radius * radius - dx * dx - dy * dy).max(0.0).sqrt();
    let d = normalize([dx, dy, dz]);
    let axis = cross([0.0, 0.0, 1.0], d);
    if norm(axis) < 1e-12 {
        return Rot3::IDENTITY;
    }
    Rot3::about_axis(axis, d[2].clamp(-1.0, 1.0).acos())
}

/// An eyeball at rest: its radius and where it looks ([`gaze`]), one definition for the
/// drawn eyeball and the iris points the judge reads.
fn eyeball_pose(eye: &crate::sim::rig::Eye, surface: &[V3]) -> (f64, Rot3) {
    let radius = eyeball_radius(eye, surface);
    (radius, gaze(eye, surface, radius))
}

/// An eyeball's radius: just inside its lid opening at rest.
fn eyeball_radius(eye: &crate::sim::rig::Eye, surface: &[V3]) -> f64 {
    0.95 * eye
        .contour
        .iter()
        .map(|&v| norm(sub(surface[v], eye.centre)))
        .fold(f64::INFINITY, f64::min)
}

/// The irises as Face Mesh v2 places its points 468-477, in the world frame of `state` (moved
/// with the head): for the eye on the image's left (-x, the subject's right) and then the
/// other, the iris centre on the front of the eyeball and four points on its rim, towards +x,
/// +y, -x and -y (image right, up, left, down for a frontal camera).
pub fn iris_points(model: &FaceModel, state: &State) -> [V3; 10] {
    let rest = model.rest_state();
    let surface = rest.surface(model.vertex_count());
    let (r, t) = head_motion(model, state);
    let mut eyes: Vec<&crate::sim::rig::Eye> = model.rig.eyes.iter().collect();
    eyes.sort_by(|a, b| a.centre[0].total_cmp(&b.centre[0]));
    let mut out = [[0.0; 3]; 10];
    for (k, eye) in eyes.iter().enumerate() {
        let (radius, look) = eyeball_pose(eye, surface);
        let iris = IRIS_RADIUS.min(0.9 * radius);
        let front = (radius * radius - iris * iris).sqrt();
        let c = eye.centre;
        let local = [
            [0.0, 0.0, radius],
            [iris, 0.0, front],
            [0.0, iris, front],
            [-iris, 0.0, front],
            [0.0, -iris, front],
        ];
        for (j, d) in local.iter().enumerate() {
            out[5 * k + j] = add(r.apply(add(c, look.apply(*d))), t);
        }
    }
    out
}

/// Every part for `state`, moved with the head (and the mandible); `face_normals` are the
/// skin's vertex normals in `state`, which the head's surface takes at the face's edge.
pub fn parts(model: &FaceModel, state: &State, face_normals: &[V3]) -> Vec<Part> {
    let n = model.vertex_count();
    let rest = model.rest_state();
    let surface = rest.surface(n);
    let (r, t) = head_motion(model, state);
    let head = |p: V3| add(r.apply(p), t);
    let jaw: Rigid = model.pose(&state.activations).jaw;
    let mut out = Vec::new();

    for eye in &model.rig.eyes {
        let (radius, look) = eyeball_pose(eye, surface);
        let c = eye.centre;
        out.push(
            eyeball(c, radius)
                .moved(|p| add(c, look.apply(sub(p, c))), &look)
                .moved(head, &r),
        );
    }

    // Teeth from the rest mouth: the contour's corners and its upper/lower midpoints.
    let mouth: Vec<V3> = model.rig.mouth.iter().map(|&v| surface[v]).collect();
    let corner_x = mouth.iter().map(|p| p[0].abs()).fold(0.0, f64::max);
    let front_z = mouth.iter().map(|p| p[2]).fold(f64::NEG_INFINITY, f64::max);
    let corners_y = {
        let mut by_x = mouth.clone();
        by_x.sort_by(|a, b| a[0].total_cmp(&b[0]));
        0.5 * (by_x[0][1] + by_x[by_x.len() - 1][1])
    };
    let mid = mouth.iter().filter(|p| p[0].abs() < 0.15 * corner_x);
    let (upper_y, lower_y) = mid.fold((f64::NEG_INFINITY, f64::INFINITY), |(u, l), p| {
        (u.max(p[1]), l.min(p[1]))
    });
    let occlusal = lerp([0.0, upper_y, 0.0], [0.0, lower_y, 0.0], 0.5)[1].min(corners_y);
    let front = [0.0, 0.0, front_z - 6e-3];
    let upper = arch(front, 0.95 * corner_x, 0.022, occlusal + 5e-4, 9.5e-3);
    out.push(upper.moved(head, &r));
    let lower_front = [0.0, 0.0, front_z - 7.5e-3];
    let lower = arch(lower_front, 0.9 * corner_x, 0.02, occlusal - 5e-4, -8.5e-3);
    let lower = lower.moved(|p| jaw.apply(p), &jaw.rotation);
    out.push(lower.moved(head, &r));

    // The head around the face: the cranium with its hair, the sides behind the cheeks and the
    // skin under the jaw, one surface grown from the face's outline.
    let outline: Vec<V3> = model.rig.outer.iter().map(|&v| surface[v]).collect();
    let half_width = outline.iter().map(|p| p[0].abs()).fold(0.0, f64::max);
    let top = outline
        .iter()
        .copied()
        .max_by(|a, b| a[1].total_cmp(&b[1]))
        .unwrap_or([0.0; 3]);
    let eyes_y = 0.5 * (model.rig.eyes[0].centre[1] + model.rig.eyes[1].centre[1]);
    let cranium = Cranium {
        centre: [0.0, eyes_y + 0.004, top[2] - 0.085],
        axes: [0.985 * half_width, 0.115, 0.095],
        hairline: top[1] - 0.004,
    };
    let now = state.surface(n);
    out.push(hull(
        model,
        &cranium,
        (surface, now, face_normals),
        &jaw,
        (&r, t),
    ));

    // Ears on the sides of the cranium, their centres 2 cm behind the face's edge (the tragus
    // at the edge), from brow to nose-base height, turned 25 degrees so their backs stand out.
    for side in [-1.0, 1.0] {
        let (y, z) = (eyes_y - 0.006, cranium.centre[2] - 0.005);
        let c = [side * (cranium.half_width_at(y, z) + 0.004), y, z];
        let turn = Rot3::about_axis([0.0, 1.0, 0.0], -side * 25f64.to_radians());
        let ear = ellipsoid(c, [0.006, 0.031, 0.017], 16, |_| EAR)
            .moved(|p| add(c, turn.apply(sub(p, c))), &turn);
        out.push(ear.moved(head, &r));
    }

    out.push(neck(&outline, eyes_y, head));
    out
}

/// The ellipsoid the head's surface is shaped on, fitted to the face's outline (as wide as
/// the face, its front just behind the forehead's top edge, 19 cm from glabella to the back
/// of the head), and where its hair begins.
struct Cranium {
    centre: V3,
    axes: V3,
    hairline: f64,
}

impl Cranium {
    /// Skin at the face and temples; hair over the top and the back, down to the nape. A soft
    /// hairline, 10 mm wide, so the grid shows no steps.
    fn colour(&self, p: V3) -> [f64; 3] {
        let back = (self.centre[2] - p[2]) / self.axes[2];
        let line = self.hairline
            - 0.13 * back.clamp(0.0, 1.0)
            - 0.03 * (p[0].abs() / self.axes[0]).powi(4);
        let t = smoothstep((p[1] - line) / 0.01 + 0.5);
        std::array::from_fn(|k| SKIN[k] + t * (HAIR[k] - SKIN[k]))
    }

    /// The ellipsoid's half width at height `y` and depth `z` (0 outside it).
    fn half_width_at(&self, y: f64, z: f64) -> f64 {
        let (dy, dz) = (
            (y - self.centre[1]) / self.axes[1],
            (z - self.centre[2]) / self.axes[2],
        );
        self.axes[0] * (1.0 - dy * dy - dz * dz).max(0.0).sqrt()
    }

    /// The point a fraction `v` of the way from `p` (on the face's outline) to the back of the
    /// head: along the great circle of the ellipsoid's directions from `p`'s to straight back,
    /// its distance from the centre (in axis units) easing from `p`'s to the ellipsoid's over
    /// the first 30% of the way.
    fn towards_back(&self, p: V3, v: f64) -> V3 {
        let n: V3 = std::array::from_fn(|k| (p[k] - self.centre[k]) / self.axes[k]);
        let rho = norm(n);
        let u = scale(n, 1.0 / rho);
        let back = [0.0, 0.0, -1.0];
        let omega = (-u[2]).clamp(-1.0, 1.0).acos();
        let d = if omega < 1e-9 {
            u
        } else {
            scale(
                add(
                    scale(u, ((1.0 - v) * omega).sin()),
                    scale(back, (v * omega).sin()),
                ),
                1.0 / omega.sin(),
            )
        };
        let radius = rho + (1.0 - rho) * smoothstep(v / 0.3);
        std::array::from_fn(|k| self.centre[k] + self.axes[k] * radius * d[k])
    }
}

/// The head around the face, one surface from the face's outline to the back of the head:
/// over the top from the forehead, round the sides from the temples and cheeks, under the jaw
/// from the chin to the neck (`Cranium::towards_back`). Its first row is the face's outline as
/// the face now is, with the face's normals there, so the cranium meets the face without a
/// seam. Behind the mandible (under the jaw, behind the ramus) it follows the mandible, fully
/// near the outline and not at all 40% of the way back; the outline's own motion beyond the
/// mandible's fades over the first 20%.
fn hull(
    model: &FaceModel,
    cranium: &Cranium,
    (rest, now, face_normals): (&[V3], &[V3], &[V3]),
    jaw: &Rigid,
    (r, t): (&Rot3, V3),
) -> Part {
    // Columns per edge of the outline, and rows from the outline to the back.
    const SPLIT: usize = 4;
    const ROWS: usize = 64;
    let outer = &model.rig.outer;
    let m = outer.len();
    let cols = m * SPLIT;
    // Column `j`: its outline edge's two vertices and how far along the edge it lies.
    let column = |j: usize| {
        (
            outer[j / SPLIT],
            outer[(j / SPLIT + 1) % m],
            (j % SPLIT) as f64 / SPLIT as f64,
        )
    };
    let along = |values: &[f64], j: usize| {
        let (a, b, s) = column(j);
        values[a] + s * (values[b] - values[a])
    };
    let carried = |q: V3, w: f64| add(r.apply(lerp(q, jaw.apply(q), w)), t);
    let mut part = Part::default();
    for i in 0..ROWS {
        let v = i as f64 / (ROWS - 1) as f64;
        for j in 0..cols {
            let (a, b, s) = column(j);
            let edge = lerp(rest[a], rest[b], s);
            let jaw_weight = along(&model.rig.jaw_weight, j);
            let offset = sub(lerp(now[a], now[b], s), carried(edge, jaw_weight));
            let p = cranium.towards_back(edge, v);
            let follows = jaw_weight * (1.0 - smoothstep((v - 0.05) / 0.35));
            part.positions.push(add(
                carried(p, follows),
                scale(offset, 1.0 - smoothstep(v / 0.2)),
            ));
            part.colours.push(cranium.colour(p));
        }
    }
    for i in 0..ROWS - 1 {
        for j in 0..cols {
            let (a, b) = (i * cols + j, i * cols + (j + 1) % cols);
            let (c, d) = (b + cols, a + cols);
            part.triangles.push([a, b, c]);
            part.triangles.push([a, c, d]);
        }
    }
    part.normals = vertex_normals(&part.positions, &part.triangles);
    // Outward, whichever way the outline runs.
    let centre = add(r.apply(cranium.centre), t);
    let outward: f64 = part
        .positions
        .iter()
        .zip(&part.normals)
        .map(|(&p, &n)| dot(n, sub(p, centre)))
        .sum();
    if outward < 0.0 {
        part.normals = part.normals.iter().map(|&n| scale(n, -1.0)).collect();
    }
    for j in 0..cols {
        let (a, b, s) = column(j);
        part.normals[j] = normalize(lerp(face_normals[a], face_normals[b], s));
    }
    part
}

/// The neck and shoulders: rings from inside the head down, the top ring moved with the head
/// (`head`), the shoulders fixed.
fn neck(outline: &[V3], eyes_y: f64, head: impl Fn(V3) -> V3) -> Part {
    // Its front (the throat) lies 5.5 cm behind the chin, as in an adult's profile, so the chin of
    // an opened jaw, which swings down and back, stays in front of it (with its front 1.6 cm
    // behind the chin, the neck hid the lower face of a wide-open mouth).
    let chin = outline
        .iter()
        .copied()
        .min_by(|a, b| a[1].total_cmp(&b[1]))
        .unwrap_or([0.0; 3]);
    // Below the chin the neck runs 6.5 cm, as an adult's front does in a frontal view to the
    // top of the trapezius, then widens over 4.5 cm into the slope of the shoulders (a bust's
    // base), instead of a cylinder as long as the face. It is 12 cm wide and 10.4 cm deep,
    // its back (the nape) just inside the back of the head where they meet, and leans
    // forward as it rises (its axis 8.5 degrees from vertical), so the head sits in front of
    // the shoulders.
    let neck_top = eyes_y - 0.05;
    let flare_top = chin[1] - 0.065;
    let neck_bottom = chin[1] - 0.11;
    let (neck_half_width, neck_half_depth) = (0.06, 0.052);
    let (shoulder_half_width, shoulder_half_depth) = (0.17, 0.085);
    let neck_centre_z = chin[2] - 0.055 - neck_half_depth;
    let lean = 0.15;
    let neck = Part::grid(
        32,
        40,
        true,
        |u, v| {
            let phi = u * std::f64::consts::TAU;
            let y = neck_top + v * (neck_bottom - neck_top);
            let t = smoothstep((flare_top - y) / (flare_top - neck_bottom));
            let half_width = neck_half_width + t * (shoulder_half_width - neck_half_width);
            let half_depth = neck_half_depth + t * (shoulder_half_depth - neck_half_depth);
            [
                half_width * phi.cos(),
                y,
                neck_centre_z - lean * (neck_top - y) + half_depth * phi.sin(),
            ]
        },
        |_, _, _| SKIN,
    );
    let neck = Part {
        positions: neck
            .positions
            .iter()
            .map(|&p| {
                // The shoulders stay; the neck above them bends toward the head.
                lerp(
                    p,
                    head(p),
                    smoothstep((p[1] - flare_top) / (neck_top - flare_top)),
                )
            })
            .collect(),
        ..neck
    };
    let normals = vertex_normals(&neck.positions, &neck.triangles);
    Part { normals, ..neck }
}
