//! The face surface: a triangle mesh in metres, its topology (edges, boundary loops,
//! left/right mirror map) and Loop subdivision.
//!
//! Pure data and geometry; reading mesh files lives in `io::mesh`.

use std::collections::{BTreeMap, HashMap};

use super::geom::{add, cross, normalize, scale, sub, V3};

/// A triangle mesh. Triangles are counter-clockwise seen from outside (the face's front).
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub positions: Vec<V3>,
    pub triangles: Vec<[usize; 3]>,
}

/// Why a mesh cannot be used as a face surface.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    #[error("mesh has no triangles")]
    Empty,
    #[error("triangle {triangle} refers to vertex {vertex}, but the mesh has {count} vertices")]
    VertexOutOfRange {
        triangle: usize,
        vertex: usize,
        count: usize,
    },
    #[error("triangle {triangle} repeats a vertex")]
    Degenerate { triangle: usize },
    #[error("edge ({0}, {1}) is shared by more than two triangles")]
    NonManifold(usize, usize),
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
    #[error(
        "vertex {vertex} has no mirror image across x = 0 (nearest is {distance_m:.2e} m away)"
    )]
    NotSymmetric { vertex: usize, distance_m: f64 },
}

impl Mesh {
    /// Checks indices, degeneracy, manifoldness and finiteness.
    pub fn new(positions: Vec<V3>, triangles: Vec<[usize; 3]>) -> Result<Mesh, MeshError> {
        if triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        if let Some(v) = positions
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(MeshError::NonFinite(v));
        }
        for (t, tri) in triangles.iter().enumerate() {
            for &v in tri {
                if v >= positions.len() {
                    return Err(MeshError::VertexOutOfRange {
                        triangle: t,
                        vertex: v,
                        count: positions.len(),
                    });
                }
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(MeshError::Degenerate { triangle: t });
            }
        }
        let mesh = Mesh {
            positions,
            triangles,
        };
        for (&(a, b), &count) in &mesh.edge_use() {
            if count > 2 {
                return Err(MeshError::NonManifold(a, b));
            }
        }
        Ok(mesh)
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles using each undirected edge (a < b).
    fn edge_use(&self) -> BTreeMap<(usize, usize), usize> {
        let mut uses = BTreeMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        uses
    }

    /// Undirected edges (a < b), sorted.
    pub fn edges(&self) -> Vec<[usize; 2]> {
        self.edge_use().keys().map(|&(a, b)| [a, b]).collect()
    }

    /// Sorted neighbour lists.
    pub fn neighbours(&self) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); self.vertex_count()];
        for [a, b] in self.edges() {
            out[a].push(b);
            out[b].push(a);
        }
        for n in &mut out {
            n.sort_unstable();
        }
        out
    }

    /// Area-weighted vertex normals (unit length).
    pub fn vertex_normals(&self) -> Vec<V3> {
        let mut normals = vec![[0.0; 3]; self.vertex_count()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|v| self.positions[v]);
            let n = cross(sub(b, a), sub(c, a));
            for &v in t {
                normals[v] = add(normals[v], n);
            }
        }
        normals.into_iter().map(normalize).collect()
    }

    /// Per-vertex area: a third of the area of each incident triangle (m^2).
    pub fn vertex_areas(&self) -> Vec<f64> {
        let mut areas = vec![0.0; self.vertex_count()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|v| self.positions[v]);
            let area = 0.5 * super::geom::norm(cross(sub(b, a), sub(c, a)));
            for &v in t {
                areas[v] += area / 3.0;
            }
        }
        areas
    }

    /// Closed boundary loops, each in the direction the triangles traverse their boundary edges,
    /// starting at its smallest vertex index; loops sorted by length, longest first.
    pub fn boundary_loops(&self) -> Vec<Vec<usize>> {
        let uses = self.edge_use();
        let mut next = BTreeMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if uses[&(a.min(b), a.max(b))] == 1 {
                    next.insert(a, b);
                }
            }
        }
        let mut loops = Vec::new();
        let mut seen = std::collections::BTreeSet::new();
        for &start in next.keys() {
            if seen.contains(&start) {
                continue;
            }
            let mut lp = vec![start];
            seen.insert(start);
            let mut v = next[&start];
            while v != start {
                lp.push(v);
                seen.insert(v);
                v = next[&v];
            }
            loops.push(lp);
        }
        loops.sort_by(|a, b| b.len().cmp(&a.len()).then(a[0].cmp(&b[0])));
        loops
    }

    /// For each vertex, the vertex at its mirror image across the x = 0 plane.
    pub fn mirror_map(&self) -> Result<Vec<usize>, MeshError> {
        const CELL: f64 = 1e-3;
        let key = |p: V3| -> (i64, i64, i64) {
            (
                (p[0] / CELL).floor() as i64,
                (p[1] / CELL).floor() as i64,
                (p[2] / CELL).floor() as i64,
            )
        };
        let mut grid: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
        for (i, &p) in self.positions.iter().enumerate() {
            grid.entry(key(p)).or_default().push(i);
        }
        let tolerance = 1e-7;
        let mut map = Vec::with_capacity(self.vertex_count());
        for (i, &p) in self.positions.iter().enumerate() {
            let target = [-p[0], p[1], p[2]];
            let (kx, ky, kz) = key(target);
            let mut best = (f64::INFINITY, usize::MAX);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        for &j in grid.get(&(kx + dx, ky + dy, kz + dz)).into_iter().flatten() {
                            let d = super::geom::norm(sub(self.positions[j], target));
                            if d < best.0 || (d == best.0 && j < best.1) {
                                best = (d, j);
                            }
                        }
                    }
                }
            }
            if best.0 > tolerance {
                return Err(MeshError::NotSymmetric {
                    vertex: i,
                    distance_m: best.0,
                });
            }
            map.push(best.1);
        }
        Ok(map)
    }

    /// One step of Loop subdivision (Loop 1987) with the boundary rules of Hoppe et al. 1994:
    /// boundary curves are subdivided as cubic B-splines, so holes keep their shape.
    /// The first `vertex_count()` vertices keep their indices; edge vertices follow in edge order.
    pub fn loop_subdivide(&self) -> Mesh {
        let n = self.vertex_count();
        let edges = self.edges();
        let edge_index: BTreeMap<(usize, usize), usize> = edges
            .iter()
            .enumerate()
            .map(|(i, &[a, b])| ((a, b), n + i))
            .collect();
        // Opposite vertices of each edge.
        let mut opposite: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                opposite.entry((a.min(b), a.max(b))).or_default().push(c);
            }
        }
        let neighbours = self.neighbours();
        let mut boundary_neighbours = vec![Vec::new(); n];
        for (&(a, b), opp) in &opposite {
            if opp.len() == 1 {
                boundary_neighbours[a].push(b);
                boundary_neighbours[b].push(a);
            }
        }
        let p = &self.positions;
        let mut positions = Vec::with_capacity(n + edges.len());
        for v in 0..n {
            let new = if boundary_neighbours[v].len() == 2 {
                let [b1, b2] = [boundary_neighbours[v][0], boundary_neighbours[v][1]];
                add(scale(p[v], 0.75), scale(add(p[b1], p[b2]), 0.125))
            } else {
                let k = neighbours[v].len() as f64;
                let c = 0.375 + 0.25 * (2.0 * std::f64::consts::PI / k).cos();
                let beta = (0.625 - c * c) / k;
                let sum = neighbours[v]
                    .iter()
                    .fold([0.0; 3], |acc, &u| add(acc, p[u]));
                add(scale(p[v], 1.0 - k * beta), scale(sum, beta))
            };
            positions.push(new);
        }
        for &[a, b] in &edges {
            let opp = &opposite[&(a, b)];
            let new = if opp.len() == 2 {
                add(
                    scale(add(p[a], p[b]), 0.375),
                    scale(add(p[opp[0]], p[opp[1]]), 0.125),
                )
            } else {
                scale(add(p[a], p[b]), 0.5)
            };
            positions.push(new);
        }
        let mid = |a: usize, b: usize| edge_index[&(a.min(b), a.max(b))];
        let mut triangles = Vec::with_capacity(4 * self.triangles.len());
        for &[a, b, c] in &self.triangles {
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            triangles.push([a, ab, ca]);
            triangles.push([b, bc, ab]);
            triangles.push([c, ca, bc]);
            triangles.push([ab, bc, ca]);
        }
        Mesh {
            positions,
            triangles,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Mesh {
        Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    #[test]
    fn square_has_one_boundary_loop_of_four() {
        assert_eq!(square().boundary_loops(), vec![vec![0, 1, 2, 3]]);
    }

    #[test]
    fn subdivision_quadruples_triangles_and_keeps_a_flat_patch_flat() {
        let s = square().loop_subdivide();
        assert_eq!(s.triangles.len(), 8);
        assert_eq!(s.vertex_count(), 4 + 5);
        assert!(s.positions.iter().all(|p| p[2] == 0.0));
        assert_eq!(s.boundary_loops()[0].len(), 8);
    }

    #[test]
    fn out_of_range_vertex_is_named() {
        let err = Mesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 5]]).unwrap_err();
        assert_eq!(
            err,
            MeshError::VertexOutOfRange {
                triangle: 0,
                vertex: 5,
                count: 3
            }
        );
    }
}
