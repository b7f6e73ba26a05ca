//! # The evidence a filter-table noise term is decided on
//!
//! Why a module of its own: the gyro side (`super::filter_tuning`, the Allan deviation of the
//! holds) and the star side (`super::fhst_noise`) both produce it and `filter_tuning` decides
//! on it; here neither depends on the other.

use serde::Serialize;

/// One axis's (or tracker's) evidence on a noise term, in the table field's unit (per gyro
/// channel for σ_v and σ_u): the whole data's value and interval, and each held-out fold's
/// value (`None` when the term is not detected).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NoiseEvidence {
    /// Gyro axis (X, Y, Z) or tracker (FHST1, FHST2).
    pub axis: &'static str,
    /// Samples (all folds).
    pub samples: usize,
    /// Whole data: [value, low, high] when detected.
    pub whole: Option<[f64; 3]>,
    /// Fold A and fold B: value when detected.
    pub folds: [Option<f64>; 2],
    /// Why the whole data give no evidence although they were analysed, when so.
    pub note: Option<String>,
}
