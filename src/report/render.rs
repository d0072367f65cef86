//! A small software renderer for the face: perspective camera, z-buffer, per-pixel smooth
//! (Phong) shading, 2x supersampling; eye and mouth openings show a dark interior. An optional
//! overlay draws each muscle from origin to insertion coloured by its activation.

use image::{Rgb, RgbImage};

use crate::sim::geom::{add, cross, dot, norm, normalize, scale, sub, V3};
use crate::sim::model::{FaceModel, State};
use crate::sim::muscles::MuscleKind;
use crate::sim::tissue::SKULL;

use super::head::{self, SKIN};

/// What the renderer draws, as a version hashed into every cache key whose result reads a
/// render: the table of renders, the photo table, and every face read through renders
/// (`observer.source = "render"`, through `Source::renderer`). Bump it when a render of the
/// same face changes.
// 2: the head is one surface grown from the face's outline (no seam at the cranium, skin under
// the jaw that follows it), ears behind the face's edge, a neck 10.4 cm deep that leans forward.
pub const RENDER_VERSION: u32 = 2;

/// Look-at perspective camera (metres, degrees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: V3,
    pub target: V3,
    pub up: V3,
    pub fov_y_degrees: f64,
}

impl Camera {
    /// Frontal view framing the canonical face.
    pub fn frontal() -> Camera {
        Camera {
            eye: [0.0, 0.0, 0.62],
            target: [0.0, -0.005, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 18.5,
        }
    }

    /// A frontal view wide enough for the head turned +-40 degrees and carried by the neck
    /// (its condyles move a few centimetres).
    pub fn head_motion() -> Camera {
        Camera {
            eye: [0.0, -0.02, 0.85],
            target: [0.0, -0.03, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 26.0,
        }
    }

    /// A three-quarter view from the subject's left (the viewer's right).
    pub fn three_quarter() -> Camera {
        Camera {
            eye: [0.32, 0.04, 0.53],
            target: [0.0, -0.005, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 18.5,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub camera: Camera,
    /// Draw muscles over the face.
    pub muscle_overlay: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 480,
            height: 560,
            camera: Camera::frontal(),
            muscle_overlay: false,
        }
    }
}

const LIPS: [f64; 3] = [0.74, 0.38, 0.38];
const BROW: [f64; 3] = [0.28, 0.19, 0.13];
const EYE: [f64; 3] = [0.08, 0.07, 0.09];
const MOUTH: [f64; 3] = [0.22, 0.04, 0.06];
const BACKGROUND: [f64; 3] = [0.93, 0.93, 0.95];

struct Projector {
    right: V3,
    up: V3,
    forward: V3,
    eye: V3,
    focal: f64,
    width: f64,
    height: f64,
}

impl Projector {
    fn new(c: &Camera, width: u32, height: u32) -> Projector {
        let forward = normalize(sub(c.target, c.eye));
        let right = normalize(cross(forward, c.up));
        let up = cross(right, forward);
        let focal = 0.5 * height as f64 / (0.5 * c.fov_y_degrees.to_radians()).tan();
        Projector {
            right,
            up,
            forward,
            eye: c.eye,
            focal,
            width: width as f64,
            height: height as f64,
        }
    }

    /// Pixel x, y and view depth.
    fn project(&self, p: V3) -> [f64; 3] {
        let d = sub(p, self.eye);
        let z = dot(d, self.forward);
        [
            0.5 * self.width + self.focal * dot(d, self.right) / z,
            0.5 * self.height - self.focal * dot(d, self.up) / z,
            z,
        ]
    }
}

struct Target {
    width: usize,
    height: usize,
    color: Vec<[f64; 3]>,
    depth: Vec<f64>,
}

impl Target {
    /// Rasterises a triangle with per-vertex normals (None = flat colour, unlit).
    fn triangle(
        &mut self,
        proj: &Projector,
        p: [V3; 3],
        n: Option<[V3; 3]>,
        colours: [[f64; 3]; 3],
    ) {
        let s = p.map(|q| proj.project(q));
        if s.iter().any(|q| q[2] <= 0.0) {
            return;
        }
        let area =
            (s[1][0] - s[0][0]) * (s[2][1] - s[0][1]) - (s[2][0] - s[0][0]) * (s[1][1] - s[0][1]);
        if area.abs() < 1e-12 {
            return;
        }
        let min_x = s
            .iter()
            .map(|q| q[0])
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as usize;
        let max_x = s
            .iter()
            .map(|q| q[0])
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil()
            .min(self.width as f64 - 1.0);
        let min_y = s
            .iter()
            .map(|q| q[1])
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as usize;
        let max_y = s
            .iter()
            .map(|q| q[1])
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil()
            .min(self.height as f64 - 1.0);
        if max_x < 0.0 || max_y < 0.0 {
            return;
        }
        let light = normalize([-0.35, 0.45, 1.0]);
        let fill = normalize([0.6, -0.1, 0.6]);
        for y in min_y..=max_y as usize {
            for x in min_x..=max_x as usize {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((s[1][0] - px) * (s[2][1] - py) - (s[2][0] - px) * (s[1][1] - py)) / area;
                let w1 = ((s[2][0] - px) * (s[0][1] - py) - (s[0][0] - px) * (s[2][1] - py)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * s[0][2] + w1 * s[1][2] + w2 * s[2][2];
                let i = y * self.width + x;
                if z >= self.depth[i] {
                    continue;
                }
                self.depth[i] = z;
                let base: [f64; 3] = std::array::from_fn(|k| {
                    w0 * colours[0][k] + w1 * colours[1][k] + w2 * colours[2][k]
                });
                self.color[i] = match n {
                    None => base,
                    Some(n) => {
                        let mut normal =
                            normalize(add(add(scale(n[0], w0), scale(n[1], w1)), scale(n[2], w2)));
                        let to_eye = normalize(sub(
                            proj.eye,
                            add(add(scale(p[0], w0), scale(p[1], w1)), scale(p[2], w2)),
                        ));
                        if dot(normal, to_eye) < 0.0 {
                            normal = scale(normal, -1.0);
                        }
                        let diffuse =
                            0.72 * dot(normal, light).max(0.0) + 0.18 * dot(normal, fill).max(0.0);
                        let half = normalize(add(light, to_eye));
                        let specular = 0.12 * dot(normal, half).max(0.0).powi(24);
                        base.map(|c| (c * (0.22 + diffuse) + specular).min(1.0))
                    }
                };
            }
        }
    }

    fn line(&mut self, a: [f64; 2], b: [f64; 2], radius: f64, color: [f64; 3]) {
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        let steps = (len * 2.0).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            self.disc(
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])],
                radius,
                color,
            );
        }
    }

    fn disc(&mut self, c: [f64; 2], radius: f64, color: [f64; 3]) {
        let r = radius.ceil() as i64;
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (c[0] as i64 + dx, c[1] as i64 + dy);
                if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
                    continue;
                }
                if ((dx * dx + dy * dy) as f64) <= radius * radius {
                    self.color[y as usize * self.width + x as usize] = color;
                }
            }
        }
    }
}

/// Blue (0) through white to red (1).
fn activation_colour(a: f64) -> [f64; 3] {
    let a = a.clamp(0.0, 1.0);
    if a < 0.5 {
        let t = a / 0.5;
        [0.15 + 0.85 * t, 0.3 + 0.7 * t, 0.9 + 0.1 * t]
    } else {
        let t = (a - 0.5) / 0.5;
        [1.0, 1.0 - 0.85 * t, 1.0 - 0.85 * t]
    }
}

/// The red lips (MediaPipe's outer, semi-outer, semi-inner and inner lip rings) and the
/// eyebrows (its upper and lower brow lines without their temple ends) as canonical-mesh vertex indices; a surface
/// triangle with all three corners in a set takes its colour, so both move with the skin.
const LIP_VERTICES: [usize; 80] = [
    61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291, 146, 91, 181, 84, 17, 314, 405, 321, 375, 78,
    191, 80, 81, 82, 13, 312, 311, 310, 415, 308, 95, 88, 178, 87, 14, 317, 402, 318, 324, 76, 184,
    74, 73, 72, 11, 302, 303, 304, 408, 306, 77, 90, 180, 85, 16, 315, 404, 320, 307, 62, 183, 42,
    41, 38, 12, 268, 271, 272, 407, 292, 96, 89, 179, 86, 15, 316, 403, 319, 325,
];
const BROW_VERTICES: [usize; 22] = [
    70, 63, 105, 66, 107, 55, 193, 46, 53, 52, 65, 300, 293, 334, 296, 336, 285, 417, 276, 283,
    282, 295,
];

/// Per surface triangle: skin, lip or brow colour. On a subdivided mesh (canonical vertices
/// first, then one per split edge) a new vertex is in a set when the two canonical vertices
/// nearest to it at rest, its edge's ends at the first level, both are.
fn surface_marks(model: &FaceModel) -> Vec<[f64; 3]> {
    const CANONICAL: usize = 468;
    let rest = &model.surface.positions;
    let mark = |set: &[usize]| -> Vec<bool> {
        let mut inside = vec![false; rest.len()];
        for &v in set {
            inside[v] = true;
        }
        for v in CANONICAL.min(rest.len())..rest.len() {
            let mut near: Vec<(f64, usize)> = (0..CANONICAL)
                .map(|u| (norm(sub(rest[u], rest[v])), u))
                .collect();
            near.select_nth_unstable_by(1, |a, b| a.0.total_cmp(&b.0));
            inside[v] = inside[near[0].1] && inside[near[1].1];
        }
        inside
    };
    let (lip, brow) = (mark(&LIP_VERTICES), mark(&BROW_VERTICES));
    model
        .surface
        .triangles
        .iter()
        .map(|t| {
            if t.iter().all(|&v| lip[v]) {
                LIPS
            } else if t.iter().all(|&v| brow[v]) {
                BROW
            } else {
                SKIN
            }
        })
        .collect()
}

/// Image pixels (x right, y down) and view depth of world points as `render` draws them with
/// `options` (no supersampling).
pub fn project(options: &RenderOptions, points: &[V3]) -> Vec<[f64; 3]> {
    let proj = Projector::new(&options.camera, options.width, options.height);
    points.iter().map(|&p| proj.project(p)).collect()
}

/// Renders `state` of `model`.
pub fn render(model: &FaceModel, state: &State, options: &RenderOptions) -> RgbImage {
    const SS: u32 = 2;
    let (w, h) = (options.width * SS, options.height * SS);
    let proj = Projector::new(&options.camera, w, h);
    let mut target = Target {
        width: w as usize,
        height: h as usize,
        color: vec![BACKGROUND; (w * h) as usize],
        depth: vec![f64::INFINITY; (w * h) as usize],
    };
    let n = model.vertex_count();
    let surface = state.surface(n);
    let normals = head::vertex_normals(surface, &model.surface.triangles);
    let marks = surface_marks(model);
    for (t, colour) in model.surface.triangles.iter().zip(&marks) {
        target.triangle(
            &proj,
            t.map(|v| surface[v]),
            Some(t.map(|v| normals[v])),
            [*colour; 3],
        );
    }
    for part in head::parts(model, state, &normals) {
        for t in &part.triangles {
            target.triangle(
                &proj,
                t.map(|v| part.positions[v]),
                Some(t.map(|v| part.normals[v])),
                t.map(|v| part.colours[v]),
            );
        }
    }
    // Openings: a dark fan just behind the opening's rim, so nothing behind the face shows
    // (the eyeballs and teeth sit in front of it).
    let holes = [
        (&model.rig.mouth, MOUTH),
        (&model.rig.eyes[0].contour, EYE),
        (&model.rig.eyes[1].contour, EYE),
    ];
    for (contour, colour) in holes {
        let rim: Vec<V3> = contour
            .iter()
            .map(|&v| state.positions[SKULL * n + v])
            .collect();
        let mut centre = scale(
            rim.iter().fold([0.0; 3], |acc, &p| add(acc, p)),
            1.0 / rim.len() as f64,
        );
        centre[2] -= 0.01;
        for k in 0..rim.len() {
            target.triangle(
                &proj,
                [centre, rim[k], rim[(k + 1) % rim.len()]],
                None,
                [colour; 3],
            );
        }
    }
    if options.muscle_overlay {
        let pose = model.pose(&state.activations);
        let act = state.activations.values();
        for (i, m) in model.muscles.iter().enumerate() {
            if m.nodes.is_empty() {
                continue;
            }
            let total: f64 = m.nodes.iter().map(|&(_, f)| f).sum();
            let insertion = scale(
                m.nodes.iter().fold([0.0; 3], |acc, &(node, f)| {
                    add(acc, scale(state.positions[node], f))
                }),
                1.0 / total,
            );
            let colour = activation_colour(act[i]);
            let ins = proj.project(insertion);
            match m.kind {
                MuscleKind::Linear { .. } => {
                    let o = proj.project(pose.targets[i]);
                    target.line([o[0], o[1]], [ins[0], ins[1]], 2.5, colour);
                    target.disc([o[0], o[1]], 6.0, [0.1, 0.1, 0.1]);
                    target.disc([o[0], o[1]], 4.0, colour);
                    target.disc([ins[0], ins[1]], 5.0, colour);
                }
                MuscleKind::Sphincter { .. } => {
                    // The zone's nodes, each a dot.
                    for &(node, _) in &m.nodes {
                        let p = proj.project(state.positions[node]);
                        target.disc([p[0], p[1]], 2.5, colour);
                    }
                }
                MuscleKind::Lid(_) => {}
            }
        }
    }
    // Downsample.
    let mut out = RgbImage::new(options.width, options.height);
    for y in 0..options.height {
        for x in 0..options.width {
            let mut c = [0.0; 3];
            for sy in 0..SS {
                for sx in 0..SS {
                    let p = target.color[((y * SS + sy) * w + x * SS + sx) as usize];
                    for k in 0..3 {
                        c[k] += p[k];
                    }
                }
            }
            let px = c.map(|v| ((v / (SS * SS) as f64).clamp(0.0, 1.0) * 255.0).round() as u8);
            out.put_pixel(x, y, Rgb(px));
        }
    }
    out
}
