//! # What the effect search returns: the evidence of each candidate, the iterations, the result
//!
//! Why a module of their own: the change-point scan ([`super::change_point`]) reads a search's
//! result (the accepted steps, the final residuals) and the search ([`super::search`]) calls
//! the scan; with the result types here, the scan depends on them and not on the search, and
//! the two import in one direction (search → change_point → search_result).

use super::fit::{Layout, PostFit, SubFit, Systems};
use super::structure::StructureTest;
use serde::Serialize;

/// The evidence for one candidate in one iteration.
#[derive(Clone, Debug, Serialize)]
pub struct Evidence {
    /// Candidate label.
    pub effect: String,
    /// Linear parameters.
    pub k: usize,
    /// χ² reduction (σ rescaled to the measured noise floor).
    pub delta_chi2: f64,
    /// F statistic of the likelihood-ratio test.
    pub f: f64,
    /// p-value of the LR (F) test.
    pub p_value: f64,
    /// Holm-adjusted over the candidates of the iteration.
    pub p_holm: f64,
    /// BIC improvement (> 0 favours the candidate).
    pub delta_bic: f64,
    /// χ² of the difference between the halves' estimates.
    pub halves_chi2: f64,
    /// Its p-value.
    pub halves_p: f64,
    /// Estimates from the first and second halves.
    pub halves_estimates: (Vec<f64>, Vec<f64>),
    /// Signature structure before/after (max F excess over the signature tests).
    pub signature_excess: (f64, f64),
    /// The adequacy check passed.
    pub adequate: bool,
    /// Added to the model.
    pub accepted: bool,
    /// Why not, if rejected.
    pub rejected_because: Option<String>,
}

impl Evidence {
    /// A candidate's likelihood-ratio test: Δχ², F and p, ΔBIC, and the halves (χ², p,
    /// estimates). Holm's p is 1 until the family's correction; no signature test; not yet
    /// judged adequate, accepted or rejected.
    pub(crate) fn likelihood_test(
        effect: String,
        k: usize,
        (delta_chi2, f, p_value): (f64, f64, f64),
        delta_bic: f64,
        (halves_chi2, halves_p, halves_estimates): (f64, f64, (Vec<f64>, Vec<f64>)),
    ) -> Self {
        Self {
            effect,
            k,
            delta_chi2,
            f,
            p_value,
            p_holm: 1.0,
            delta_bic,
            halves_chi2,
            halves_p,
            halves_estimates,
            signature_excess: (f64::NAN, f64::NAN),
            adequate: false,
            accepted: false,
            rejected_because: None,
        }
    }

    /// Evidence of an effect whose own fit failed (singular sub-model).
    pub(super) fn placeholder(effect: String) -> Self {
        Self {
            effect,
            k: 0,
            delta_chi2: f64::NAN,
            f: f64::NAN,
            p_value: f64::NAN,
            p_holm: f64::NAN,
            delta_bic: f64::NAN,
            halves_chi2: f64::NAN,
            halves_p: f64::NAN,
            halves_estimates: (Vec::new(), Vec::new()),
            signature_excess: (f64::NAN, f64::NAN),
            adequate: false,
            accepted: true,
            rejected_because: None,
        }
    }
}

/// One iteration of the loop.
#[derive(Clone, Debug, Serialize)]
pub struct Iteration {
    /// Iteration number (1-based).
    pub number: usize,
    /// Effect added (None: the loop stopped).
    pub added: Option<String>,
    /// Evidence of every candidate tried.
    pub candidates: Vec<Evidence>,
}

/// Result of the search.
#[derive(Clone, Debug)]
pub struct SearchResult {
    /// Layout (alignments + library).
    pub layout: Layout,
    /// Declared effects in the model from the start (effect indices).
    pub baseline: Vec<usize>,
    /// Effects added, in order.
    pub added: Vec<usize>,
    /// Fit of the baseline model (calibration chain + declared effects).
    pub baseline_fit: SubFit,
    /// Final fit.
    pub final_fit: SubFit,
    /// Post-fit residuals of the baseline.
    pub before: PostFit,
    /// Post-fit residuals of the final model.
    pub after: PostFit,
    /// Iterations.
    pub iterations: Vec<Iteration>,
    /// Structure tests of the baseline residuals.
    pub tests_before: Vec<StructureTest>,
    /// Structure tests of the final residuals.
    pub tests_after: Vec<StructureTest>,
    /// Final evidence of each added effect (from the iteration that added it).
    pub evidence: Vec<Evidence>,
    /// The systems (for the halves of the final model).
    pub systems: Systems,
    /// Parameters fixed from outside the batch systems: the time tags, absolute against
    /// the gyro ([`super::time_reference`]); fits of the model keep them.
    pub fixed: Vec<super::fit::Fixed>,
}
