//! facelab: a research harness for biomechanical facial expression transfer, reproducing
//! Zeng et al., "Neuromuscular Control of the Face-Head-Neck Biomechanical Complex With
//! Learning-Based Expression Transfer From Images and Videos", with the muscle-based editing
//! of Choe, Lee & Ko 2001.
//!
//! Modules and what each may use: `docs/architecture.md` (DESIGN 4 as amended), enforced by
//! `tests/architecture.rs`. Leaves: `rng` (the only source of randomness), `stats`, `cache`,
//! `boxqp` (the bounded least-squares solvers). Computation: `sim` (the face and the neck), `observe` (landmarks -> AUs, pose),
//! `learn` (the MLP), `cohort`, `landmark`, `edit`, `dataset` (the training data),
//! `headneck` (the learned neck controller), `judge` (MediaPipe's blendshapes on pictures and
//! faces). Files: `io`. Configuration: `spec`. Output: `report`. The harness, in three rooms:
//! the run machinery (`run`), the transfer pipeline that commands and experiments share
//! (`transfer`), the registered experiments (`experiments`), and the work behind the other
//! command-line tools (`tools`).

// Small dense matrix algebra reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub mod boxqp;
pub mod cache;
pub mod cohort;
pub mod dataset;
pub mod edit;
pub mod experiments;
pub mod headneck;
pub mod io;
pub mod judge;
pub mod landmark;
pub mod learn;
pub mod observe;
pub mod report;
pub mod rng;
pub mod run;
pub mod sim;
pub mod spec;
pub mod stats;
pub mod tools;
pub mod transfer;
