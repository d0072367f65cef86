//! The harness: commands that put the simulator, the observer and the reports together.

pub mod bench;
pub mod editing;
pub mod face;
pub mod headpose;
pub mod inversion;
pub mod observe;
pub mod photos;
pub mod pose_transfer;
pub mod reach;
pub mod realfaces;
pub mod run;
pub mod stage;
pub mod table1;
pub mod table2;
pub mod table2_stage;
pub mod transfer;
