//! The pool of light that top-k rows do not carry ([`super::DroppedMass::Pool`]).
//!
//! A top-k row i keeps its k largest entries and records their sum and the dropped
//! mass D_i: the row's true sum is R_i = stored_i + D_i. Used as stored, the kept
//! entries lose the dropped light. Scaling each row up to R_i (`rowview.rs`) makes the
//! row sum right but not the columns: power leaving patch i that no kept entry carries
//! is still lost, and power that arrives is taken from the wrong senders (a wall whose
//! 64 largest entries are its neighbours gets none of the lamp's light, scaled up).
//!
//! The pool treats the missing part of the matrix as one rank-one term. In the
//! gathering form H_j = Σ_i F_ji B_i, what row j is missing gets
//!
//!   H_j = Σ_{i kept in row j} F_ji B_i + D_j β,   β = Σ_i s_i B_i / W,
//!
//! with W = Σ_j A_j D_j over the reflecting rows (the receivers the equation for B
//! needs) and s_i the power per unit radiosity that patch i sends but no kept entry of
//! a reflecting row carries:
//!
//!   s_i = max(0, A_i (R_i − K_i) − Σ_{j reflecting} A_j F_ji),
//!
//! K_i the stored part of row i that goes to patches that reflect nothing (their
//! irradiance comes by reciprocity from row i itself, `check.rs`). So the light patch i
//! emits or reflects is carried in full, A_i R_i B_i, by the kept entries and the pool,
//! and the pool hands out exactly what it takes in (Σ_j A_j D_j β = Σ_i s_i B_i): a
//! closed scene whose rows sum to 1 conserves power whatever k is. The light is shared
//! among receivers in proportion to what each one's row says it cannot see in its kept
//! entries; that is the ambient term of progressive radiosity (Cohen, Chen, Wallace and
//! Greenberg, SIGGRAPH 1988, §4) with the unknown part of each row, rather than the
//! whole unshot power, as its weight. It places the dropped light on the right
//! receivers on average, not per pair: entries that matter to one receiver should be
//! kept (a larger k).
//!
//! Shooting uses rows the other way round (row i of a shooter i says what it sends),
//! so the roles swap: a shot from patch i sends what its own row dropped, A_i D_i ΔB_i,
//! into the pool, and the pool, shot like a patch when its unshot power is the largest,
//! gives each reflecting receiver j the share u_j / U of what it holds, with u_j the
//! light j lacks from the kept entries of the rows that shoot at it:
//!
//!   u_j = max(0, A_j R_j − Σ_i A_i F_ij),   U = Σ_j u_j (reflecting j).
//!
//! Both forms are exact where the form factors are uniform (F_ij = A_j / A_total, the
//! inside of a sphere) whatever the rows keep, which a test checks.
//!
//! An emitting patch without a stored row has no known R_i: its light is carried by
//! the kept entries of the other rows only and the solve says so
//! ([`Pool::senders_without_rows`]).

/// What one scan of the rows measures for the pool ([`Pool::from_scan`]), per patch.
#[derive(Debug)]
pub(crate) struct PoolScan {
    /// Σ over reflecting rows r of A_r F_rx, per column x.
    pub(crate) carried: Vec<f64>,
    /// Σ over every row read of A_r F_rx, per column x.
    pub(crate) shot_at: Vec<f64>,
    /// A_r (stored + dropped − to non-reflecting patches) per row read, `None` for a
    /// row not read.
    pub(crate) total: Vec<Option<f64>>,
    /// W = Σ_j A_j D_j over reflecting rows.
    pub(crate) weight: f64,
}

/// The pool's weights, measured in one scan of the rows.
#[derive(Clone, Debug, Default)]
pub(crate) struct Pool {
    /// s_i (module docs): what patch i puts into the pool per unit radiosity.
    send: Vec<f64>,
    /// W = Σ_j A_j D_j over reflecting rows.
    pub(crate) weight: f64,
    /// u_j / U (module docs) for reflecting rows j, 0 for other patches (shooting).
    pub(crate) shoot_share: Vec<f64>,
    /// Emitting patches without a stored row: (first, count).
    pub(crate) senders_without_rows: Option<(u32, usize)>,
}

impl Pool {
    /// The pool from what one scan of the rows measured ([`PoolScan`]); `reflects`
    /// per patch, `missing` the emitting patches without a stored row.
    pub(crate) fn from_scan(
        scan: PoolScan,
        reflects: &[bool],
        missing: Option<(u32, usize)>,
    ) -> Self {
        let PoolScan {
            carried,
            shot_at,
            total,
            weight,
        } = scan;
        let n = total.len();
        let send = (0..n)
            .map(|i| total[i].map_or(0.0, |t| (t - carried[i]).max(0.0)))
            .collect();
        let mut shoot_share: Vec<f64> = (0..n)
            .map(|j| match total[j] {
                Some(t) if reflects[j] => (t - shot_at[j]).max(0.0),
                _ => 0.0,
            })
            .collect();
        let u: f64 = shoot_share.iter().sum();
        for s in &mut shoot_share {
            *s = if u > 0.0 { *s / u } else { 0.0 };
        }
        Pool {
            send,
            weight,
            shoot_share,
            senders_without_rows: missing,
        }
    }

    /// β per column for radiosity `b` (`n × m`): Σ_i s_i B_i / W (0 when W = 0: no
    /// reflecting row dropped anything).
    pub(crate) fn beta(&self, b: &[f64], m: usize) -> Vec<f64> {
        let mut beta = vec![0.0; m];
        if self.weight <= 0.0 {
            return beta;
        }
        for (s, bi) in self.send.iter().zip(b.chunks_exact(m)) {
            if *s != 0.0 {
                for (o, x) in beta.iter_mut().zip(bi) {
                    *o += s * x;
                }
            }
        }
        for o in &mut beta {
            *o /= self.weight;
        }
        beta
    }

    /// s_i / W for patch i (0 when W = 0): the transpose of the pool's term, for the
    /// adjoint solve.
    pub(crate) fn send_share(&self, i: usize) -> f64 {
        if self.weight > 0.0 {
            self.send[i] / self.weight
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::rows::{Row, RowValues};
    use crate::solve::system::System;
    use crate::solve::{DroppedMass, MemoryRows};
    use glam::DVec3;

    /// Three unit-area reflecting patches; rows keep one entry each and drop the rest of
    /// a row sum of 1.
    fn three() -> (System, MemoryRows) {
        let square = crate::patch::Patch {
            corners: [DVec3::ZERO, DVec3::X, DVec3::X + DVec3::Y, DVec3::Y],
            n_corners: 4,
            normal: DVec3::Z,
            area: 1.0,
            group: 0,
            face: 0,
            rho: [0.5; 3],
            emission: [0.0; 3],
        };
        let patches = crate::patch::PatchSet {
            patches: vec![square; 3],
            groups: vec!["g".into()],
        };
        let row = |index: u32, col: u32, val: f32| Row {
            index,
            values: RowValues::Sparse {
                cols: vec![col],
                vals: vec![val],
            },
            dropped: 1.0 - val,
            links: Vec::new(),
            link_error: None,
        };
        let rows = vec![row(0, 1, 0.6), row(1, 0, 0.6), row(2, 0, 0.5)];
        let rho = vec![[0.5f32; 3]; 3];
        let e = vec![vec![[1.0f32; 3], [0.0; 3], [0.0; 3]]];
        let sys = System::new(&patches, &e, &rho, DroppedMass::Pool).unwrap();
        (sys, MemoryRows::new(patches, rows).unwrap())
    }

    #[test]
    fn the_pool_takes_in_what_it_hands_out() {
        let (sys, src) = three();
        let pool = sys.measure_pool(&src).unwrap();
        // Carried into patch 0 by rows 1 and 2: 0.6 + 0.5; its row sums to 1: nothing
        // left (clamped at 0). Patch 1: 1 − 0.6; patch 2: 1 − 0.
        let want = [0.0, 1.0 - 0.6, 1.0];
        for (got, want) in pool.send.iter().zip(want) {
            assert!((got - want).abs() < 1e-7, "{:?}", pool.send);
        }
        assert!((pool.weight - 1.3).abs() < 1e-7, "{}", pool.weight);
        // Σ_j A_j D_j β = Σ_i s_i B_i for any B.
        let b = [2.0, 2.0, 2.0, 3.0, 3.0, 3.0, 5.0, 5.0, 5.0];
        let beta = pool.beta(&b, 3);
        let out = pool.weight * beta[0];
        let into = 0.4 * 3.0 + 5.0;
        assert!((out - into).abs() < 1e-6, "{out} vs {into}");
        assert_eq!(pool.senders_without_rows, None);
    }
}
