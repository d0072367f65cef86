//! facelab: a research harness for biomechanical facial expression transfer, reproducing
//! Zeng et al., "Neuromuscular Control of the Face-Head-Neck Biomechanical Complex With
//! Learning-Based Expression Transfer From Images and Videos", with the muscle-based editing
//! of Choe, Lee & Ko 2001.
//!
//! Modules (see DESIGN.md 4): `sim` (the face), `observe` (landmarks), `io` (files),
//! `report` (renders), `rng` (the only source of randomness).

// Small dense matrix algebra reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub mod cache;
pub mod cohort;
pub mod edit;
pub mod experiments;
pub mod invert;
pub mod io;
pub mod landmark;
pub mod learn;
pub mod observe;
pub mod report;
pub mod rng;
pub mod sim;
pub mod spec;
pub mod stats;
