//! The choices of `mmenn fit` that the command line names: the network size, how the
//! networks are trained, how one is picked from the sweep, and whether the assumed model
//! is updated first; each parses from its command-line spelling.

use serde::Serialize;

/// How many hidden units the network gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HiddenChoice {
    /// The sizing sweep (thesis §3.1: 1–10 units × 10 initialisations) picks.
    #[default]
    Auto,
    /// This many units (still the best of several initialisations).
    Fixed(usize),
}

impl std::str::FromStr for HiddenChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        match s.parse::<usize>() {
            Ok(n) if n > 0 => Ok(Self::Fixed(n)),
            _ => Err(format!("'{s}' is neither \"auto\" nor a positive integer")),
        }
    }
}

/// How the sweep trains its networks on `d̂`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Training {
    /// MATLAB `trainlm`'s Levenberg–Marquardt (the thesis procedure; the default).
    #[default]
    Trainlm,
    /// `trainlm` for 10 steps, then the gain-ratio schedule with geodesic acceleration
    /// (`nn::Damping::TrainlmThenGainRatio` + `nn::Acceleration::Geodesic`), measured
    /// against MINPACK as faster and reaching lower minima (the `nn` crate README).
    Accelerated,
}

impl std::str::FromStr for Training {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "trainlm" => Ok(Self::Trainlm),
            "accelerated" => Ok(Self::Accelerated),
            _ => Err(format!("'{s}' is neither \"trainlm\" nor \"accelerated\"")),
        }
    }
}

impl std::str::FromStr for NetworkSelection {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "d-mse" => Ok(Self::CorrectionMse),
            "free-run" => Ok(Self::FreeRun),
            _ => Err(format!("'{s}' is neither \"d-mse\" nor \"free-run\"")),
        }
    }
}

/// How `fit` picks the network among the sweep's trained networks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NetworkSelection {
    /// The sweep's rule on the test MSE of `d` (thesis §3.1).
    #[default]
    CorrectionMse,
    /// The network whose hybrid model has the smallest free-run output error on the
    /// training record (what the model is for; thesis §7.1 suggests judging the network by
    /// the state predictions). Diverging candidates are skipped.
    FreeRun,
}

impl std::str::FromStr for ModelUpdateChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "none" => Ok(Self::None),
            "regression" => Ok(Self::Regression),
            _ => Err(format!("'{s}' is neither \"none\" nor \"regression\"")),
        }
    }
}

/// Whether `fit` first updates the assumed model by regressing `d̂` on `[x̂, u]`
/// (thesis §4.3.3: ignorance model → updated model), then reruns MME with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ModelUpdateChoice {
    /// Use the assumed model as given.
    #[default]
    None,
    /// Regression update of the corrected rows of A and B, then MME again.
    Regression,
}

impl std::str::FromStr for NetworkEnsemble {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "single" => Ok(Self::Single),
            "band" => Ok(Self::Band),
            _ => Err(format!("'{s}' is neither \"single\" nor \"band\"")),
        }
    }
}

/// Whether `fit` keeps one network of the sweep or averages the equally good ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NetworkEnsemble {
    /// The one network [`NetworkSelection`] picks (the thesis procedure; the default).
    #[default]
    Single,
    /// The mean of every sweep network inside the sizing rule's band of the best test MSE
    /// of `d̂` (`nn::ensemble`): bagging over initialisations and sizes, merged exactly into
    /// one wider network, so `model.json` still holds one network. It lowers the variance
    /// a single restart carries on short records.
    Band,
}

impl std::str::FromStr for NetworkInputs {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "states-and-inputs" => Ok(Self::StatesAndInputs),
            "states" => Ok(Self::States),
            _ => Err(format!(
                "'{s}' is neither \"states-and-inputs\" nor \"states\""
            )),
        }
    }
}

/// What the network reads: `(x̂, u)` (the thesis) or the states `x̂` alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NetworkInputs {
    /// The states and the model's inputs (thesis ch. 4; the default).
    #[default]
    StatesAndInputs,
    /// The states alone: for an assumed model that already carries the input's path (a
    /// calibrated drive gain), the missing effect is a function of the state, and a record
    /// with a wider input than the training one cannot push the network outside the box
    /// of its training pairs. `model.json` records it through the network's input count.
    States,
}

impl std::str::FromStr for DomainPolicy {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "checked" => Ok(Self::Checked),
            "extrapolate" => Ok(Self::Extrapolate),
            "hold" => Ok(Self::Hold),
            _ => Err(format!(
                "'{s}' is neither \"checked\", \"extrapolate\" nor \"hold\""
            )),
        }
    }
}

impl std::fmt::Display for DomainPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Extrapolate => "extrapolate",
            Self::Hold => "hold",
            Self::Checked => "checked",
        })
    }
}

/// What the network does outside the box its training pairs spanned ([`nn::Domain`]), or
/// how `fit` decides it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DomainPolicy {
    /// [`nn::Domain::Extrapolate`] for every candidate, unchecked (the thesis method; the
    /// library's default, kept for the thesis experiments of `cargo xtask reproduce`).
    #[default]
    Extrapolate,
    /// [`nn::Domain::Hold`] for every candidate (`--network-domain hold`, or
    /// `--hold-network-domain`).
    Hold,
    /// [`nn::Domain::Extrapolate`] unless the guard's amplitude stress check fails a
    /// network candidate, which is then judged and kept with [`nn::Domain::Hold`]
    /// (`crate::fit::guard`'s `check_domains`; the command line's default). The held-out
    /// data never leave the training box by much, so they cannot show a network that
    /// explodes beyond it; the stress check runs each candidate on the held-out input
    /// scaled by [`STRESS_FACTOR`](crate::fit::STRESS_FACTOR) about its mean.
    Checked,
}

impl DomainPolicy {
    /// The domain the networks are selected, trained and first judged with: `Hold` for
    /// [`DomainPolicy::Hold`], otherwise `Extrapolate`.
    pub fn initial(self) -> nn::Domain {
        match self {
            Self::Hold => nn::Domain::Hold,
            Self::Extrapolate | Self::Checked => nn::Domain::Extrapolate,
        }
    }
}

impl From<nn::Domain> for DomainPolicy {
    /// The fixed policy of one domain.
    fn from(d: nn::Domain) -> Self {
        match d {
            nn::Domain::Extrapolate => Self::Extrapolate,
            nn::Domain::Hold => Self::Hold,
        }
    }
}

/// What the validation records (`--val`) are for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ValidationUse {
    /// Scoring only (the default, as a validation set is in MATLAB's `compare`): every
    /// choice of the fit (the sweep's test set, trajectory training's early stopping, the
    /// guard) is made on the training records as without validation data, and the
    /// validation fit is an independent number.
    #[default]
    Score,
    /// Also for choosing: the sweep's test set is MME on the validation records, the
    /// trajectory training stops early on them and the guard judges its candidates on
    /// the first of them (the thesis's use of its validation data). The validation fit
    /// is then the score of the chosen model on the data it was chosen on: optimistic.
    Select,
}

impl std::str::FromStr for ValidationUse {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "score" => Ok(Self::Score),
            "select" => Ok(Self::Select),
            _ => Err(format!("'{s}' is neither \"score\" nor \"select\"")),
        }
    }
}

impl std::fmt::Display for ValidationUse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Score => "score",
            Self::Select => "select",
        })
    }
}
