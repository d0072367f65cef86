//! Learning AUs -> activations (DESIGN 2.3): the candle MLP, its seeded initialization,
//! per-AU normalization and training. Uses nothing else from the crate: randomness comes in
//! as a uniform source the caller makes from `rng::stream`.

pub mod batch;
pub mod mlp;
pub mod params;

pub use batch::{batchable, train_batch, BatchError, Job};
pub use mlp::{train, Curves, LearnError, Mlp, Normalizer, Pairs};
pub use params::{ModelParams, Normalization, TrainParams};
