//! Learning AUs -> activations (DESIGN 2.3): the candle MLP, its seeded initialization,
//! per-AU normalization and training. Uses nothing else from the crate: randomness comes in
//! as a uniform source the caller makes from `rng::stream`.

pub mod batch;
pub mod mlp;
pub mod params;

pub use batch::{batchable, train_batch, BatchError, Job};
pub use mlp::{train, Curves, LearnError, Mlp, Normalizer, Pairs};
pub use params::{ModelParams, Normalization, TrainParams};

/// Runs `f` with candle's CPU kernels on one thread each (candle reads `RAYON_NUM_THREADS`
/// at every matrix product), for work that runs several networks side by side on rayon's
/// workers, and for a network trained alone: a small MLP trains fastest on one thread (on two
/// it takes twice as long, `bench train`), and the bytes do not depend on it.
/// The variable is restored afterwards, also if `f` panics; rayon's global pool is started
/// first, so it keeps its own size.
pub fn one_thread_each<R>(f: impl FnOnce() -> R) -> R {
    const VAR: &str = "RAYON_NUM_THREADS";
    struct Restore(Option<std::ffi::OsString>);
    impl Drop for Restore {
        fn drop(&mut self) {
            match self.0.take() {
                Some(v) => std::env::set_var(VAR, v),
                None => std::env::remove_var(VAR),
            }
        }
    }
    let _ = rayon::current_num_threads();
    let _restore = Restore(std::env::var_os(VAR));
    std::env::set_var(VAR, "1");
    f()
}
