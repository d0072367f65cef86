//! Table 1 (DESIGN 3, paper 5.2): six per-expression networks against one unified network,
//! by test MSE. Per-expression network e: inputs = e's prototype AUs, outputs = the controls of
//! those AUs (`experiments/expression_aus.csv`, `experiments/au_muscles.csv`), trained and
//! tested on e's pairs only. Unified: 17 AUs -> 56 controls on all pairs; MSE_All over every
//! output of the whole test split, and restricted to each expression's test pairs and outputs
//! so the two can be compared like for like.

//!
//! The networks themselves (which there are, their pairs, the split and their test) are the
//! cell's, in `run::cell::networks`: every run that trains makes them, and Table 1 reports them.

use crate::run::cell::networks::Row;
use crate::stats;

mod report;
pub(crate) use report::{sweep_labels, Table1, Table1Rows};

/// Zeng et al. Table 1, in `ORDER` (`run::cell::networks::ORDER`), then MSE_All.
pub const PAPER: [f64; 7] = [
    0.000591, 0.002925, 0.001611, 0.009689, 0.000266, 0.002516, 0.000729,
];

/// Per expression, the paired difference across seeds: each seed's per-expression network's
/// MSE minus its unified network's on the same test pairs and outputs, as mean and 95%
/// interval half-width, and whether the interval excludes zero.
pub fn paired(rows: &[Row]) -> Vec<(f64, f64, bool)> {
    (0..6)
        .map(|k| {
            let d: Vec<f64> = rows
                .iter()
                .map(|r| r.per_expression[k] - r.unified_restricted[k])
                .collect();
            let (m, c) = (stats::mean(&d), stats::ci95(&d));
            (m, c, d.len() > 1 && m.abs() > c)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paired_difference_is_per_seed_and_says_when_it_excludes_zero() {
        let row = |seed: u64, joy: f64, unified_joy: f64| Row {
            seed,
            per_expression: [joy, 1.0, 1.0, 1.0, 1.0, 1.0],
            all: 0.0,
            unified_restricted: [unified_joy, 1.0, 2.0 + seed as f64, 1.0, 1.0, 1.0],
        };
        // Joy: the per-expression network is 1.0 worse on every seed, a difference the
        // seeds agree on however large the spread of each column.
        let rows = [row(1, 2.0, 1.0), row(2, 11.0, 10.0), row(3, 6.0, 5.0)];
        let p = paired(&rows);
        assert!((p[0].0 - 1.0).abs() < 1e-12 && p[0].1 < 1e-12 && p[0].2);
        // Sadness: no difference, no mark.
        assert_eq!(p[1], (0.0, 0.0, false));
        // Fear: differences -2, -3, -4 (mean -3, interval 2.48).
        assert!((p[2].0 + 3.0).abs() < 1e-12 && p[2].2);
        // One seed: no interval, no claim.
        assert!(!paired(&rows[..1])[0].2);
    }
}
