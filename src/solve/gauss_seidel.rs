//! Gauss–Seidel iteration: B_i ← E_i + ρ_i Σ_j F_ij B_j, updating B in place, rows in
//! the order the source stores them (one sequential scan per sweep).
//!
//! The order is the file's (for `.ffz` files: the order rows were written, which
//! depends on scheduling), not the patch order. It converges for any order: with
//! ρ_i < 1 and row sums ≤ 1, I − ρF is a nonsingular M-matrix and "rows read before i"
//! versus "the rest" (the self term F_ii, non-zero only for curved patches, taken from
//! the old value) is a regular splitting of it (Varga, Matrix Iterative Analysis,
//! thm. 3.13). Links whose slope takes some weights below zero (spec §5.7) make some
//! entries negative; then it converges whenever max_i ρ_i Σ_j |F_ij| < 1 (the sweep
//! is a contraction in the max norm), the coefficient of the stopping rule below.
//! The answer differs between orders only within the tolerance. Random access in
//! patch order would cost a seek per row for no gain in convergence.
//!
//! Stopping rule. Splitting F into the entries read before and after row i in a
//! sweep, the residual after the sweep is r_i = ρ_i Σ_{j not yet updated when row i
//! was read} F_ij (B_j^old − B_j^new) (the self term F_ii included), hence
//!
//!   |r_ic| ≤ (max_i ρ_ic S_i) · max_j |ΔB_jc|,   S_i = Σ_j |F_ij| (scaled row),
//!
//! a rigorous bound computed during the sweep at no cost. With the pool of
//! [`super::DroppedMass::Pool`] the sweep uses β of the B it started from; β is linear
//! in B, so the residual gains ρ_i D_i |β(B^new) − β(B^old)|, bounded by
//! (max_i ρ_ic D_i) |Δβ_c| with β(B^new) computed after the sweep (O(n)).
//! When the bound is within
//! the tolerance, a final pass computes H = F B and the exact residual (one more
//! scan); the solve ends if that confirms it.

use tracing::debug;

use super::check::{final_pass, Mode};
use super::source::RowSource;
use super::system::{
    column_max_abs, max_of, missing_error, nan_max, relative, Presence, System, FOR_GATHER,
};
use super::{HState, Iterate, SolveConfig, SolveError, SolveMethod};

/// Run Gauss–Seidel sweeps until the exact relative residual is within
/// `cfg.tolerance` or `cfg.max_iterations` sweeps are done.
///
/// # Errors
/// A needed row missing, Skipped, duplicated or malformed; the source's read error.
pub(crate) fn run(
    sys: &System,
    src: &dyn RowSource,
    cfg: &SolveConfig,
) -> Result<Iterate, SolveError> {
    let (n, m) = (sys.n, sys.m);
    let patches = src.patches();
    let mut b = sys.e.clone();
    let mut h = vec![0.0; n * m];
    let mut acc = vec![0.0; m];
    let max_sweeps = cfg.max_iterations.max(1);
    let start = std::time::Instant::now();
    let mut passes = 0;
    let mut sweep = 0;
    loop {
        sweep += 1;
        let mut change = vec![0.0f64; m];
        let mut coef = vec![0.0f64; m];
        let mut pool_coef = vec![0.0f64; m];
        let mut presence = Presence::new(n);
        let beta = sys.beta(&b);
        src.scan(&mut |row| {
            let Some((i, view)) = sys.gather_view(row, &mut presence, patches)? else {
                return Ok(());
            };
            let abs_sum = sys.gather(&view, &b, &beta, &mut acc)?;
            for c in 0..m {
                let k = i * m + c;
                let rho = sys.rho_col(i, c);
                let v = sys.e[k] + rho * acc[c];
                change[c] = nan_max(change[c], (v - b[k]).abs());
                coef[c] = coef[c].max(rho * abs_sum);
                pool_coef[c] = pool_coef[c].max(rho * view.dropped);
                b[k] = v;
            }
            Ok(())
        })?;
        passes += 1;
        if let Some(first) = presence.missing(|i| sys.reflects[i]) {
            return Err(missing_error(patches, first, FOR_GATHER));
        }
        let scale = column_max_abs(&b, m);
        let beta_after = sys.pool_beta(&b);
        let bound: Vec<f64> = (0..m)
            .map(|c| coef[c] * change[c] + pool_coef[c] * (beta_after[c] - beta[c]).abs())
            .collect();
        let rel_bound = max_of(&relative(&bound, &scale));
        debug!(sweep, residual_bound = rel_bound, "gauss-seidel sweep");
        cfg.report(SolveMethod::GaussSeidel, sweep, rel_bound, start);
        let last = sweep >= max_sweeps;
        if rel_bound <= cfg.tolerance || last {
            let fp = final_pass(sys, src, &b, &mut h, Mode::Full)?;
            passes += 1;
            let rel = max_of(&relative(&fp.residual_abs, &scale));
            debug!(sweep, residual = rel, "gauss-seidel check");
            let converged = rel <= cfg.tolerance;
            if converged || last {
                return Ok(Iterate {
                    b,
                    h,
                    state: HState::Complete(fp),
                    iterations: sweep,
                    passes,
                    rows_read: 0,
                    converged,
                });
            }
        }
    }
}
