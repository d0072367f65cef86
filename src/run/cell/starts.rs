//! Where a cell's data set starts its solves besides rest, cached as stages of their own:
//! the linear basis (`basis.bin`) and the grid of the paper family's equilibria (`grid.bin`,
//! where the spec sets `dataset.grid`).

use crate::cache::Entry;
use crate::run::stage::{Artifact, Stages, Unit};
use crate::sim::basis::LinearBasis;
use crate::sim::controls::{Activations, CONTROL_COUNT};
use crate::sim::expression::{Expression, ExpressionWeights};
use crate::sim::geom::V3;
use crate::sim::grid::ExpressionGrid;
use crate::sim::{FaceModel, SolveParams};
use crate::spec::Spec;
use anyhow::{bail, Context, Result};

use super::keys::Keys;

pub(crate) fn basis_bytes(b: &LinearBasis) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend((b.vertex_count as u64).to_le_bytes());
    out.extend((b.rest.len() as u64).to_le_bytes());
    out.extend((b.fields.len() as u64).to_le_bytes());
    for p in &b.rest {
        for c in p {
            out.extend(c.to_le_bytes());
        }
    }
    for f in &b.fields {
        for v in f {
            out.extend(v.to_le_bytes());
        }
    }
    out
}

pub(crate) fn basis_from(bytes: &[u8]) -> Result<LinearBasis> {
    let mut words = bytes
        .chunks_exact(8)
        .map(|c| <[u8; 8]>::try_from(c).expect("8 bytes"));
    let mut next_u = || -> Result<usize> {
        Ok(u64::from_le_bytes(words.next().context("basis file cut short")?) as usize)
    };
    let (vertex_count, nodes, count) = (next_u()?, next_u()?, next_u()?);
    let floats: Vec<f64> = bytes[24..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    if floats.len() != 3 * nodes * (1 + count) {
        bail!(
            "basis file has {} values, expected {}",
            floats.len(),
            3 * nodes * (1 + count)
        );
    }
    let rest: Vec<V3> = floats[..3 * nodes]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let fields = floats[3 * nodes..]
        .chunks_exact(3 * nodes)
        .map(<[f64]>::to_vec)
        .collect();
    Ok(LinearBasis {
        vertex_count,
        rest,
        fields,
    })
}

/// The basis file: its sizes, then the rest positions and the fields (f64, little-endian).
impl Artifact for LinearBasis {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![("basis.bin".into(), basis_bytes(self))])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        basis_from(&entry.read("basis.bin")?)
    }
}

/// The linear basis of the cell's face (cached), when the spec solves from predictions.
pub(crate) fn load_basis(
    k: &Keys,
    stages: &mut Stages,
    model: &FaceModel,
    spec: &Spec,
) -> Result<Option<LinearBasis>> {
    let Some(key) = &k.basis else {
        return Ok(None);
    };
    let basis = stages.get_or_compute(&Unit::keyed("basis", key), |_| {
        let params = SolveParams {
            tolerance: spec.dataset.tolerance,
            ..SolveParams::default()
        };
        LinearBasis::build(model, &params).context("building the linear basis")
    })?;
    Ok(Some(basis))
}

/// The grid file: its steps, its expressions (as indices into `Expression::ALL`) and node
/// count, then the rest positions and, per expression and grid face, the activations and the
/// displacement field (integers u64, values f64, little-endian).
pub(crate) fn grid_bytes(g: &ExpressionGrid) -> Vec<u8> {
    let mut out = Vec::new();
    let indices = g.expressions.iter().map(|e| {
        Expression::ALL
            .iter()
            .position(|x| x == e)
            .expect("every expression is in ALL")
    });
    let head = [g.steps, g.expressions.len()]
        .into_iter()
        .chain(indices)
        .chain([g.rest.len()]);
    for word in head {
        out.extend((word as u64).to_le_bytes());
    }
    let faces = g
        .activations
        .iter()
        .zip(&g.fields)
        .flat_map(|(a, f)| a.iter().zip(f));
    let floats = g
        .rest
        .iter()
        .flatten()
        .chain(faces.flat_map(|(a, f)| a.values().iter().chain(f)));
    for v in floats {
        out.extend(v.to_le_bytes());
    }
    out
}

pub(crate) fn grid_from(bytes: &[u8]) -> Result<ExpressionGrid> {
    let word = |i: usize| -> Result<usize> {
        let b = bytes.get(8 * i..8 * i + 8).context("grid file cut short")?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")) as usize)
    };
    let (steps, count) = (word(0)?, word(1)?);
    if !(3..=64).contains(&steps) || count > Expression::ALL.len() {
        bail!("grid file: {steps} steps and {count} expressions");
    }
    let expressions = (0..count)
        .map(|i| {
            let index = word(2 + i)?;
            Expression::ALL
                .get(index)
                .copied()
                .with_context(|| format!("grid file: expression {index}"))
        })
        .collect::<Result<Vec<_>>>()?;
    let nodes = word(2 + count)?;
    let faces = (steps + 1) * (steps + 1);
    let per_face = CONTROL_COUNT + 3 * nodes;
    let floats: Vec<f64> = bytes[8 * (3 + count)..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let expected = 3 * nodes + count * faces * per_face;
    if floats.len() != expected || bytes.len() % 8 != 0 {
        bail!("grid file has {} values, expected {expected}", floats.len());
    }
    let rest = floats[..3 * nodes]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let (mut activations, mut fields) = (Vec::new(), Vec::new());
    for expression in floats[3 * nodes..].chunks_exact(faces * per_face) {
        let (mut a, mut f) = (Vec::new(), Vec::new());
        for face in expression.chunks_exact(per_face) {
            let values: [f64; CONTROL_COUNT] = face[..CONTROL_COUNT]
                .try_into()
                .expect("CONTROL_COUNT values");
            a.push(Activations::from_values(&values).context("grid file")?);
            f.push(face[CONTROL_COUNT..].to_vec());
        }
        activations.push(a);
        fields.push(f);
    }
    Ok(ExpressionGrid {
        steps,
        expressions,
        rest,
        fields,
        activations,
    })
}

impl Artifact for ExpressionGrid {
    fn encode(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![("grid.bin".into(), grid_bytes(self))])
    }
    fn decode(entry: &Entry) -> Result<Self> {
        grid_from(&entry.read("grid.bin")?)
    }
}

/// The grid of the paper family's equilibria (cached), when the data set starts from it.
pub(crate) fn load_grid(
    k: &Keys,
    stages: &mut Stages,
    model: &FaceModel,
    weights: &ExpressionWeights,
    spec: &Spec,
) -> Result<Option<ExpressionGrid>> {
    let Some(key) = &k.grid else {
        return Ok(None);
    };
    let grid = stages.get_or_compute(&Unit::keyed("grid", key), |_| {
        let params = SolveParams {
            tolerance: spec.dataset.tolerance,
            ..SolveParams::default()
        };
        ExpressionGrid::build(model, weights, &Expression::ALL, spec.dataset.grid, &params)
            .context("solving the grid of the paper family's faces")
    })?;
    Ok(Some(grid))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_file_reads_back_to_the_same_grid_and_a_cut_one_is_an_error() {
        let weights = crate::io::face::FaceSource::of(&crate::io::Layout::here())
            .weights()
            .unwrap();
        let expressions = vec![Expression::Fear, Expression::Joy];
        let steps = 3;
        let nodes = 5;
        let points = crate::sim::grid::grid_points(&expressions, steps);
        let grid = ExpressionGrid {
            steps,
            rest: (0..nodes)
                .map(|i| [i as f64, 0.5, -1.0 / (i + 1) as f64])
                .collect(),
            fields: points
                .chunks(16)
                .map(|c| {
                    c.iter()
                        .map(|&(_, s, j)| (0..3 * nodes).map(|k| s * k as f64 - j).collect())
                        .collect()
                })
                .collect(),
            activations: points
                .chunks(16)
                .map(|c| c.iter().map(|&(e, s, j)| weights.sample(e, s, j)).collect())
                .collect(),
            expressions,
        };
        let bytes = grid_bytes(&grid);
        let back = grid_from(&bytes).unwrap();
        assert_eq!(back.steps, grid.steps);
        assert_eq!(back.expressions, grid.expressions);
        assert_eq!(back.rest, grid.rest);
        assert_eq!(back.fields, grid.fields);
        assert_eq!(back.activations, grid.activations);
        assert_eq!(grid_bytes(&back), bytes);
        let cut = grid_from(&bytes[..bytes.len() - 8]).unwrap_err();
        assert!(format!("{cut:#}").contains("values, expected"), "{cut:#}");
        assert!(grid_from(&bytes[..12]).is_err());
    }
}
