//! Network and training parameters (paper 4.1, 4.3): what a `[model]` and `[train]` section
//! resolve to.

/// Per-AU input normalization, fitted on the training inputs and stored with the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Normalization {
    None,
    MinMax,
    ZScore,
}

impl Normalization {
    /// What this normalization subtracts from a column and divides it by: (min, max - min)
    /// for min-max, (mean, population SD) for z-score, (0, 1) for none. The one definition
    /// the network's input normalizer and Table 2's flat-AU test share.
    pub fn offset_spread(self, column: &[f64]) -> (f64, f64) {
        match self {
            Normalization::None => (0.0, 1.0),
            Normalization::MinMax => {
                let (lo, hi) = crate::stats::min_max(column);
                (lo, hi - lo)
            }
            Normalization::ZScore => crate::stats::mean_sd(column),
        }
    }
}

impl Normalization {
    pub const NAMES: [&'static str; 3] = ["none", "minmax", "zscore"];

    pub fn parse(s: &str) -> Option<Normalization> {
        match s {
            "none" => Some(Normalization::None),
            "minmax" => Some(Normalization::MinMax),
            "zscore" => Some(Normalization::ZScore),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Normalization::None => "none",
            Normalization::MinMax => "minmax",
            Normalization::ZScore => "zscore",
        }
    }
}

/// The MLP's hidden layers (paper 4.1: 4 x 100, ReLU; footnote 1 chose it by test MSE).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ModelParams {
    /// Hidden layers. Default 4.
    pub layers: usize,
    /// Neurons per hidden layer. Default 100.
    pub width: usize,
}

impl Default for ModelParams {
    fn default() -> Self {
        ModelParams {
            layers: 4,
            width: 100,
        }
    }
}

/// Training (paper 4.3): Adam, MSE loss.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TrainParams {
    /// Adam step size. Default 0.01.
    pub learning_rate: f64,
    /// Pairs per step. Default 32.
    pub batch_size: usize,
    /// Passes over the training pairs. Default 100.
    pub epochs: usize,
    /// Input normalization. Default none (raw AUs); the paper normalizes each AU across all
    /// pairs (Zeng et al. 4.1, 4.3), which its specs (`experiments/table1.toml` and those
    /// that extend it) set as `train.normalization = "minmax"`.
    pub normalization: Normalization,
}

impl Default for TrainParams {
    fn default() -> Self {
        TrainParams {
            learning_rate: 0.01,
            batch_size: 32,
            epochs: 100,
            normalization: Normalization::None,
        }
    }
}
