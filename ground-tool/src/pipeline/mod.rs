//! # The calibration chain on real telemetry
//!
//! [`observations`]: DA and FADS (counts → referenced vectors, fine attitudes);
//! [`calibrate`]: TP → FADS → FFCAL → adjustment → IRUCAL → tables; [`tam`]: the TAM
//! calibration against the FHST fine attitude and [`magnetics_table`]: the OBC's Table 6 from it
//! (issue 20).

pub mod alignment_heldout;
pub mod calibrate;
pub mod ffcal_stages;
pub mod fhst_noise;
pub mod filter_floor;
pub mod filter_tuning;
pub mod flown;
pub mod fss_consider;
pub mod fss_systematic;
pub mod gyro_chain;
pub mod iru_fixes;
pub mod magnetics_table;
pub mod maneuvers;
pub mod observations;
pub mod star_batches;
pub mod tam;
pub mod tuning_evidence;
pub mod wheels;
