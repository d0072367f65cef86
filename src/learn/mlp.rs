//! The AU -> activation network (paper 4.1): a candle MLP, `inputs -> layers x width ReLU ->
//! outputs` (linear), f32, trained with Adam on the MSE (paper 4.3).
//!
//! Determinism: weights are drawn from the caller's seeded uniform source in sorted parameter
//! name order, PyTorch's default `U(-1/sqrt(fan_in), 1/sqrt(fan_in))` for weights and biases;
//! batches are shuffled from the same source. candle's CPU matrix products split work by
//! output block, so the thread count does not change any sum's order.

use std::collections::BTreeMap;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::optim::{AdamW, Optimizer, ParamsAdamW};

use super::params::{ModelParams, Normalization, TrainParams};

#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    #[error("training diverged at epoch {epoch}, step {step}: loss {loss}")]
    Diverged {
        epoch: usize,
        step: usize,
        loss: f64,
    },
    #[error("no training pairs")]
    Empty,
    #[error("the weights file is missing `{0}`")]
    Missing(String),
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    #[error(transparent)]
    Safetensors(#[from] safetensors::SafeTensorError),
}

/// Row-major pairs: `x` is n x inputs, `y` is n x outputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Pairs {
    pub inputs: usize,
    pub outputs: usize,
    pub x: Vec<f32>,
    pub y: Vec<f32>,
}

impl Pairs {
    pub fn len(&self) -> usize {
        self.x.len() / self.inputs.max(1)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Per-input affine map `(x - offset) * scale`, fitted on the training inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer {
    pub offset: Vec<f32>,
    pub scale: Vec<f32>,
}

impl Normalizer {
    pub fn fit(kind: Normalization, pairs: &Pairs) -> Normalizer {
        let (n, d) = (pairs.len(), pairs.inputs);
        let (offset, scale): (Vec<f32>, Vec<f32>) = (0..d)
            .map(|j| {
                let column: Vec<f64> = (0..n).map(|i| pairs.x[i * d + j] as f64).collect();
                let (offset, spread) = kind.offset_spread(&column);
                let scale = if spread > 1e-12 {
                    (1.0 / spread) as f32
                } else {
                    1.0
                };
                (offset as f32, scale)
            })
            .unzip();
        Normalizer { offset, scale }
    }

    /// The map that normalizes with `self` and de-normalizes with `target`: data normalized
    /// like `self`'s source land where `target`'s source lies (per input, affine).
    pub fn onto(&self, target: &Normalizer) -> Normalizer {
        let (offset, scale) = self
            .offset
            .iter()
            .zip(&self.scale)
            .zip(target.offset.iter().zip(&target.scale))
            .map(|((&o, &s), (&to, &ts))| {
                // ((x - o) s) / ts + to = (x - (o - to ts / s)) (s / ts)
                let (o, s, to, ts) = (o as f64, s as f64, to as f64, ts as f64);
                ((o - to * ts / s) as f32, (s / ts) as f32)
            })
            .unzip();
        Normalizer { offset, scale }
    }

    pub fn apply(&self, x: &[f32]) -> Vec<f32> {
        let d = self.offset.len();
        x.iter()
            .enumerate()
            .map(|(i, v)| (v - self.offset[i % d]) * self.scale[i % d])
            .collect()
    }
}

/// A trained (or initialized) network with its input normalization.
pub struct Mlp {
    /// (weight out x in, bias out) per layer.
    pub(super) layers: Vec<(Var, Var)>,
    pub normalizer: Normalizer,
    pub inputs: usize,
    pub outputs: usize,
}

fn name(layer: usize, part: &str) -> String {
    format!("layer{layer:02}.{part}")
}

impl Mlp {
    /// A fresh network; `uniform` yields U[0, 1) draws from a seeded stream.
    pub fn new(
        inputs: usize,
        outputs: usize,
        model: &ModelParams,
        normalizer: Normalizer,
        uniform: &mut dyn FnMut() -> f64,
    ) -> Result<Mlp, LearnError> {
        let mut sizes = vec![inputs];
        sizes.extend(std::iter::repeat_n(model.width, model.layers));
        sizes.push(outputs);
        // Shapes by sorted name, so the draw order is the name order.
        let mut shapes: BTreeMap<String, (usize, usize, usize)> = BTreeMap::new();
        for l in 0..sizes.len() - 1 {
            shapes.insert(name(l, "bias"), (sizes[l + 1], 1, sizes[l]));
            shapes.insert(name(l, "weight"), (sizes[l + 1], sizes[l], sizes[l]));
        }
        let mut tensors: BTreeMap<String, Var> = BTreeMap::new();
        for (n, &(rows, cols, fan_in)) in &shapes {
            let bound = 1.0 / (fan_in as f64).sqrt();
            let data: Vec<f32> = (0..rows * cols)
                .map(|_| ((2.0 * uniform() - 1.0) * bound) as f32)
                .collect();
            let shape = if cols == 1 {
                vec![rows]
            } else {
                vec![rows, cols]
            };
            tensors.insert(n.clone(), Var::from_vec(data, shape, &Device::Cpu)?);
        }
        let layers = (0..sizes.len() - 1)
            .map(|l| {
                (
                    tensors[&name(l, "weight")].clone(),
                    tensors[&name(l, "bias")].clone(),
                )
            })
            .collect();
        Ok(Mlp {
            layers,
            normalizer,
            inputs,
            outputs,
        })
    }

    fn vars(&self) -> Vec<Var> {
        self.layers
            .iter()
            .flat_map(|(w, b)| [w.clone(), b.clone()])
            .collect()
    }

    /// Forward pass on normalized inputs (n x inputs).
    fn forward(&self, x: &Tensor) -> Result<Tensor, LearnError> {
        let mut h = x.clone();
        let last = self.layers.len() - 1;
        for (l, (w, b)) in self.layers.iter().enumerate() {
            h = h
                .matmul(&w.as_tensor().t()?)?
                .broadcast_add(b.as_tensor())?;
            if l < last {
                h = h.relu()?;
            }
        }
        Ok(h)
    }

    /// Predictions for raw (unnormalized) inputs, row-major.
    pub fn predict(&self, x: &[f32]) -> Result<Vec<f32>, LearnError> {
        let n = x.len() / self.inputs;
        let t = Tensor::from_vec(self.normalizer.apply(x), (n, self.inputs), &Device::Cpu)?;
        Ok(self.forward(&t)?.flatten_all()?.to_vec1::<f32>()?)
    }

    /// Mean squared error over all pairs and outputs.
    pub fn mse(&self, pairs: &Pairs) -> Result<f64, LearnError> {
        if pairs.is_empty() {
            return Ok(0.0);
        }
        Ok(mse_of(&self.predict(&pairs.x)?, &pairs.y))
    }

    /// Weights and normalization as safetensors bytes (names sorted, no metadata).
    pub fn to_safetensors(&self) -> Result<Vec<u8>, LearnError> {
        let mut named: BTreeMap<String, Tensor> = BTreeMap::new();
        for (l, (w, b)) in self.layers.iter().enumerate() {
            named.insert(name(l, "weight"), w.as_tensor().clone());
            named.insert(name(l, "bias"), b.as_tensor().clone());
        }
        let d = self.inputs;
        named.insert(
            "norm.offset".into(),
            Tensor::from_vec(self.normalizer.offset.clone(), d, &Device::Cpu)?,
        );
        named.insert(
            "norm.scale".into(),
            Tensor::from_vec(self.normalizer.scale.clone(), d, &Device::Cpu)?,
        );
        Ok(safetensors::serialize(named.iter(), None)?)
    }

    /// Reads what `to_safetensors` wrote.
    pub fn from_safetensors(bytes: &[u8]) -> Result<Mlp, LearnError> {
        let map = candle_core::safetensors::load_buffer(bytes, &Device::Cpu)?;
        let get = |n: &str| {
            map.get(n)
                .cloned()
                .ok_or_else(|| LearnError::Missing(n.into()))
        };
        let mut layers = Vec::new();
        while map.contains_key(&name(layers.len(), "weight")) {
            let l = layers.len();
            layers.push((
                Var::from_tensor(&get(&name(l, "weight"))?)?,
                Var::from_tensor(&get(&name(l, "bias"))?)?,
            ));
        }
        let offset = get("norm.offset")?.to_vec1::<f32>()?;
        let scale = get("norm.scale")?.to_vec1::<f32>()?;
        let inputs = offset.len();
        let outputs = layers
            .last()
            .ok_or_else(|| LearnError::Missing(name(0, "weight")))?
            .1
            .as_tensor()
            .dims1()?;
        Ok(Mlp {
            layers,
            normalizer: Normalizer { offset, scale },
            inputs,
            outputs,
        })
    }
}

/// The mean squared error of predictions `p` against targets `y` (row-major, alike), in f64.
pub(super) fn mse_of(p: &[f32], y: &[f32]) -> f64 {
    let d: Vec<f64> = p.iter().zip(y).map(|(a, b)| (a - b) as f64).collect();
    crate::stats::mean_square(&d)
}

/// Train and test MSE after each epoch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Curves {
    pub train: Vec<f64>,
    pub test: Vec<f64>,
}

/// Trains a fresh network on `train`, recording both curves; `uniform` seeds the weights and
/// the batch order.
pub fn train(
    train_pairs: &Pairs,
    test_pairs: &Pairs,
    model: &ModelParams,
    params: &TrainParams,
    uniform: &mut dyn FnMut() -> f64,
) -> Result<(Mlp, Curves), LearnError> {
    if train_pairs.is_empty() {
        return Err(LearnError::Empty);
    }
    let normalizer = Normalizer::fit(params.normalization, train_pairs);
    let mlp = Mlp::new(
        train_pairs.inputs,
        train_pairs.outputs,
        model,
        normalizer,
        uniform,
    )?;
    let (n, d, o) = (train_pairs.len(), train_pairs.inputs, train_pairs.outputs);
    let x = Tensor::from_vec(mlp.normalizer.apply(&train_pairs.x), (n, d), &Device::Cpu)?;
    let y = Tensor::from_vec(train_pairs.y.clone(), (n, o), &Device::Cpu)?;
    let mut opt = AdamW::new(
        mlp.vars(),
        ParamsAdamW {
            lr: params.learning_rate,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        },
    )?;
    let mut curves = Curves::default();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut step = 0;
    for epoch in 1..=params.epochs {
        // Fisher-Yates with our stream.
        for i in (1..n).rev() {
            let j = ((uniform() * (i + 1) as f64) as usize).min(i);
            order.swap(i, j);
        }
        let mut sum = 0.0;
        for batch in order.chunks(params.batch_size) {
            step += 1;
            let idx = Tensor::from_slice(batch, batch.len(), &Device::Cpu)?;
            let xb = x.index_select(&idx, 0)?;
            let yb = y.index_select(&idx, 0)?;
            let loss = (mlp.forward(&xb)? - yb)?.sqr()?.mean_all()?;
            let value = loss.to_dtype(DType::F64)?.to_scalar::<f64>()?;
            if !value.is_finite() {
                return Err(LearnError::Diverged {
                    epoch,
                    step,
                    loss: value,
                });
            }
            sum += value * batch.len() as f64;
            opt.backward_step(&loss)?;
        }
        let train_mse = sum / n as f64;
        curves.train.push(train_mse);
        curves.test.push(mlp.mse(test_pairs)?);
    }
    // The last step may have made the weights non-finite without a non-finite loss yet.
    let check = mlp.mse(train_pairs)?;
    if !check.is_finite() {
        return Err(LearnError::Diverged {
            epoch: params.epochs,
            step,
            loss: check,
        });
    }
    Ok((mlp, curves))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A seeded U[0, 1) source for the learning tests (a linear congruential generator).
    pub(in crate::learn) fn uniform_from(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn line_data(n: usize) -> Pairs {
        let mut u = uniform_from(9);
        let mut p = Pairs {
            inputs: 2,
            outputs: 1,
            ..Default::default()
        };
        for _ in 0..n {
            let (a, b) = (u() as f32, u() as f32);
            p.x.extend([a, b]);
            p.y.push(0.3 * a - 0.2 * b + 0.1);
        }
        p
    }

    #[test]
    fn learns_a_linear_map_and_round_trips_its_weights() {
        let data = line_data(256);
        let model = ModelParams {
            layers: 2,
            width: 16,
        };
        let params = TrainParams {
            epochs: 60,
            learning_rate: 0.01,
            ..TrainParams::default()
        };
        let (mlp, curves) = train(&data, &data, &model, &params, &mut uniform_from(1)).unwrap();
        assert!(
            curves.test.last().unwrap() < &1e-3,
            "{:?}",
            curves.test.last()
        );
        let bytes = mlp.to_safetensors().unwrap();
        let back = Mlp::from_safetensors(&bytes).unwrap();
        assert_eq!(
            back.predict(&data.x).unwrap(),
            mlp.predict(&data.x).unwrap()
        );
        // Same seed, same bytes.
        let (again, _) = train(&data, &data, &model, &params, &mut uniform_from(1)).unwrap();
        assert_eq!(again.to_safetensors().unwrap(), bytes);
    }

    #[test]
    fn a_huge_learning_rate_diverges_with_the_epoch_named() {
        let data = line_data(64);
        let params = TrainParams {
            learning_rate: 1e12,
            epochs: 50,
            ..TrainParams::default()
        };
        let err = train(
            &data,
            &data,
            &ModelParams::default(),
            &params,
            &mut uniform_from(2),
        )
        .err()
        .expect("diverges");
        assert!(err.to_string().contains("diverged at epoch"), "{err}");
    }
}
