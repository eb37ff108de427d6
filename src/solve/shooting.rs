//! Progressive refinement ("shooting", Cohen, Chen, Wallace and Greenberg, SIGGRAPH
//! 1988): the patch with the most unshot power sends it to every other patch, until the
//! power not yet distributed is within the tolerance of the emitted power.
//!
//! Shooting from patch j needs column j of F: B_i gains ρ_i F_ij ΔB_j. The file stores
//! rows, so reciprocity (A_i F_ij = A_j F_ji) turns the column into row j:
//!
//!   ΔB_i += ρ_i (A_j / A_i) F_ji ΔB_j,
//!
//! one random-access read of row j per shot. With top-k rows this uses the truncation
//! of row j (the power j sends), scaled so that all of it arrives somewhere: shooting
//! then conserves power exactly, while the gathering solvers use the truncation of row
//! i; the two systems differ by the asymmetry of the truncation (the final pass reports
//! the residual against the gathering form).
//!
//! With the pool of [`super::DroppedMass::Pool`] (`pool.rs`) rows are not scaled: a
//! shot from j also puts A_j D_j ΔB_j into the pool, and the pool is shot like one more
//! patch when its unshot power P is the largest, giving each reflecting receiver i
//! ΔB_i = ρ_i (u_i / U) P / A_i (O(n), no row read).
//!
//! Choice of shooter. Departure from the single-RHS algorithm: with K cases × RGB the
//! "unshot power" of patch j is Σ_c A_j ΔB_jc / Φ_c over columns c with emitted power
//! Φ_c > 0, i.e. each column's unshot power relative to its own emission, so a dim case
//! is not starved by a bright one. The stopping rule matches: stop when, for every
//! column, the unshot power Σ_j A_j ΔB_jc < tolerance × Φ_c. Receivers that reflect
//! nothing get no unshot radiosity (their B stays E).
//!
//! Cost per shot: the row (n or k entries × 3K) plus an O(n) search for the next
//! shooter.

use tracing::debug;

use super::source::RowSource;
use super::system::{missing_error, skipped_error, System, FOR_SHOOT};
use super::{HState, Iterate, SolveConfig, SolveError, SolveMethod};

/// Shoot until the unshot power is within `cfg.tolerance` of the emitted power per
/// column, or `cfg.max_iterations × n` shots are done.
///
/// # Errors
/// The row of a patch that must shoot is missing, Skipped or malformed; the source's
/// read error.
pub(crate) fn run(
    sys: &System,
    src: &dyn RowSource,
    cfg: &SolveConfig,
) -> Result<Iterate, SolveError> {
    let (n, m) = (sys.n, sys.m);
    let patches = src.patches();
    let emitted = sys.emitted_power();
    let start = std::time::Instant::now();
    let weight: Vec<f64> = emitted
        .iter()
        .map(|&p| if p > 0.0 { 1.0 / p } else { 0.0 })
        .collect();
    let mut b = sys.e.clone();
    let mut unshot = sys.e.clone();
    let priority_of = |unshot: &[f64], i: usize| -> f64 {
        let u = &unshot[i * m..(i + 1) * m];
        sys.area[i] * u.iter().zip(&weight).map(|(x, w)| x * w).sum::<f64>()
    };
    let mut priority: Vec<f64> = (0..n).map(|i| priority_of(&unshot, i)).collect();
    let inv_area: Vec<f64> = sys.area.iter().map(|a| 1.0 / a).collect();
    let mut unshot_power = emitted.clone();
    let max_shots = cfg.max_iterations.max(1).saturating_mul(n.max(1));
    let mut shots = 0usize;
    let mut shot = vec![0.0; m];
    // The pool's unshot power per column (stays 0 without a pool or when no reflecting
    // row dropped anything).
    let pool = sys
        .pool
        .as_ref()
        .filter(|p| p.shoot_share.iter().any(|&s| s > 0.0));
    let mut pool_unshot = vec![0.0; m];
    let converged = loop {
        // Relative unshot power per column; exact sums every n shots so that the
        // running update cannot drift.
        if shots.is_multiple_of(n.max(1)) {
            unshot_power = column_power(sys, &unshot);
            for (p, q) in unshot_power.iter_mut().zip(&pool_unshot) {
                *p += q;
            }
        }
        let worst = unshot_power
            .iter()
            .zip(&weight)
            .map(|(u, w)| u * w)
            .fold(0.0, f64::max);
        if worst < cfg.tolerance || worst == 0.0 {
            break true;
        }
        if shots >= max_shots {
            break false;
        }
        let pool_priority: f64 = pool_unshot.iter().zip(&weight).map(|(x, w)| x * w).sum();
        let best = argmax(&priority);
        if let Some(pool) = pool.filter(|_| best.is_none_or(|j| pool_priority > priority[j])) {
            shot.copy_from_slice(&pool_unshot);
            pool_unshot.fill(0.0);
            for (c, p) in unshot_power.iter_mut().enumerate() {
                *p -= shot[c];
            }
            for (i, &s) in pool.shoot_share.iter().enumerate() {
                if s == 0.0 {
                    continue;
                }
                let share = s * inv_area[i];
                for c in 0..m {
                    let delta = sys.rho_col(i, c) * share * shot[c];
                    b[i * m + c] += delta;
                    unshot[i * m + c] += delta;
                    unshot_power[c] += sys.area[i] * delta;
                }
                priority[i] = priority_of(&unshot, i);
            }
            shots += 1;
            continue;
        }
        let Some(j) = best else {
            break true;
        };
        let row = src.row(j as u32)?.ok_or_else(|| {
            // Every row that can be shot (it emits or reflects) is needed.
            let missing = (0..n as u32)
                .filter(|&i| (sys.reflects[i as usize] || sys.emits[i as usize]) && !src.has_row(i))
                .count();
            missing_error(patches, (j as u32, missing), FOR_SHOOT)
        })?;
        if row.index as usize != j {
            return Err(SolveError::BadRow {
                row: j as u32,
                message: format!("random access returned row {} instead", row.index),
            });
        }
        let view = sys
            .view(&row)?
            .ok_or_else(|| skipped_error(patches, j, FOR_SHOOT))?;
        shot.copy_from_slice(&unshot[j * m..(j + 1) * m]);
        unshot[j * m..(j + 1) * m].fill(0.0);
        for (c, p) in unshot_power.iter_mut().enumerate() {
            *p -= sys.area[j] * shot[c];
        }
        let aj = sys.area[j];
        // Per receiver i with w = F_ji A_j / A_i: d_c = ρ_ic w shot_c. Its priority grows
        // by A_i Σ_c d_c weight_c = F_ji A_j Σ_ch ρ_i,ch Σ_k shot_(k,ch) weight_(k,ch)
        // (A_i cancels), and the unshot power of column c by A_i d_c, summed per channel
        // over the row (`rho_sum`) and applied once after it.
        let mut per_channel = [0.0f64; 3];
        for (c, (s, w)) in shot.iter().zip(&weight).enumerate() {
            per_channel[c % 3] += s * w;
        }
        let mut rho_sum = [0.0f64; 3];
        view.visit(n, |i, f| {
            if !sys.reflects[i] {
                return;
            }
            let rho = &sys.rho[i];
            let w = f * aj * inv_area[i];
            for (c, (bc, uc)) in b[i * m..(i + 1) * m]
                .iter_mut()
                .zip(&mut unshot[i * m..(i + 1) * m])
                .enumerate()
            {
                let d = rho[c % 3] * w * shot[c];
                *bc += d;
                *uc += d;
            }
            for ch in 0..3 {
                rho_sum[ch] += f * rho[ch];
            }
            priority[i] += f * aj * (0..3).map(|ch| rho[ch] * per_channel[ch]).sum::<f64>();
        })?;
        for (c, p) in unshot_power.iter_mut().enumerate() {
            *p += aj * shot[c] * rho_sum[c % 3];
        }
        if pool.is_some() && view.dropped > 0.0 {
            for (c, (p, q)) in unshot_power.iter_mut().zip(&mut pool_unshot).enumerate() {
                let into = aj * view.dropped * shot[c];
                *p += into;
                *q += into;
            }
        }
        // j's own entry (F_jj ≠ 0 on curved patches) may have given it new unshot power.
        priority[j] = priority_of(&unshot, j);
        shots += 1;
        if shots.is_multiple_of(n.max(1)) {
            debug!(shots, unshot = worst, "shooting");
            cfg.report(SolveMethod::Shooting, shots, worst, start);
        }
    };
    debug!(shots, converged, "shooting done");
    Ok(Iterate {
        b,
        h: vec![0.0; n * m],
        state: HState::Missing,
        iterations: shots,
        passes: 0,
        rows_read: shots as u64,
        converged,
    })
}

/// Σ_j A_j x_jc per column.
fn column_power(sys: &System, x: &[f64]) -> Vec<f64> {
    let m = sys.m;
    let mut p = vec![0.0; m];
    for (i, chunk) in x.chunks_exact(m).enumerate() {
        for (p, v) in p.iter_mut().zip(chunk) {
            *p += sys.area[i] * v;
        }
    }
    p
}

/// Index of the largest positive value, `None` when none is positive.
fn argmax(v: &[f64]) -> Option<usize> {
    let mut best = None;
    let mut best_value = 0.0;
    for (i, &x) in v.iter().enumerate() {
        if x > best_value {
            best_value = x;
            best = Some(i);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::argmax;

    #[test]
    fn argmax_picks_first_largest_and_ignores_zeros() {
        assert_eq!(argmax(&[0.0, 2.0, 1.0, 2.0]), Some(1));
        assert_eq!(argmax(&[0.0, 0.0]), None);
        assert_eq!(argmax(&[]), None);
    }
}
