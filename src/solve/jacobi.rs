//! Jacobi iteration: B⁽ᵏ⁺¹⁾ = E + ρ F B⁽ᵏ⁾, one sequential scan of the rows per sweep.
//!
//! Every sweep computes G = F B⁽ᵏ⁾ for the reflecting patches, which is at once the
//! irradiance H of B⁽ᵏ⁾ and its exact residual: B⁽ᵏ⁾ − E − ρ G = B⁽ᵏ⁾ − B⁽ᵏ⁺¹⁾. So the
//! iteration stops as soon as ‖B⁽ᵏ⁾ − B⁽ᵏ⁺¹⁾‖∞ ≤ tolerance × ‖B⁽ᵏ⁾‖∞ (per column) and
//! returns B⁽ᵏ⁾ with its H and exact residual, with no extra pass (the pool's β of
//! [`super::DroppedMass::Pool`] is computed from B⁽ᵏ⁾ before the sweep, so this holds
//! with it too). The order of the rows does not matter. Rows of patches that reflect nothing are never used: their
//! B stays E.

use tracing::debug;

use super::source::RowSource;
use super::system::{
    column_max_abs, max_of, missing_error, nan_max, relative, Presence, System, FOR_GATHER,
};
use super::{HState, Iterate, SolveConfig, SolveError, SolveMethod};

/// Run Jacobi sweeps until the relative residual is within `cfg.tolerance` or
/// `cfg.max_iterations` sweeps are done.
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
    let mut next = sys.e.clone();
    let mut h = vec![0.0; n * m];
    let mut acc = vec![0.0; m];
    let max_sweeps = cfg.max_iterations.max(1);
    let start = std::time::Instant::now();
    let mut sweep = 0;
    loop {
        sweep += 1;
        let mut change = vec![0.0f64; m];
        let mut presence = Presence::new(n);
        let beta = sys.beta(&b);
        src.scan(&mut |row| {
            let Some((i, view)) = sys.gather_view(row, &mut presence, patches)? else {
                return Ok(());
            };
            sys.gather(&view, &b, &beta, &mut acc)?;
            for c in 0..m {
                let k = i * m + c;
                h[k] = acc[c];
                let v = sys.e[k] + sys.rho_col(i, c) * acc[c];
                change[c] = nan_max(change[c], (v - b[k]).abs());
                next[k] = v;
            }
            Ok(())
        })?;
        if let Some(first) = presence.missing(|i| sys.reflects[i]) {
            return Err(missing_error(patches, first, FOR_GATHER));
        }
        // `change` is exactly the residual of `b` (see the module docs).
        let rel = max_of(&relative(&change, &column_max_abs(&b, m)));
        debug!(sweep, residual = rel, "jacobi sweep");
        cfg.report(SolveMethod::Jacobi, sweep, rel, start);
        let converged = rel <= cfg.tolerance;
        if converged || sweep >= max_sweeps {
            return Ok(Iterate {
                b,
                h,
                state: HState::Reflecting(change),
                iterations: sweep,
                passes: sweep,
                rows_read: 0,
                converged,
            });
        }
        std::mem::swap(&mut b, &mut next);
    }
}
