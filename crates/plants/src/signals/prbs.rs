//! Maximum-length pseudo-random binary sequences from a Fibonacci LFSR, with period and
//! balance checked for every supported register length.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use super::{SampleGrid, check_finite};
use crate::error::{PlantError, Result};

/// Lowest supported PRBS register length.
pub const PRBS_MIN_ORDER: u32 = 2;
/// Highest supported PRBS register length.
pub const PRBS_MAX_ORDER: u32 = 24;

/// Feedback taps (exponents of a primitive polynomial `x^n + … + 1`) per register length,
/// from the standard maximal-length tables (Xilinx XAPP052); each is checked by the
/// period test below.
const PRBS_TAPS: [&[u32]; 23] = [
    &[2, 1],
    &[3, 2],
    &[4, 3],
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 6, 4, 1],
    &[13, 4, 3, 1],
    &[14, 5, 3, 1],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 6, 2, 1],
    &[20, 17],
    &[21, 19],
    &[22, 21],
    &[23, 18],
    &[24, 23, 22, 17],
];

/// Maximum-length PRBS from an `order`-bit Fibonacci LFSR: period `2^order − 1` clocks,
/// `2^(order−1)` ones and `2^(order−1) − 1` zeros per period. Each bit is held for `hold`
/// samples and mapped to `high` (1) or `low` (0). The nonzero initial register is drawn
/// from `seed` (a cyclic shift of the same sequence).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prbs {
    /// Register length, `PRBS_MIN_ORDER..=PRBS_MAX_ORDER`.
    pub order: u32,
    /// Samples per bit (≥ 1).
    pub hold: usize,
    /// Level of a 0 bit.
    pub low: f64,
    /// Level of a 1 bit.
    pub high: f64,
    /// Seed of the initial register.
    pub seed: u64,
}

impl Default for Prbs {
    fn default() -> Self {
        Self {
            order: 10,
            hold: 1,
            low: -1.0,
            high: 1.0,
            seed: 1,
        }
    }
}

impl Prbs {
    /// The raw bit sequence (0/1), `len` clocks long.
    pub fn bits(&self, len: usize) -> Result<Vec<u8>> {
        if !(PRBS_MIN_ORDER..=PRBS_MAX_ORDER).contains(&self.order) {
            return Err(PlantError::InvalidSignal {
                signal: "prbs",
                field: "order",
                value: f64::from(self.order),
                reason: "register length must lie in 2..=24",
            });
        }
        let n = self.order;
        let taps = PRBS_TAPS[(n - PRBS_MIN_ORDER) as usize];
        // Tap exponent t feeds back from register bit n − t (bit 0 is shifted out).
        let mask: u32 = taps.iter().fold(0, |m, &t| m | (1 << (n - t)));
        let full = (1u32 << n) - 1;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut state: u32 = rng.random_range(1..=full);
        let mut out = Vec::with_capacity(len);
        for _ in 0..len {
            out.push((state & 1) as u8);
            let fb = (state & mask).count_ones() & 1;
            state = (state >> 1) | (fb << (n - 1));
        }
        Ok(out)
    }

    /// Period of the sequence in clocks, `2^order − 1`.
    pub fn period(&self) -> usize {
        (1usize << self.order.min(63)) - 1
    }

    pub(super) fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        check_finite("prbs", "low", self.low)?;
        check_finite("prbs", "high", self.high)?;
        if self.hold == 0 {
            return Err(PlantError::InvalidSignal {
                signal: "prbs",
                field: "hold",
                value: 0.0,
                reason: "must hold each bit for at least one sample",
            });
        }
        let clocks = grid.len.div_ceil(self.hold);
        let bits = self.bits(clocks)?;
        Ok((0..grid.len)
            .map(|k| {
                if bits[k / self.hold] == 1 {
                    self.high
                } else {
                    self.low
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(dt: f64, len: usize) -> SampleGrid {
        SampleGrid { t0: 0.0, dt, len }
    }

    /// Every supported register length gives the maximal period `2^n − 1` (the register
    /// first returns to its start state after exactly that many clocks, checked by
    /// brute force on the output: the sequence repeats with that period and with no
    /// shorter divisor period) and the maximal-length balance of ones and zeros.
    #[test]
    fn prbs_has_maximal_period_and_balance() {
        for order in PRBS_MIN_ORDER..=PRBS_MAX_ORDER {
            let p = Prbs {
                order,
                seed: u64::from(order),
                ..Prbs::default()
            };
            let period = p.period();
            let bits = p.bits(period + order as usize).unwrap();
            // Repeats after `period` clocks: the n-bit window at 0 recurs at `period`.
            assert_eq!(
                &bits[..order as usize],
                &bits[period..period + order as usize],
                "order {order}"
            );
            // A maximal LFSR visits every nonzero n-bit window once per period, so no
            // window repeats inside the period (no shorter period exists).
            let n = order as usize;
            let mut seen = vec![false; period + 1];
            let mut w = (0..n).fold(0usize, |acc, j| acc | (usize::from(bits[j]) << j));
            for k in 0..period {
                assert!(
                    w != 0 && !seen[w],
                    "order {order}: window repeats at clock {k}"
                );
                seen[w] = true;
                // Slide the window one clock: drop bit k, append bit k + n.
                w = (w >> 1) | (usize::from(bits[k + n]) << (n - 1));
            }
            let ones: usize = bits[..period].iter().map(|&b| usize::from(b)).sum();
            assert_eq!(ones, 1 << (order - 1), "order {order}");
            assert_eq!(period - ones, (1 << (order - 1)) - 1, "order {order}");
        }
    }

    #[test]
    fn prbs_holds_bits_and_maps_levels() {
        let p = Prbs {
            order: 5,
            hold: 3,
            low: 0.5,
            high: 2.0,
            seed: 9,
        };
        let x = p.sample(&grid(0.1, 31 * 3)).unwrap();
        let bits = p.bits(31).unwrap();
        for (k, v) in x.iter().enumerate() {
            let want = if bits[k / 3] == 1 { 2.0 } else { 0.5 };
            assert!((v - want).abs() < f64::EPSILON, "sample {k}");
        }
        let bad = Prbs {
            order: 30,
            ..Prbs::default()
        };
        assert!(matches!(
            bad.bits(4),
            Err(PlantError::InvalidSignal { field: "order", .. })
        ));
    }
}
