//! The thesis's comparison models on a simulated data set (ch. 5): NARX networks with
//! tapped delays from the correlation-based suggestion (and, where the thesis used it, a
//! fixed larger order), and a linear output-error model initialised from the physics model
//! with the thesis's free parameters. Each is simulated free-run on the training and test
//! recipes.

use anyhow::{Context, Result};
use mmenn::sysid_baselines::{
    NarxConfig, NarxOrders, NetworkChoice, OeConfig, OeModel, SuggestionConfig, fit_narx, fit_oe,
    suggest_lags,
};
use mmenn::sysid_core::{LinearModel, Model, ModelNames};
use nalgebra::DMatrix;

use crate::data::DataSet;
use crate::experiments::{Ctx, FIT_SEED, Mode};

/// A model's free-run states (rows = all states, NaN rows where it has no estimate) on the
/// training and test record, or why it has none.
pub type Trajectories = [(DMatrix<f64>, Option<String>); 2];

/// Starting point of the output-error fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OeStart {
    /// The data set's assumed (physics) model.
    Assumed,
    /// The double pendulum's physics linearisation about the hanging equilibrium (its
    /// ignorance model has A = 0 and B = 0, where the input has no effect on the outputs
    /// and the free parameters cannot be identified).
    DoublePendulumLinearised,
}

/// One comparison model's free-run states.
#[derive(Debug)]
pub struct BaselineRun {
    /// Row label (`NARX (na = 6, nb = 6)`, `linear OE`).
    pub label: String,
    /// States on the training and test recipes (NaN rows for states it does not predict).
    pub trajectories: Trajectories,
    /// Notes for the table (lags, fitted parameters, failures).
    pub notes: Vec<String>,
}

fn nan_states(set: &DataSet, record: usize) -> DMatrix<f64> {
    let rec = if record == 0 {
        &set.train
    } else {
        set.test.as_ref().unwrap_or(&set.train)
    };
    let t = &rec.sim.truth.states;
    DMatrix::from_element(t.nrows(), t.ncols(), f64::NAN)
}

/// NARX network size by mode: hidden units and initialisations.
fn narx_network(mode: Mode) -> NetworkChoice {
    match mode {
        Mode::Quick => NetworkChoice::Hidden {
            units: 3,
            restarts: 2,
        },
        Mode::Full => NetworkChoice::Hidden {
            units: 5,
            restarts: 5,
        },
    }
}

fn narx(ctx: &Ctx, set: &DataSet, orders: NarxOrders, how: &str) -> BaselineRun {
    let label = format!("NARX ({how}: na = {}, nb = {})", orders.na, orders.nb);
    let config = NarxConfig {
        orders,
        network: narx_network(ctx.mode),
        seed: FIT_SEED,
        ..NarxConfig::default()
    };
    let mut notes = Vec::new();
    let mut traj: Trajectories = [(nan_states(set, 0), None), (nan_states(set, 1), None)];
    match fit_narx(&set.train.sim.data, &config) {
        Err(e) => {
            let why = format!("{label}: training failed: {e}");
            traj[0].1 = Some(why.clone());
            traj[1].1 = Some(why.clone());
            notes.push(why);
        }
        Ok(fit) => {
            let model = &set.train.sim.assumed.model;
            let records = [Some(&set.train), set.test.as_ref()];
            for (slot, rec) in traj.iter_mut().zip(records) {
                let Some(rec) = rec else { continue };
                match fit.model.simulate(&rec.sim.data.experiments()[0]) {
                    Ok(pred) => {
                        for (j, out) in fit.model.output_names().iter().enumerate() {
                            if let Ok(i) = model.state_index(out) {
                                slot.0.row_mut(i).copy_from(&pred.outputs.row(j));
                            }
                        }
                    }
                    Err(e) => {
                        let why = format!("{label}: free-run failed: {e}");
                        notes.push(why.clone());
                        slot.1 = Some(why);
                    }
                }
            }
            let r = &fit.restarts[fit.chosen];
            notes.push(format!(
                "{label}: {} hidden units, one-step training MSE {:.3e}, {} regressor rows.",
                r.hidden, r.train_mse, fit.rows
            ));
        }
    }
    BaselineRun {
        label,
        trajectories: traj,
        notes,
    }
}

fn oe(set: &DataSet, free: &[&str], start: OeStart) -> Result<BaselineRun> {
    let label = "linear OE".to_string();
    let assumed = match start {
        OeStart::Assumed => set.train.sim.assumed.model.clone(),
        OeStart::DoublePendulumLinearised => {
            mmenn::plants::DoublePendulum::new(mmenn::plants::DoublePendulumParams::default())?
                .linearised_model()?
        }
    };
    let assumed = &assumed;
    let config = OeConfig {
        free: free.iter().map(|s| s.to_string()).collect(),
        ..OeConfig::default()
    };
    let mut traj: Trajectories = [(nan_states(set, 0), None), (nan_states(set, 1), None)];
    let mut notes = Vec::new();
    match fit_oe(assumed, &set.train.sim.data, &config) {
        Err(e) => {
            let why = format!("linear OE: fit failed: {e}");
            traj[0].1 = Some(why.clone());
            traj[1].1 = Some(why.clone());
            notes.push(why);
        }
        Ok(fit) => {
            let m = &fit.model.model;
            let n = m.n_states();
            let names = ModelNames {
                states: m.state_names().to_vec(),
                inputs: m.input_names().to_vec(),
                outputs: m.state_names().to_vec(),
                corrections: m.correction_names().to_vec(),
            };
            let every_state = OeModel::new(
                LinearModel::with_names(
                    m.a().clone(),
                    m.b().clone(),
                    DMatrix::identity(n, n),
                    m.e().clone(),
                    names,
                )
                .context("the fitted OE model with C = I")?,
            );
            let records = [Some(&set.train), set.test.as_ref()];
            for (slot, rec) in traj.iter_mut().zip(records) {
                let Some(rec) = rec else { continue };
                match every_state.simulate_from(&rec.sim.data.experiments()[0], &rec.x0()) {
                    Ok(p) => slot.0 = p.outputs,
                    Err(e) => {
                        let why = format!("linear OE: free-run failed: {e}");
                        notes.push(why.clone());
                        slot.1 = Some(why);
                    }
                }
            }
            let params: Vec<String> = fit
                .parameters
                .iter()
                .map(|p| {
                    format!(
                        "{} = {:.4} ± {:.2e} (from {:.4})",
                        p.name, p.value, p.std, p.initial
                    )
                })
                .collect();
            notes.push(format!(
                "linear OE: free parameters fitted by free-run error, initialised from the physics model: {}; stability {:?}.",
                params.join(", "),
                fit.stability.verdict
            ));
        }
    }
    Ok(BaselineRun {
        label,
        trajectories: traj,
        notes,
    })
}

/// NARX with the suggested lags, NARX with `extra_lags` delays (when given and different),
/// and the output-error model with `oe_free` free entries.
pub fn run_all(
    ctx: &Ctx,
    set: &DataSet,
    oe_free: &[&str],
    oe_start: OeStart,
    extra_lags: Option<usize>,
) -> Result<Vec<BaselineRun>> {
    let data = &set.train.sim.data;
    let suggestion = suggest_lags(data, &SuggestionConfig::default())
        .with_context(|| format!("NARX lag suggestion on {}", set.spec.name))?;
    let mut runs = vec![narx(ctx, set, suggestion.orders, "suggested")];
    if let Some(l) = extra_lags
        && (l != suggestion.orders.na || l != suggestion.orders.nb)
    {
        runs.push(narx(ctx, set, NarxOrders::symmetric(l), "thesis order"));
    }
    runs.push(oe(set, oe_free, oe_start)?);
    Ok(runs)
}
