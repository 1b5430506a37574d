//! What judges a round's model (the protocol of its free-run search), kept for the
//! verdict's bootstrap judge, and the fixed bound of a claim when that judge cannot run.

use sysid_core::{Dataset, TermModel};

use crate::CalibrationConfig;
use crate::judge::{BootstrapJudgement, JudgeConfig, Protocol};
use crate::refine::RefineConfig;

/// The free-run cost on `measured` judged values below which named effects are claimed
/// when the bootstrap judge cannot run. With `R` given, a right model must reach the
/// noise level itself: `J ≤ 1 + 3√(2/M)` (`M·J` is χ²_M, standard deviation `√(2M)`).
/// With `R` estimated, [`super::CONFIRM_COST`].
pub fn claim_bound(noise_given: bool, measured: usize) -> f64 {
    if noise_given {
        noise_level_bound(measured)
    } else {
        super::CONFIRM_COST
    }
}

/// `1 + 3√(2/M)`: the largest free-run cost of a right model on `M` values (3σ).
pub(super) fn noise_level_bound(measured: usize) -> f64 {
    1.0 + 3.0 * (2.0 / measured.max(1) as f64).sqrt()
}

/// What judges a round's model: the records and initial-state guesses of its free-run
/// search, the model as calibrated on the calibration records only (before any
/// recalibration on the whole records), the indices of the terms the round calibrated,
/// and the noise variance of the judged cost.
#[derive(Debug, Clone)]
pub(super) struct JudgeContext {
    pub(super) model: TermModel,
    pub(super) new_terms: Vec<usize>,
    pub(super) cal: Dataset,
    pub(super) cal_x0: Vec<Vec<f64>>,
    pub(super) hold: Option<(Dataset, Vec<Vec<f64>>)>,
    pub(super) noise_variance: Vec<f64>,
}

impl JudgeContext {
    /// Its judging protocol, with the free-run search's calibration settings.
    pub(super) fn protocol<'a>(&'a self, calibration: &'a CalibrationConfig) -> Protocol<'a> {
        Protocol {
            cal: &self.cal,
            cal_x0: &self.cal_x0,
            hold: self.hold.as_ref().map(|(d, x)| (d, x.as_slice())),
            noise_variance: &self.noise_variance,
            calibration,
        }
    }

    /// Judge its model by the protocol against the protocol's bootstrap reference.
    pub(super) fn judge(&self, seed: u64) -> crate::Result<BootstrapJudgement> {
        let calibration = RefineConfig::default().calibration;
        let protocol = self.protocol(&calibration);
        let config = JudgeConfig {
            seed,
            ..JudgeConfig::default()
        };
        crate::judge(&self.model, &self.new_terms, &protocol, &config)
    }
}
