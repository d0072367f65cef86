//! Networks of one shape trained as one batched model: each layer's weights stacked on a
//! leading axis, one batched matrix product per layer, one optimizer over the stacked
//! tensors. candle pays its per-operation cost once per step for all of them instead of once
//! per network, which is most of what a 32-row step of these small MLPs costs.
//!
//! Each network keeps everything that is its own: its initialization and batch order from
//! its own uniform source, drawn in the order [`train`](super::train) draws them, its own
//! pairs and normalizer, its own loss. The loss summed over the networks has, for each
//! network's weights, that network's gradient alone; the batched products add each network's
//! terms in the order its own product does, and Adam updates element by element. So every
//! network's bytes (weights and curves) are those [`train`](super::train) gives it alone,
//! whatever networks share its batch (`batched_networks_are_trained_as_alone`).

use candle_core::{DType, Device, Tensor, Var, D};
use candle_nn::optim::{AdamW, Optimizer, ParamsAdamW};

use super::mlp::{mse_of, Curves, LearnError, Mlp, Normalizer, Pairs};
use super::params::{ModelParams, TrainParams};

/// One network's part of a batched training: its pairs and its uniform source.
pub struct Job<'a> {
    pub train: &'a Pairs,
    pub test: &'a Pairs,
    pub uniform: &'a mut dyn FnMut() -> f64,
}

/// A batch failed: the index of the network it failed on (`None`: the batch as a whole, e.g.
/// a tensor operation), and why.
#[derive(Debug, thiserror::Error)]
#[error("{}: {error}", index.map_or("the batch".to_string(), |i| format!("network {i} of the batch")))]
pub struct BatchError {
    pub index: Option<usize>,
    #[source]
    pub error: LearnError,
}

/// Whether `jobs` can be trained as one batch: the same numbers of inputs, outputs, training
/// and test pairs (so the same batches and steps per epoch).
pub fn batchable(jobs: &[Job]) -> bool {
    let shape = |j: &Job| (j.train.inputs, j.train.outputs, j.train.len(), j.test.len());
    jobs.windows(2).all(|w| shape(&w[0]) == shape(&w[1]))
}

/// Trains `jobs` (networks of one shape, [`batchable`]) as one batched model; each result is
/// the network and curves [`train`](super::train) makes of its job alone.
pub fn train_batch(
    jobs: &mut [Job],
    model: &ModelParams,
    params: &TrainParams,
) -> Result<Vec<(Mlp, Curves)>, BatchError> {
    let at = |index: usize| {
        move |error: LearnError| BatchError {
            index: Some(index),
            error,
        }
    };
    let on = |e: candle_core::Error| BatchError {
        index: None,
        error: e.into(),
    };
    assert!(batchable(jobs), "a batch holds networks of one shape");
    if let Some(i) = jobs.iter().position(|j| j.train.is_empty()) {
        return Err(at(i)(LearnError::Empty));
    }
    let k = jobs.len();
    // Each network as `train` starts it: normalizer, then weights from its own source.
    let mut nets = Vec::with_capacity(k);
    for (i, job) in jobs.iter_mut().enumerate() {
        let normalizer = Normalizer::fit(params.normalization, job.train);
        let mlp = Mlp::new(
            job.train.inputs,
            job.train.outputs,
            model,
            normalizer,
            job.uniform,
        )
        .map_err(at(i))?;
        nets.push(mlp);
    }
    let stacked = stack(&nets).map_err(on)?;
    let (n, d, o) = (
        jobs[0].train.len(),
        jobs[0].train.inputs,
        jobs[0].train.outputs,
    );
    let tensor = |v: Vec<f32>, rows: usize, cols: usize| {
        Tensor::from_vec(v, (rows, cols), &Device::Cpu).map_err(on)
    };
    let mut x = Vec::with_capacity(k);
    let mut y = Vec::with_capacity(k);
    for (job, net) in jobs.iter().zip(&nets) {
        x.push(tensor(net.normalizer.apply(&job.train.x), n, d)?);
        y.push(tensor(job.train.y.clone(), n, o)?);
    }
    let nt = jobs[0].test.len();
    let test_x: Vec<Tensor> = jobs
        .iter()
        .zip(&nets)
        .map(|(job, net)| tensor(net.normalizer.apply(&job.test.x), nt, d))
        .collect::<Result<_, _>>()?;
    let test_x = Tensor::stack(&test_x, 0).map_err(on)?;
    let vars: Vec<Var> = stacked
        .iter()
        .flat_map(|(w, b)| [w.clone(), b.clone()])
        .collect();
    let mut opt = AdamW::new(
        vars,
        ParamsAdamW {
            lr: params.learning_rate,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        },
    )
    .map_err(on)?;
    let mut curves = vec![Curves::default(); k];
    let mut orders: Vec<Vec<u32>> = vec![(0..n as u32).collect(); k];
    let mut step = 0;
    for epoch in 1..=params.epochs {
        // Fisher-Yates with each network's own stream, as `train` shuffles.
        for (job, order) in jobs.iter_mut().zip(&mut orders) {
            for i in (1..n).rev() {
                let j = (((job.uniform)() * (i + 1) as f64) as usize).min(i);
                order.swap(i, j);
            }
        }
        let mut sums = vec![0.0; k];
        for b in (0..n).step_by(params.batch_size) {
            step += 1;
            let len = params.batch_size.min(n - b);
            let mut xb = Vec::with_capacity(k);
            let mut yb = Vec::with_capacity(k);
            for i in 0..k {
                let idx =
                    Tensor::from_slice(&orders[i][b..b + len], len, &Device::Cpu).map_err(on)?;
                xb.push(x[i].index_select(&idx, 0).map_err(on)?);
                yb.push(y[i].index_select(&idx, 0).map_err(on)?);
            }
            let xb = Tensor::stack(&xb, 0).map_err(on)?;
            let yb = Tensor::stack(&yb, 0).map_err(on)?;
            let squares = (forward(&stacked, &xb).map_err(on)? - yb)
                .and_then(|t| t.sqr())
                .map_err(on)?;
            // Each network's loss as `train` computes it, for its curve and its check.
            for (i, sum) in sums.iter_mut().enumerate() {
                let value = squares
                    .get(i)
                    .and_then(|t| t.mean_all())
                    .and_then(|t| t.to_dtype(DType::F64))
                    .and_then(|t| t.to_scalar::<f64>())
                    .map_err(on)?;
                if !value.is_finite() {
                    return Err(at(i)(LearnError::Diverged {
                        epoch,
                        step,
                        loss: value,
                    }));
                }
                *sum += value * len as f64;
            }
            let loss = squares
                .flatten_from(1)
                .and_then(|t| t.mean(D::Minus1))
                .and_then(|t| t.sum_all())
                .map_err(on)?;
            opt.backward_step(&loss).map_err(on)?;
        }
        let predicted = forward(&stacked, &test_x)
            .and_then(|t| t.flatten_all())
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(on)?;
        for (i, c) in curves.iter_mut().enumerate() {
            c.train.push(sums[i] / n as f64);
            c.test.push(mse(
                &predicted[i * nt * o..(i + 1) * nt * o],
                &jobs[i].test.y,
            ));
        }
    }
    unstack(&stacked, &mut nets).map_err(on)?;
    finished(nets, curves, jobs, params.epochs, step)
}

/// The trained networks with their curves, each checked: the last step may have made its
/// weights non-finite without a non-finite loss yet.
fn finished(
    nets: Vec<Mlp>,
    curves: Vec<Curves>,
    jobs: &[Job],
    epochs: usize,
    step: usize,
) -> Result<Vec<(Mlp, Curves)>, BatchError> {
    let mut out = Vec::with_capacity(nets.len());
    for (i, (net, c)) in nets.into_iter().zip(curves).enumerate() {
        let at = |error| BatchError {
            index: Some(i),
            error,
        };
        let check = net.mse(jobs[i].train).map_err(at)?;
        if !check.is_finite() {
            return Err(at(LearnError::Diverged {
                epoch: epochs,
                step,
                loss: check,
            }));
        }
        out.push((net, c));
    }
    Ok(out)
}

/// Each layer's weights and biases of `nets` stacked on a leading axis (networks first).
fn stack(nets: &[Mlp]) -> candle_core::Result<Vec<(Var, Var)>> {
    let layers = nets[0].layers.len();
    let mut stacked: Vec<(Var, Var)> = Vec::with_capacity(layers);
    for l in 0..layers {
        let w: Vec<&Tensor> = nets.iter().map(|m| m.layers[l].0.as_tensor()).collect();
        let b: Vec<Tensor> = nets
            .iter()
            .map(|m| m.layers[l].1.as_tensor().unsqueeze(0))
            .collect::<Result<_, _>>()?;
        stacked.push((
            Var::from_tensor(&Tensor::stack(&w, 0)?)?,
            Var::from_tensor(&Tensor::stack(&b, 0)?)?,
        ));
    }
    Ok(stacked)
}

/// Each network's weights back from the stacked layers into its own.
fn unstack(stacked: &[(Var, Var)], nets: &mut [Mlp]) -> candle_core::Result<()> {
    for (i, net) in nets.iter_mut().enumerate() {
        for (l, (w, b)) in stacked.iter().enumerate() {
            let w = w.as_tensor().get(i)?.contiguous()?;
            let b = b.as_tensor().get(i)?.squeeze(0)?;
            net.layers[l] = (Var::from_tensor(&w)?, Var::from_tensor(&b)?);
        }
    }
    Ok(())
}

/// The stacked networks' forward pass on stacked normalized inputs (networks x rows x
/// inputs).
fn forward(layers: &[(Var, Var)], x: &Tensor) -> candle_core::Result<Tensor> {
    let mut h = x.clone();
    let last = layers.len() - 1;
    for (l, (w, b)) in layers.iter().enumerate() {
        h = h
            .matmul(&w.as_tensor().transpose(1, 2)?)?
            .broadcast_add(b.as_tensor())?;
        if l < last {
            h = h.relu()?;
        }
    }
    Ok(h)
}

/// `Mlp::mse` of predictions `p` against `y` (0 for none, as `Mlp::mse` of no pairs).
fn mse(p: &[f32], y: &[f32]) -> f64 {
    if p.is_empty() {
        return 0.0;
    }
    mse_of(p, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::mlp::tests::uniform_from;

    fn data(n: usize, seed: u64) -> Pairs {
        let mut u = uniform_from(seed);
        let mut p = Pairs {
            inputs: 3,
            outputs: 2,
            ..Default::default()
        };
        for _ in 0..n {
            let (a, b, c) = (u() as f32, u() as f32, u() as f32);
            p.x.extend([a, b, 2.0 * c]);
            p.y.extend([0.3 * a - 0.2 * b + 0.1, (a * c).max(0.2)]);
        }
        p
    }

    /// Three networks trained as one batch, and as two, give each the bytes (weights and
    /// both curves) it gets trained alone; a ragged last batch included.
    #[test]
    fn batched_networks_are_trained_as_alone() {
        let model = ModelParams {
            layers: 3,
            width: 24,
        };
        let params = TrainParams {
            epochs: 7,
            batch_size: 16,
            learning_rate: 0.01,
            ..TrainParams::default()
        };
        let sets: Vec<(Pairs, Pairs)> = (0..3).map(|s| (data(100, s), data(30, 10 + s))).collect();
        let alone: Vec<(Vec<u8>, Curves)> = sets
            .iter()
            .enumerate()
            .map(|(s, (train, test))| {
                let (m, c) = super::super::train(
                    train,
                    test,
                    &model,
                    &params,
                    &mut uniform_from(s as u64 + 40),
                )
                .unwrap();
                (m.to_safetensors().unwrap(), c)
            })
            .collect();
        for split in [3, 1] {
            let mut sources: Vec<_> = (0..3).map(|s| uniform_from(s as u64 + 40)).collect();
            let mut got = Vec::new();
            let mut jobs: Vec<Job> = sets
                .iter()
                .zip(sources.iter_mut())
                .map(|((train, test), u)| Job {
                    train,
                    test,
                    uniform: u,
                })
                .collect();
            let (first, rest) = jobs.split_at_mut(split);
            for part in [first, rest] {
                if !part.is_empty() {
                    got.extend(train_batch(part, &model, &params).unwrap());
                }
            }
            for (i, ((m, c), (bytes, curves))) in got.iter().zip(&alone).enumerate() {
                assert_eq!(
                    &m.to_safetensors().unwrap(),
                    bytes,
                    "network {i}, split {split}"
                );
                assert_eq!(c, curves, "network {i}, split {split}");
            }
        }
    }

    #[test]
    fn a_batch_of_two_shapes_is_refused() {
        let (a, b) = (data(10, 1), data(12, 2));
        let (mut u, mut v) = (uniform_from(1), uniform_from(2));
        let jobs = [
            Job {
                train: &a,
                test: &a,
                uniform: &mut u,
            },
            Job {
                train: &b,
                test: &b,
                uniform: &mut v,
            },
        ];
        assert!(!batchable(&jobs));
    }
}
