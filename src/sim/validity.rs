//! Whether a solved face is one a real face could take: no inverted tissue element, no
//! surface triangle turned over, and lips and lids that meet without passing through each
//! other. Used by the tests, the gallery and `facelab face sweep`.
//!
//! Lips and lids are compared in the face plane: each margin's contour is split at its
//! corners into an upper and a lower path (as the rig does), and every vertex of the upper
//! path must stay above the lower path at its abscissa (and the lower below the upper), by
//! at least `-CROSSING_TOLERANCE`. Touching is allowed; the sign says which side is which.
//! Depends on `geom`, `model`, `rig`, `tissue`.

use super::geom::{cross, dot, sub, V3};
use super::model::{FaceModel, State};
use super::rig::split_contour;
use super::tissue::{prism_volume, LIP_THICKNESS_SCALE};

/// How far (m) an upper margin may sink below the lower one before it counts as passing
/// through: 0.5 mm. The margins are compared in height only, and lips that touch roll over
/// each other by a few tenths of a millimetre at different depths; real faces are measured to
/// about 1 mm (repeatability 0.74-1.5 mm, shared/facs-magnitudes.md).
pub const CROSSING_TOLERANCE: f64 = 5e-4;

/// What is wrong with a face, counted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Defects {
    /// Prisms with non-positive volume.
    pub inverted_prisms: usize,
    /// Surface triangles whose normal turned more than 90 degrees from rest. Triangles
    /// touching the inner lip crease are left out: at the commissures the rest surface
    /// already folds ~150 degrees (see `Tissue::build`), and the lips rolling there turns
    /// those hidden triangles over without any visible fold.
    pub folded_triangles: usize,
    /// Margin vertices of the lips that crossed the opposite lip.
    pub lip_crossings: usize,
    /// Margin vertices of the lids that crossed the opposite lid.
    pub lid_crossings: usize,
    /// Smallest signed gap between the lips (m); negative means overlap.
    pub min_lip_gap: f64,
    /// Smallest signed gap between the lids of either eye (m).
    pub min_lid_gap: f64,
}

impl Defects {
    /// True when nothing is inverted, folded or crossed.
    pub fn is_clean(&self) -> bool {
        self.inverted_prisms == 0
            && self.folded_triangles == 0
            && self.lip_crossings == 0
            && self.lid_crossings == 0
    }
}

impl std::fmt::Display for Defects {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} inverted prisms, {} folded triangles, {} lip and {} lid margin crossings \
             (smallest gaps: lips {:.2} mm, lids {:.2} mm)",
            self.inverted_prisms,
            self.folded_triangles,
            self.lip_crossings,
            self.lid_crossings,
            self.min_lip_gap * 1e3,
            self.min_lid_gap * 1e3
        )
    }
}

/// Signed gaps of a contour's two margins: for every vertex of the upper path its height
/// above the lower path, and for every vertex of the lower path the upper path's height
/// above it. The contour is split on its rest shape, so the labels do not follow a crossing.
/// The corners themselves are left out of the opposite path: a corner pulled up or down
/// makes the path beside it nearly vertical, and heights read off it mean nothing there; a
/// vertex beyond the opposite path's last interior vertex is not compared.
fn margin_gaps(contour: &[usize], rest: &[V3], now: &[V3]) -> Vec<f64> {
    let (_, _, upper, lower) = split_contour(contour, rest);
    let height = |path: &[usize], x: f64| -> Option<f64> {
        let mut pts: Vec<V3> = path.iter().map(|&v| now[v]).collect();
        pts.sort_by(|a, b| a[0].total_cmp(&b[0]));
        pts.windows(2).find_map(|w| {
            (x >= w[0][0] && x <= w[1][0]).then(|| {
                let t = if w[1][0] > w[0][0] {
                    (x - w[0][0]) / (w[1][0] - w[0][0])
                } else {
                    0.0
                };
                w[0][1] + t * (w[1][1] - w[0][1])
            })
        })
    };
    let mut gaps = Vec::with_capacity(upper.len() + lower.len());
    for &v in &upper {
        gaps.extend(height(&lower, now[v][0]).map(|y| now[v][1] - y));
    }
    for &v in &lower {
        gaps.extend(height(&upper, now[v][0]).map(|y| y - now[v][1]));
    }
    gaps
}

/// The defects of `state` (a solved state of `model`).
pub fn defects(model: &FaceModel, state: &State) -> Defects {
    let inverted_prisms = model
        .tissue
        .prisms
        .iter()
        .filter(|p| prism_volume(&p.nodes.map(|i| state.positions[i])) <= 0.0)
        .count();
    let rest = model.rest_state();
    let normal = |x: &[V3], t: &[usize; 3]| {
        let [a, b, c] = t.map(|v| x[v]);
        cross(sub(b, a), sub(c, a))
    };
    let folded_triangles = model
        .surface
        .triangles
        .iter()
        .filter(|t| {
            t.iter()
                .all(|&v| model.tissue.thickness_scale[v] >= LIP_THICKNESS_SCALE)
        })
        .filter(|t| dot(normal(&state.positions, t), normal(&rest.positions, t)) <= 0.0)
        .count();
    let n = model.vertex_count();
    let (rest_surface, surface) = (rest.surface(n), state.surface(n));
    let lips = margin_gaps(&model.rig.mouth, rest_surface, surface);
    let lids: Vec<f64> = model
        .rig
        .eyes
        .iter()
        .flat_map(|e| margin_gaps(&e.contour, rest_surface, surface))
        .collect();
    let crossings = |g: &[f64]| g.iter().filter(|&&d| d < -CROSSING_TOLERANCE).count();
    let min = |g: &[f64]| g.iter().copied().fold(f64::INFINITY, f64::min);
    Defects {
        inverted_prisms,
        folded_triangles,
        lip_crossings: crossings(&lips),
        lid_crossings: crossings(&lids),
        min_lip_gap: min(&lips),
        min_lid_gap: min(&lids),
    }
}
