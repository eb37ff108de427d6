//! The adjoint of the radiosity system: what a receiver outside the scene's patches
//! (a sensor point) sees of light first arriving anywhere.
//!
//! A sensor reads s = g · B, with g its point-to-patch form factors and B the radiosity
//! of B = ρ∘(E⁰ + F B) for first-arrival irradiance E⁰ (per channel). Then
//! s = g · (I − ρF)⁻¹ ρ E⁰ = u · E⁰ with u = ρ ∘ y and y = g + Fᵀ(ρ ∘ y). Solving for y
//! once per sensor replaces one forward solve per hour by a dot product per hour: the
//! daylight-coefficient idea (P. Tregenza and I. Waters, "Daylight coefficients",
//! Lighting Research and Technology 15(2) 65–71, 1983) applied to the adjoint, as
//! importance is in rendering.
//!
//! Iteration: Jacobi sweeps on y, one sequential scan of the rows per sweep; row i
//! scatters F_ij ρ_i y_i into every column j (through a row's links, spec §5.7, as
//! range additions applied after the scan: O(1) a link, as the forward gather's
//! prefix sums are, `links.rs`). The same rows the forward solve reads (a
//! patch that reflects nothing contributes nothing), with the same treatment of the
//! mass top-k rows dropped (scaled rows, or the pool's rank-one term transposed:
//! y_j gains (s_j / W) Σ_i D_i ρ_i y_i, `pool.rs`), so forward and adjoint answer the
//! same question about the same matrix.

use super::source::RowSource;
use super::system::{
    column_max_abs, max_of, missing_error, nan_max, relative, Presence, System, FOR_GATHER,
};
use super::{SolveConfig, SolveError};

/// The adjoint solution: per receiver (column set k) and patch, u = ρ ∘ y per channel.
#[derive(Clone, Debug)]
pub struct Adjoint {
    /// `u[k][i]`: the response of receiver k to unit first-arrival irradiance on patch
    /// i, per channel.
    pub u: Vec<Vec<[f64; 3]>>,
    /// Sweeps done.
    pub iterations: usize,
    /// Relative change of the last sweep, max over columns.
    pub residual: f64,
    /// The tolerance was reached (not only the sweep limit).
    pub converged: bool,
}

/// Solve y = g + Fᵀ(ρ ∘ y) for every receiver's `g` (n values each, the same for every
/// channel) and return u = ρ ∘ y. Uses `cfg.tolerance`, `cfg.max_iterations` and
/// `cfg.dropped` (the method is always Jacobi).
///
/// # Errors
/// As [`super::solve`]: inconsistent inputs; a needed row missing, Skipped or malformed.
pub fn solve_adjoint(
    src: &dyn RowSource,
    g_sets: &[Vec<f32>],
    rho: &[[f32; 3]],
    cfg: &SolveConfig,
) -> Result<Adjoint, SolveError> {
    let _span = tracing::info_span!("solve_adjoint", receivers = g_sets.len()).entered();
    let sets: Vec<Vec<[f32; 3]>> = g_sets
        .iter()
        .map(|g| g.iter().map(|&x| [x; 3]).collect())
        .collect();
    let mut sys = System::new(src.patches(), &sets, rho, cfg.dropped)?;
    sys.prepare_links(src, cfg.cache_bytes);
    sys.prepare_pool(src)?;
    let (n, m) = (sys.n, sys.m);
    let patches = src.patches();
    let mut y = sys.e.clone();
    let mut next = vec![0.0; n * m];
    let max_sweeps = cfg.max_iterations.max(1);
    let mut sweep = 0;
    loop {
        sweep += 1;
        next.copy_from_slice(&sys.e);
        let mut presence = Presence::new(n);
        let mut weights = vec![0.0; m];
        // Σ_i D_i ρ_i y_i over reflecting rows: the pool's term, transposed.
        let mut gamma = vec![0.0; m];
        // The links' range additions (their patches get them after the scan).
        let mut scatter = sys.links.as_ref().map(|l| l.scatter_start(m));
        src.scan(&mut |row| {
            let Some((i, view)) = sys.gather_view(row, &mut presence, patches)? else {
                return Ok(());
            };
            for (c, w) in weights.iter_mut().enumerate() {
                *w = sys.rho_col(i, c) * y[i * m + c];
            }
            if weights.iter().all(|&w| w == 0.0) {
                return Ok(());
            }
            if view.dropped > 0.0 {
                for (g, w) in gamma.iter_mut().zip(&weights) {
                    *g += view.dropped * w;
                }
            }
            view.visit_entries(n, |j, f| {
                let out = &mut next[j * m..(j + 1) * m];
                for (o, w) in out.iter_mut().zip(&weights) {
                    *o += f * w;
                }
            })?;
            if let (false, Some(space), Some(into)) =
                (view.links.is_empty(), &sys.links, scatter.as_mut())
            {
                space.scatter(
                    view.links,
                    view.index,
                    view.cols(),
                    &weights,
                    into,
                    &mut next,
                );
            }
            Ok(())
        })?;
        if let (Some(space), Some(into)) = (&sys.links, &scatter) {
            into.add_to(space, &mut next);
        }
        if let Some(first) = presence.missing(|i| sys.reflects[i]) {
            return Err(missing_error(patches, first, FOR_GATHER));
        }
        if let Some(pool) = &sys.pool {
            for (i, out) in next.chunks_exact_mut(m).enumerate() {
                let s = pool.send_share(i);
                if s != 0.0 {
                    for (o, g) in out.iter_mut().zip(&gamma) {
                        *o += s * g;
                    }
                }
            }
        }
        let mut change = vec![0.0f64; m];
        for (k, (a, b)) in next.iter().zip(&y).enumerate() {
            let c = k % m;
            change[c] = nan_max(change[c], (a - b).abs());
        }
        let rel = max_of(&relative(&change, &column_max_abs(&next, m)));
        std::mem::swap(&mut y, &mut next);
        let converged = rel <= cfg.tolerance;
        if converged || sweep >= max_sweeps {
            let u = (0..sys.cases)
                .map(|k| {
                    (0..n)
                        .map(|i| std::array::from_fn(|ch| sys.rho[i][ch] * y[i * m + 3 * k + ch]))
                        .collect()
                })
                .collect();
            return Ok(Adjoint {
                u,
                iterations: sweep,
                residual: rel,
                converged,
            });
        }
    }
}
