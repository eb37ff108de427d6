//! Top-k rows: keep the k largest entries of a row, record the rest as dropped mass.
//!
//! The paper's future work proposed keeping the top 10–20 % of each row "renormalised
//! so no light is lost" (docs/architecture.md §1). Here the kept entries are stored unchanged
//! and `Row::dropped` holds the sum of the others, so the true row sum is
//! `stored + dropped` and a reader can redistribute it (scale the kept entries by
//! (stored + dropped) / stored) or not (see `formats/` and [`crate::rows`]).
//!
//! Ties are broken by the smaller column, so the kept set is a pure function of the
//! values (deterministic across threads and runs).

use std::cmp::Ordering;

use crate::rows::{Row, RowValues};

/// Builds the row from f64 values: of the positive entries ≥ `eps` (0: every positive
/// entry), all if there are at most `k`, else the `k` largest (columns ascending); the
/// rest summed into `dropped`. `order` is scratch space.
pub(crate) fn top_k_row(
    index: u32,
    values: &[f64],
    k: usize,
    eps: f64,
    order: &mut Vec<u32>,
) -> Row {
    order.clear();
    order.extend((0..values.len() as u32).filter(|&j| values[j as usize] > 0.0));
    let mut dropped = 0.0f64;
    if eps > 0.0 {
        // Below the threshold, in column order, then the top-k selection among the rest.
        dropped = order
            .iter()
            .map(|&j| values[j as usize])
            .filter(|&v| v < eps)
            .sum();
        order.retain(|&j| values[j as usize] >= eps);
    }
    if order.len() > k {
        let by_value_desc = |a: &u32, b: &u32| -> Ordering {
            values[*b as usize]
                .total_cmp(&values[*a as usize])
                .then(a.cmp(b))
        };
        if k > 0 {
            order.select_nth_unstable_by(k - 1, by_value_desc);
        }
        let (_, rest) = order.split_at_mut(k);
        rest.sort_unstable();
        dropped += rest.iter().map(|&j| values[j as usize]).sum::<f64>();
        order.truncate(k);
    }
    order.sort_unstable();
    let cols = order.clone();
    let vals = cols.iter().map(|&j| values[j as usize] as f32).collect();
    Row {
        index,
        values: RowValues::Sparse { cols, vals },
        dropped: dropped as f32,
        links: Vec::new(),
        link_error: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_largest_and_records_dropped() {
        let v = [0.1, 0.0, 0.3, 0.2, 0.3, 0.05];
        let mut order = Vec::new();
        let r = top_k_row(4, &v, 2, 0.0, &mut order);
        // 0.3 at columns 2 and 4 are the two largest.
        assert_eq!(
            r.values,
            RowValues::Sparse {
                cols: vec![2, 4],
                vals: vec![0.3, 0.3]
            }
        );
        assert!((r.dropped as f64 - 0.35).abs() < 1e-7);
        let total: f64 = v.iter().sum();
        assert!((r.true_sum() - total).abs() < 1e-6);
    }

    #[test]
    fn ties_break_by_column() {
        let v = [0.2, 0.2, 0.2, 0.2];
        let r = top_k_row(0, &v, 3, 0.0, &mut Vec::new());
        assert_eq!(
            r.values,
            RowValues::Sparse {
                cols: vec![0, 1, 2],
                vals: vec![0.2; 3]
            }
        );
    }

    #[test]
    fn short_rows_keep_all_positive() {
        let v = [0.0, 0.5, 0.0];
        let r = top_k_row(0, &v, 3, 0.0, &mut Vec::new());
        assert_eq!(
            r.values,
            RowValues::Sparse {
                cols: vec![1],
                vals: vec![0.5]
            }
        );
        assert_eq!(r.dropped, 0.0);
    }

    #[test]
    fn a_threshold_keeps_the_entries_at_or_above_it() {
        let v = [0.1, 0.0, 0.3, 0.2, 0.3, 0.05];
        // Alone (k = every column): 0.1, 0.2, 0.3, 0.3 kept; 0.05 dropped.
        let r = top_k_row(0, &v, v.len(), 0.1, &mut Vec::new());
        assert_eq!(
            r.values,
            RowValues::Sparse {
                cols: vec![0, 2, 3, 4],
                vals: vec![0.1, 0.3, 0.2, 0.3]
            }
        );
        assert!((f64::from(r.dropped) - 0.05).abs() < 1e-8);
        // With k = 3: the three largest of those; 0.1 joins the dropped mass.
        let r = top_k_row(0, &v, 3, 0.1, &mut Vec::new());
        assert_eq!(
            r.values,
            RowValues::Sparse {
                cols: vec![2, 3, 4],
                vals: vec![0.3, 0.2, 0.3]
            }
        );
        assert!((f64::from(r.dropped) - 0.15).abs() < 1e-8);
    }
}
