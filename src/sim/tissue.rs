//! Layered facial soft tissue after Lee, Terzopoulos & Waters 1995 (LTW95): the surface mesh
//! is offset inward into four node sheets (surface, dermis, fascia, skull); each surface
//! triangle becomes three stacked prism elements (epidermis/dermis, dermal-fatty, muscle
//! layer) joined by in-sheet, vertical and crossing springs, with per-prism volume
//! preservation and skull non-penetration for the fascia sheet.
//!
//! Units: metres, newtons, pascals. Depends only on `sim::geom` and `sim::mesh`.

use super::geom::{add, cross, dot, norm, normalize, scale, sub, tet_volume, V3};
use super::mesh::Mesh;

/// The four node sheets, outermost first. Node index = `sheet * vertex_count + vertex`.
pub const SHEETS: usize = 4;
pub const SURFACE: usize = 0;
pub const DERMIS: usize = 1;
pub const FASCIA: usize = 2;
pub const SKULL: usize = 3;

/// Material and geometry of the tissue. Defaults are LTW95-style values scaled to SI and to
/// measured human facial tissue; each field says where its default comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TissueParams {
    /// Epidermis + dermis thickness (m). Default 1.5 mm: facial skin is 1-2 mm thick
    /// (LTW95 Sec. 3 uses a thin epidermal layer over a thicker dermal-fatty layer).
    pub epidermis_thickness: f64,
    /// Dermal-fatty (subcutaneous) layer thickness (m). Default 4 mm, mid-face soft tissue
    /// depth minus skin and muscle (cadaver and ultrasound depths are 5-15 mm in total).
    pub dermal_fatty_thickness: f64,
    /// Muscle layer thickness, fascia to skull (m). Default 3 mm (mimetic muscles are 1-4 mm).
    pub muscle_layer_thickness: f64,
    /// Young's modulus of the epidermis/dermis slab (Pa). Default 60 kPa: in-vivo skin
    /// at small strain is 50-200 kPa (suction and indentation tests).
    pub epidermis_modulus: f64,
    /// Strain beyond which epidermal in-sheet springs stiffen (LTW95's biphasic spring).
    /// Default 0.15, where skin's collagen straightens (the toe of its stress-strain curve).
    pub epidermis_stiffening_strain: f64,
    /// Stiffness ratio of the epidermal springs past the stiffening strain. Default 8 (LTW95
    /// use a stiffer second slope; skin's linear region is 5-20x its toe region).
    pub epidermis_stiffening_factor: f64,
    /// Young's modulus of the dermal-fatty slab (Pa). Default 10 kPa (subcutaneous fat 2-25 kPa).
    pub dermal_fatty_modulus: f64,
    /// Young's modulus of the muscle layer (Pa). Default 5 kPa: loose areolar tissue under the
    /// fascia lets it slide over the skull (LTW95 make these springs the weakest).
    pub muscle_layer_modulus: f64,
    /// Crossing-spring stiffness as a fraction of the in-sheet stiffness of the same slab
    /// (shear resistance). Default 0.5.
    pub crossing_fraction: f64,
    /// Shear modulus of each slab's prisms, as a fraction of the slab's incompressible value
    /// E / 3: a compressible neo-Hookean term mu (|F|^2 / 2 - ln J) per prism, |F|^2 averaged
    /// over its 18 tetrahedra and J its volume ratio, so the rest shape carries no stress.
    /// Default 1: each slab gets its continuum shear stiffness (0 turns the term off and
    /// leaves LTW95's springs alone; `dataset.shear_modulus_fraction` in a spec).
    ///
    /// The springs of a flat prism cannot resist the shear across its thickness: at
    /// subdivision 0 an epidermis prism is ~15 mm wide and 1.5 mm thick, and the crossing
    /// springs that should hold a surface node over the dermis node beneath it lie almost in
    /// the sheet. A median vertex column has a vertical spring of 2,200 N/m (E A / h) and
    /// ~130 N/m of lateral support (six crossing springs of 22.5 N/m), where the continuum
    /// gives G A / h ~ 730 N/m; under about 0.1 mm of thickness compression the column tilts
    /// over, a mesh-scale instability that stalls Newton's method (`facelab bench solve`
    /// counts the saddles it leaves: 11 of 60 cold equilibria at subdivision 0 without the
    /// term, none with it, and Newton needs 2.5x fewer iterations).
    pub shear_modulus_fraction: f64,
    /// Volume-preservation modulus (Pa): energy kappa V0 (0.5 (J - 1)^2 + 0.2 (J - 1 - ln J)),
    /// J = V / V0, per prism (LTW95's volume constraint as a penalty, with a log barrier
    /// against inversion). Default 50 kPa, above the shear moduli: tissue is
    /// nearly incompressible but the penalty must not dominate the springs numerically.
    pub volume_modulus: f64,
    /// Skull contact stiffness per fascia node (N/m). Default 5000 N/m, ~55x the median
    /// muscle-layer vertical spring (91 N/m at subdivision 0), so penetration stays a small
    /// fraction of the layer.
    pub skull_contact_stiffness: f64,
    /// Stiffness of the contact between the lips (N/m per pair of facing inner-lip nodes,
    /// acting when the upper one sinks below the lower). Default 20000 N/m: the corner
    /// pullers together (zygomaticus major with risorius, ~40 N) otherwise push the lips
    /// 1-3 mm through each other near the corners; at this stiffness the overlap stays
    /// below the 0.5 mm `sim::validity` allows.
    pub lip_contact_stiffness: f64,
    /// Closest approach of the fascia to the skull, as a fraction of the muscle layer
    /// thickness. Default 0.25.
    pub skull_clearance_fraction: f64,
    /// Smoothing passes over the vertex normals before offsetting (each averages a normal with
    /// its neighbours'). Default 8: raw normals fold the inner sheets at the lips.
    pub normal_smoothing_passes: usize,
}

impl Default for TissueParams {
    fn default() -> Self {
        TissueParams {
            epidermis_thickness: 1.5e-3,
            dermal_fatty_thickness: 4.0e-3,
            muscle_layer_thickness: 3.0e-3,
            epidermis_modulus: 60e3,
            epidermis_stiffening_strain: 0.15,
            epidermis_stiffening_factor: 8.0,
            dermal_fatty_modulus: 10e3,
            muscle_layer_modulus: 5e3,
            crossing_fraction: 0.5,
            shear_modulus_fraction: 1.0,
            volume_modulus: 50e3,
            skull_contact_stiffness: 5000.0,
            lip_contact_stiffness: 20000.0,
            skull_clearance_fraction: 0.25,
            normal_smoothing_passes: 8,
        }
    }
}

/// A uniaxial spring (LTW95 eq. 1; paper eq. 5): force `k (l - rest)` along the spring,
/// stiffening to `k * factor` past `rest * (1 + stiffen_strain)` when `biphasic`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    pub nodes: [usize; 2],
    pub rest: f64,
    pub k: f64,
    pub biphasic: bool,
}

/// A prism element: top triangle (outer sheet) then bottom triangle (inner sheet), split into
/// three tetrahedra for its volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prism {
    pub nodes: [usize; 6],
    pub rest_volume: f64,
    /// Gram matrix of the rest shape-function gradients, summed over the 18 tetrahedra
    /// weighted by their share of the volume (see `prism_gram`).
    pub gram: [[f64; 6]; 6],
}

/// The tetrahedra of a prism, as indices into its six nodes (top 0-2, bottom 3-5), all
/// positively oriented for a valid prism whose top triangle is counter-clockwise seen from
/// outside. A prism splits into three tetrahedra in six ways (three starting corners, two
/// orientations); one split depends on the vertex order, so a mirrored face would get a
/// different volume. The average over all six is order-free (it is the volume of the prism
/// with bilinear side faces), so `PRISM_TETS` lists all 18, each weighted `1/6`.
pub const PRISM_TETS: [[usize; 4]; 18] = {
    let orders = [
        [0, 1, 2],
        [1, 2, 0],
        [2, 0, 1],
        [0, 2, 1],
        [2, 1, 0],
        [1, 0, 2],
    ];
    let mut out = [[0; 4]; 18];
    let mut o = 0;
    while o < 6 {
        let [i, j, k] = orders[o];
        let mut tets = [
            [i + 3, j + 3, k + 3, i],
            [j + 3, k + 3, i, j],
            [k + 3, i, j, k],
        ];
        let mut t = 0;
        while t < 3 {
            if o >= 3 {
                // The reversed order gives negatively oriented tetrahedra: swap two corners.
                let first = tets[t][0];
                tets[t][0] = tets[t][1];
                tets[t][1] = first;
            }
            out[3 * o + t] = tets[t];
            t += 1;
        }
        o += 1;
    }
    out
};

/// Weight of each of the `PRISM_TETS` in the prism volume.
pub const PRISM_TET_WEIGHT: f64 = 1.0 / 6.0;

/// The prism volume is a homogeneous cubic in the node positions, so its Hessian is linear in
/// them: block (i, j) is the cross-product matrix `[q_ij]_x` with
/// `q_ij = sum_k PRISM_Q[i][j][k] p_k / 36` (1/36 = split weight 1/6 times the tetrahedron's
/// 1/6). Built from the expansion of each tetrahedron's `det[b-a, c-a, d-a]` into the triple
/// products `[b,c,d] - [a,c,d] - [b,a,d] - [b,c,a]`; a triple product `[x,y,z] = x . (y x z)`
/// has Hessian blocks `(x,y) = -[z]_x`, `(x,z) = [y]_x`, `(y,z) = -[x]_x`.
pub const PRISM_Q: [[[i32; 6]; 6]; 6] = {
    let mut c = [[[0i32; 6]; 6]; 6];
    let mut t = 0;
    while t < 18 {
        let [a, b, cc, d] = PRISM_TETS[t];
        let triples = [(1, b, cc, d), (-1, a, cc, d), (-1, b, a, d), (-1, b, cc, a)];
        let mut k = 0;
        while k < 4 {
            let (sign, x, y, z) = triples[k];
            // (x, y) += -sign z, (x, z) += sign y, (y, z) += -sign x; (j, i) = -(i, j).
            let terms = [(x, y, z, -sign), (x, z, y, sign), (y, z, x, -sign)];
            let mut m = 0;
            while m < 3 {
                let (i, j, node, v) = terms[m];
                c[i][j][node] += v;
                c[j][i][node] -= v;
                m += 1;
            }
            k += 1;
        }
        t += 1;
    }
    c
};

/// Volume, gradient and Hessian vectors of a prism: `(V, dV/dp_i, q_ij)` with
/// `d2V / dp_i dp_j = [q_ij]_x` (zero for i = j). Positions are taken relative to node 0 (the
/// volume is translation invariant), which keeps the cubic terms small; then Euler's theorem
/// for homogeneous forms gives `grad V = H r / 2` and `V = r . grad V / 3`.
pub fn prism_volume_derivatives(p: &[V3; 6]) -> (f64, [V3; 6], [[V3; 6]; 6]) {
    let r = p.map(|x| sub(x, p[0]));
    let mut q = [[[0.0; 3]; 6]; 6];
    for i in 0..6 {
        for j in (i + 1)..6 {
            let mut v = [0.0; 3];
            for (k, rk) in r.iter().enumerate().skip(1) {
                let c = PRISM_Q[i][j][k];
                if c != 0 {
                    let c = c as f64 / 36.0;
                    v = [v[0] + c * rk[0], v[1] + c * rk[1], v[2] + c * rk[2]];
                }
            }
            q[i][j] = v;
            q[j][i] = [-v[0], -v[1], -v[2]];
        }
    }
    let mut g = [[0.0; 3]; 6];
    let mut volume = 0.0;
    for i in 0..6 {
        let mut gi = [0.0; 3];
        for j in 1..6 {
            if j != i {
                let c = cross(q[i][j], r[j]);
                gi = [gi[0] + c[0], gi[1] + c[1], gi[2] + c[2]];
            }
        }
        g[i] = [0.5 * gi[0], 0.5 * gi[1], 0.5 * gi[2]];
        volume += dot(g[i], r[i]);
    }
    (volume / 3.0, g, q)
}

/// `S_ab = sum_t w V_t g_a . g_b` over the `PRISM_TETS` t (weight w = `PRISM_TET_WEIGHT`),
/// with `V_t` the tetrahedron's volume and `g_a` the gradient of its linear shape function
/// of node a, all at the rest positions `p`. Since a tetrahedron's deformation gradient is
/// `F = sum_a x_a g_a^T`, `x^T S x / 2` (per coordinate) is the volume-weighted mean of
/// `|F|^2 / 2`: a quadratic, rotation-invariant measure of distortion whose gradient at rest
/// equals the prism's volume gradient. Rows sum to zero (translations cost nothing).
pub fn prism_gram(p: &[V3; 6]) -> [[f64; 6]; 6] {
    let mut s = [[0.0; 6]; 6];
    for t in &PRISM_TETS {
        let [a, b, c, d] = t.map(|i| p[i]);
        let (e1, e2, e3) = (sub(b, a), sub(c, a), sub(d, a));
        let det = dot(e1, cross(e2, e3));
        let gb = scale(cross(e2, e3), 1.0 / det);
        let gc = scale(cross(e3, e1), 1.0 / det);
        let gd = scale(cross(e1, e2), 1.0 / det);
        let g = [scale(add(add(gb, gc), gd), -1.0), gb, gc, gd];
        let w = PRISM_TET_WEIGHT * det / 6.0;
        for (i, gi) in g.iter().enumerate() {
            for (j, gj) in g.iter().enumerate() {
                s[t[i]][t[j]] += w * dot(*gi, *gj);
            }
        }
    }
    s
}

/// Signed volume of a prism from its six node positions: the mean of its six splits into
/// three tetrahedra (see `PRISM_TETS`).
pub fn prism_volume(p: &[V3; 6]) -> f64 {
    prism_volume_derivatives(p).0
}

/// Smallest signed tetrahedron volume of a prism: negative means the element is inverted.
pub fn prism_min_tet_volume(p: &[V3; 6]) -> f64 {
    PRISM_TETS
        .iter()
        .map(|t| tet_volume(p[t[0]], p[t[1]], p[t[2]], p[t[3]]))
        .fold(f64::INFINITY, f64::min)
}

/// The generated tissue: rest node positions for all four sheets, the inward offset
/// directions, the elements and their springs.
#[derive(Clone, Debug)]
pub struct Tissue {
    pub vertex_count: usize,
    /// Rest positions, `SHEETS * vertex_count`.
    pub rest: Vec<V3>,
    /// Unit outward normal per surface vertex used to offset the sheets (smoothed).
    pub normals: Vec<V3>,
    /// Per-vertex thickness scale in (0, 1] after fold removal.
    pub thickness_scale: Vec<f64>,
    pub springs: Vec<Spring>,
    pub prisms: Vec<Prism>,
    /// Prisms left out: no valid rest shape, or the muscle layer under the lips (see `build`).
    pub degenerate_prisms: usize,
}

impl Tissue {
    /// Offsets `mesh` inward and builds the elements. Sheets are thinned where offsetting
    /// along the (smoothed) normals would invert a prism, e.g. at the lips and the nostrils.
    pub fn build(mesh: &Mesh, params: &TissueParams) -> Tissue {
        let n = mesh.vertex_count();
        let normals = smoothed_normals(mesh, params.normal_smoothing_passes);
        let depths = [
            0.0,
            params.epidermis_thickness,
            params.epidermis_thickness + params.dermal_fatty_thickness,
            params.epidermis_thickness
                + params.dermal_fatty_thickness
                + params.muscle_layer_thickness,
        ];
        let (thickness_scale, rest) = thinned_sheets(mesh, &normals, &depths);

        let areas = mesh.vertex_areas();
        let moduli = [
            params.epidermis_modulus,
            params.dermal_fatty_modulus,
            params.muscle_layer_modulus,
        ];
        let mut springs = Vec::new();
        let add_spring = |springs: &mut Vec<Spring>, a: usize, b: usize, k: f64, biphasic| {
            springs.push(Spring {
                nodes: [a, b],
                rest: norm(sub(rest[a], rest[b])),
                k,
                biphasic,
            });
        };
        let edges = mesh.edges();
        for (slab, &modulus) in moduli.iter().enumerate() {
            let nominal = depths[slab + 1] - depths[slab];
            // In-sheet springs: each slab lends half its membrane stiffness E*h to each of its
            // two sheets (the skull sheet is fixed and needs none).
            for &[a, b] in &edges {
                let h = nominal * 0.5 * (thickness_scale[a] + thickness_scale[b]);
                let k = 0.5 * modulus * h;
                add_spring(&mut springs, slab * n + a, slab * n + b, k, slab == SURFACE);
                if slab + 1 < SKULL {
                    add_spring(
                        &mut springs,
                        (slab + 1) * n + a,
                        (slab + 1) * n + b,
                        k,
                        false,
                    );
                }
                // Crossing springs resist shear of the slab.
                let kc = params.crossing_fraction * k;
                add_spring(&mut springs, slab * n + a, (slab + 1) * n + b, kc, false);
                add_spring(&mut springs, slab * n + b, (slab + 1) * n + a, kc, false);
            }
            // Vertical springs: a column of area A and height h has stiffness E A / h.
            for v in 0..n {
                let h = nominal * thickness_scale[v];
                add_spring(
                    &mut springs,
                    slab * n + v,
                    (slab + 1) * n + v,
                    modulus * areas[v] / h,
                    false,
                );
            }
        }
        // Merge duplicate in-sheet springs (a sheet gets one from the slab above and below).
        springs.sort_by_key(|s| s.nodes);
        let mut merged: Vec<Spring> = Vec::with_capacity(springs.len());
        for s in springs {
            match merged.last_mut() {
                Some(last) if last.nodes == s.nodes => {
                    last.k += s.k;
                    last.biphasic |= s.biphasic;
                }
                _ => merged.push(s),
            }
        }

        let (prisms, degenerate_prisms) = volume_prisms(mesh, &rest, &thickness_scale);
        Tissue {
            vertex_count: n,
            rest,
            normals,
            thickness_scale,
            springs: merged,
            prisms,
            degenerate_prisms,
        }
    }

    /// Rest thickness of the muscle layer under vertex `v` (m).
    pub fn muscle_layer_depth(&self, v: usize) -> f64 {
        norm(sub(
            self.rest[FASCIA * self.vertex_count + v],
            self.rest[SKULL * self.vertex_count + v],
        ))
    }
}

/// The six nodes of the prism under triangle `tri` in slab `slab` (0 = epidermis).
pub fn prism_nodes(tri: &[usize; 3], slab: usize, n: usize) -> [usize; 6] {
    let top = slab * n;
    let bottom = (slab + 1) * n;
    [
        top + tri[0],
        top + tri[1],
        top + tri[2],
        bottom + tri[0],
        bottom + tri[1],
        bottom + tri[2],
    ]
}

fn triangle_area(a: V3, b: V3, c: V3) -> f64 {
    0.5 * norm(super::geom::cross(sub(b, a), sub(c, a)))
}

/// Vertex normals averaged with their neighbours' `passes` times, then pulled back toward the
/// raw normal where the smoothed one would lean more than ~70 degrees from an incident
/// triangle's normal (the inner faces of the lips), which would shear those prisms flat.
fn smoothed_normals(mesh: &Mesh, passes: usize) -> Vec<V3> {
    let neighbours = mesh.neighbours();
    let raw = mesh.vertex_normals();
    let mut normals = raw.clone();
    for _ in 0..passes {
        normals = (0..mesh.vertex_count())
            .map(|v| {
                let sum = neighbours[v]
                    .iter()
                    .fold(normals[v], |acc, &u| add(acc, normals[u]));
                normalize(sum)
            })
            .collect();
    }
    let mut incident: Vec<Vec<V3>> = vec![Vec::new(); mesh.vertex_count()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v]);
        let n = normalize(super::geom::cross(sub(b, a), sub(c, a)));
        for &v in t {
            incident[v].push(n);
        }
    }
    for v in 0..mesh.vertex_count() {
        let worst = |d: V3| {
            incident[v]
                .iter()
                .map(|&n| (super::geom::dot(n, d), n))
                .fold(
                    (f64::INFINITY, [0.0; 3]),
                    |a, b| if b.0 < a.0 { b } else { a },
                )
        };
        if worst(normals[v]).0 >= MIN_NORMAL_COSINE {
            continue;
        }
        // Turn the direction toward its worst triangle until every incident triangle is
        // faced as well as possible (the axis of the narrowest cone around their normals).
        let mut d = normals[v];
        let mut step = 0.5;
        for _ in 0..200 {
            let (cos, n) = worst(d);
            if cos >= MIN_NORMAL_COSINE {
                break;
            }
            let candidate = normalize(add(d, scale(n, step)));
            if worst(candidate).0 > cos {
                d = candidate;
            } else {
                step *= 0.5;
            }
        }
        normals[v] = d;
    }
    normals
}

/// Below this thickness scale a vertex counts as lip tissue, not bound to bone.
pub const LIP_THICKNESS_SCALE: f64 = 0.3;

/// Thinning stops here: a flatter prism only becomes numerically degenerate.
const MIN_THICKNESS_SCALE: f64 = 0.1;

/// Smallest cosine allowed between a vertex's offset direction and its triangles' normals.
const MIN_NORMAL_COSINE: f64 = 0.35;

/// The sheets' rest positions (`SHEETS` x the mesh's vertices, each offset along its normal
/// by the layer depths) and each vertex's thickness scale: the sheets are thinned where a
/// prism would be flat or inverted, and the thinning spreads a little so thickness varies
/// smoothly.
fn thinned_sheets(mesh: &Mesh, normals: &[V3], depths: &[f64; SHEETS]) -> (Vec<f64>, Vec<V3>) {
    let n = mesh.vertex_count();
    let neighbours = mesh.neighbours();
    let mut thickness_scale = vec![1.0; n];
    let place = |scales: &[f64]| -> Vec<V3> {
        let mut rest = Vec::with_capacity(SHEETS * n);
        for &depth in depths {
            for v in 0..n {
                rest.push(sub(mesh.positions[v], scale(normals[v], depth * scales[v])));
            }
        }
        rest
    };
    // Thin the sheets where a prism would be flat or inverted, then let the thinning spread
    // a little so thickness varies smoothly.
    let mut rest = place(&thickness_scale);
    for _pass in 0..200 {
        let mut bad = vec![false; n];
        let mut any = false;
        for tri in &mesh.triangles {
            for slab in 0..SHEETS - 1 {
                let p = prism_nodes(tri, slab, n).map(|i| rest[i]);
                let expected = triangle_area(p[0], p[1], p[2])
                    * (depths[slab + 1] - depths[slab])
                    * tri.iter().map(|&v| thickness_scale[v]).fold(1.0, f64::min);
                if prism_min_tet_volume(&p) < 0.05 * expected {
                    for &v in tri {
                        bad[v] = true;
                    }
                    any = true;
                }
            }
        }
        if !any {
            break;
        }
        for v in 0..n {
            if bad[v] {
                thickness_scale[v] = (thickness_scale[v] * 0.85).max(MIN_THICKNESS_SCALE);
            }
        }
        let smoothed: Vec<f64> = (0..n)
            .map(|v| {
                let mean = neighbours[v]
                    .iter()
                    .map(|&u| thickness_scale[u])
                    .sum::<f64>()
                    / neighbours[v].len().max(1) as f64;
                thickness_scale[v].min(mean * 1.15)
            })
            .collect();
        thickness_scale = smoothed;
        rest = place(&thickness_scale);
    }
    (thickness_scale, rest)
}

/// The prisms that carry a volume term, and how many carry none (the commissures' folded
/// prisms and the lips' thinned muscle layer).
fn volume_prisms(mesh: &Mesh, rest: &[V3], thickness_scale: &[f64]) -> (Vec<Prism>, usize) {
    let n = mesh.vertex_count();
    // At the lip commissures the surface folds back on itself (incident triangle normals
    // ~150 degrees apart): no offset direction gives those prisms positive volume. They
    // keep their springs but carry no volume term or inversion check.
    let mut prisms = Vec::with_capacity(3 * mesh.triangles.len());
    let mut degenerate_prisms = 0;
    for tri in &mesh.triangles {
        for slab in 0..SHEETS - 1 {
            let nodes = prism_nodes(tri, slab, n);
            let p = nodes.map(|i| rest[i]);
            // The lips are not bound to bone: where the tissue had to be thinned to
            // near nothing (the commissures and the inner lips) the muscle layer keeps its
            // springs but no volume element, so the lips can slide over the teeth.
            let lip = slab == SKULL - 1
                && tri
                    .iter()
                    .any(|&v| thickness_scale[v] < LIP_THICKNESS_SCALE);
            if lip || prism_min_tet_volume(&p) <= 0.0 {
                degenerate_prisms += 1;
                continue;
            }
            prisms.push(Prism {
                nodes,
                rest_volume: prism_volume(&p),
                gram: prism_gram(&p),
            });
        }
    }
    (prisms, degenerate_prisms)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn skewed_prism() -> [V3; 6] {
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.2, 0.9, 0.1],
            [0.1, -0.05, -0.8],
            [0.9, 0.2, -0.7],
            [0.3, 0.7, -0.9],
        ]
        .map(|v| add(v, [3.0, -2.0, 5.0]))
    }

    #[test]
    fn closed_form_volume_is_the_mean_of_the_eighteen_tetrahedra() {
        let p = skewed_prism();
        let tets: f64 = PRISM_TETS
            .iter()
            .map(|t| tet_volume(p[t[0]], p[t[1]], p[t[2]], p[t[3]]))
            .sum::<f64>()
            * PRISM_TET_WEIGHT;
        let v = prism_volume(&p);
        assert!((v - tets).abs() < 1e-12, "{v} vs {tets}");
        assert!(v > 0.2, "a positive prism: {v}");
    }

    #[test]
    fn gram_rows_sum_to_zero_and_its_rest_gradient_is_the_volume_gradient() {
        let p = skewed_prism();
        let s = prism_gram(&p);
        let (_, dv, _) = prism_volume_derivatives(&p);
        for a in 0..6 {
            let size = s[a].iter().map(|v| v.abs()).fold(0.0, f64::max);
            assert!(
                s[a].iter().sum::<f64>().abs() <= 1e-12 * size,
                "row {a}: {:?}",
                s[a]
            );
            for b in 0..6 {
                assert_eq!(s[a][b], s[b][a]);
            }
            // d/dx_a of sum_t w V_t |F_t|^2 / 2 at F = I is sum_t w V_t g_a = dV/dx_a.
            let mut grad = [0.0; 3];
            for (b, pb) in p.iter().enumerate() {
                for c in 0..3 {
                    grad[c] += s[a][b] * pb[c];
                }
            }
            assert!(
                norm(sub(grad, dv[a])) <= 1e-9 * norm(dv[a]),
                "node {a}: {grad:?} against {:?}",
                dv[a]
            );
        }
    }

    #[test]
    fn volume_derivatives_match_finite_differences() {
        let p = skewed_prism();
        let (_, g, q) = prism_volume_derivatives(&p);
        let h = 1e-6;
        for i in 0..6 {
            for c in 0..3 {
                let mut plus = p;
                let mut minus = p;
                plus[i][c] += h;
                minus[i][c] -= h;
                let fd = (prism_volume(&plus) - prism_volume(&minus)) / (2.0 * h);
                assert!((fd - g[i][c]).abs() < 1e-8, "dV/dp{i}[{c}]");
                let (_, gp, _) = prism_volume_derivatives(&plus);
                let (_, gm, _) = prism_volume_derivatives(&minus);
                for j in 0..6 {
                    // Column c of block (j, i) is d(grad_j)/d(p_i[c]) = [q_ji]_x e_c.
                    let mut unit = [0.0; 3];
                    unit[c] = 1.0;
                    let expect = cross(q[j][i], unit);
                    for r in 0..3 {
                        let fd = (gp[j][r] - gm[j][r]) / (2.0 * h);
                        assert!((fd - expect[r]).abs() < 1e-7, "H[{j}][{i}]({r},{c})");
                    }
                }
            }
        }
    }
}
