//! A stated budget for long jobs: wall-clock seconds (what a user sets, `--budget`) or
//! work units (deterministic, for tests: a unit is one integration sub-step of the
//! charging loop). Long loops charge their work as they go; once the budget is spent the
//! next charge returns [`BudgetExhausted`], naming the stage that ran out and how far it
//! got, so a job stops with a typed error instead of running on. Clones share one account,
//! so the parts of one job (a W search and the sweeps inside it) draw on the same budget.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;

/// What a budget is counted in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BudgetLimit {
    /// Wall-clock seconds from the budget's creation.
    Seconds(f64),
    /// Work units (integration sub-steps charged by the loops).
    WorkUnits(u64),
}

impl std::fmt::Display for BudgetLimit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BudgetLimit::Seconds(s) => write!(f, "{s} s"),
            BudgetLimit::WorkUnits(u) => write!(f, "{u} work units"),
        }
    }
}

/// The budget ran out: which stage was running and how far it had got.
#[derive(Debug, Clone, PartialEq, Error)]
#[error(
    "the budget of {limit} ran out during {stage} ({}; {used} work units used)",
    progress_words(*.done, *.total)
)]
pub struct BudgetExhausted {
    /// The budget.
    pub limit: BudgetLimit,
    /// The stage that was running (e.g. "nonlinear MME iteration").
    pub stage: &'static str,
    /// Steps of that stage completed.
    pub done: usize,
    /// Steps of that stage planned, when known.
    pub total: Option<usize>,
    /// Work units charged so far (all stages).
    pub used: u64,
}

fn progress_words(done: usize, total: Option<usize>) -> String {
    match total {
        Some(t) => format!("{done} of {t} done"),
        None => format!("{done} done"),
    }
}

#[derive(Debug)]
struct Account {
    limit: BudgetLimit,
    deadline: Option<Instant>,
    used: AtomicU64,
}

/// A budget shared by the parts of one job (see the module doc). The default is
/// unlimited.
#[derive(Debug, Clone, Default)]
pub struct Budget {
    account: Option<Arc<Account>>,
}

impl PartialEq for Budget {
    /// Budgets are equal when their limits are (the time already spent is not compared).
    fn eq(&self, other: &Self) -> bool {
        self.limit() == other.limit()
    }
}

impl Budget {
    /// No limit: every charge succeeds.
    pub fn unlimited() -> Self {
        Self::default()
    }

    /// At most `seconds` of wall-clock time from now. `None` when `seconds` is negative or
    /// not finite.
    pub fn seconds(seconds: f64) -> Option<Self> {
        if !(seconds.is_finite() && seconds >= 0.0) {
            return None;
        }
        let deadline = Instant::now().checked_add(Duration::from_secs_f64(seconds));
        Some(Self::with(BudgetLimit::Seconds(seconds), deadline))
    }

    /// At most `units` work units (deterministic: the same job runs out at the same point
    /// on any machine).
    pub fn work_units(units: u64) -> Self {
        Self::with(BudgetLimit::WorkUnits(units), None)
    }

    fn with(limit: BudgetLimit, deadline: Option<Instant>) -> Self {
        Self {
            account: Some(Arc::new(Account {
                limit,
                deadline,
                used: AtomicU64::new(0),
            })),
        }
    }

    /// The limit, `None` when unlimited.
    pub fn limit(&self) -> Option<BudgetLimit> {
        self.account.as_ref().map(|a| a.limit)
    }

    /// Work units charged so far.
    pub fn used(&self) -> u64 {
        self.account
            .as_ref()
            .map_or(0, |a| a.used.load(Ordering::Relaxed))
    }

    /// Charge `units` of work done by `stage` (`done` of `total` steps completed so far)
    /// and say whether the budget still holds: an error when the work units now exceed
    /// the limit or the deadline has passed.
    pub fn charge(
        &self,
        units: u64,
        stage: &'static str,
        done: usize,
        total: Option<usize>,
    ) -> Result<(), BudgetExhausted> {
        let Some(account) = &self.account else {
            return Ok(());
        };
        let used = account.used.fetch_add(units, Ordering::Relaxed) + units;
        let out = match account.limit {
            BudgetLimit::WorkUnits(max) => used > max,
            BudgetLimit::Seconds(_) => account.deadline.is_some_and(|d| Instant::now() >= d),
        };
        if out {
            Err(BudgetExhausted {
                limit: account.limit,
                stage,
                done,
                total,
                used,
            })
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_units_run_out_exactly_past_the_limit_and_clones_share_the_account() {
        let b = Budget::work_units(10);
        let c = b.clone();
        assert!(b.charge(6, "a", 1, Some(3)).is_ok());
        assert!(c.charge(4, "a", 2, Some(3)).is_ok());
        assert_eq!(b.used(), 10);
        let err = c.charge(1, "stage b", 2, Some(3)).unwrap_err();
        assert_eq!(
            err,
            BudgetExhausted {
                limit: BudgetLimit::WorkUnits(10),
                stage: "stage b",
                done: 2,
                total: Some(3),
                used: 11,
            }
        );
        let text = err.to_string();
        assert!(
            text.contains("stage b") && text.contains("2 of 3 done"),
            "{text}"
        );
        assert!(Budget::unlimited().charge(u64::MAX, "x", 0, None).is_ok());
    }

    #[test]
    fn a_zero_second_budget_is_spent_at_once_and_bad_seconds_are_refused() {
        let b = Budget::seconds(0.0).unwrap();
        assert!(matches!(
            b.charge(0, "s", 0, None),
            Err(BudgetExhausted {
                limit: BudgetLimit::Seconds(_),
                ..
            })
        ));
        assert!(Budget::seconds(f64::NAN).is_none());
        assert!(Budget::seconds(-1.0).is_none());
        assert!(
            Budget::seconds(1e6)
                .unwrap()
                .charge(1, "s", 0, None)
                .is_ok()
        );
    }
}
