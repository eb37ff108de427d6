//! The final pass: irradiance H = F B for every patch and the exact residual of B.
//!
//! For a reflecting patch i (ρ_i > 0 in some channel) H_i = Σ_j F_ij B_j comes from its
//! own row, and the residual is r_i = B_i − E_i − ρ_i H_i. A patch that reflects nothing
//! ("dark": ρ_i = 0, e.g. a black sensor) has B_i = E_i exactly and its row is never read
//! — files computed with only the needed rows do not even hold it. Its irradiance is
//! still wanted (what a sensor there measures), and comes by reciprocity
//! (A_i F_ij = A_j F_ji, eq. (1) of the paper is symmetric in i and j) from the rows of
//! the patches that send light:
//!
//!   H_i = Σ_j F_ij B_j = Σ_j (A_j / A_i) F_ji B_j,
//!
//! summed over every patch j with B_j ≠ 0: reflecting patches (rows always present) and
//! dark emitters (rows present unless the file skipped them; then the light they send
//! straight to dark patches is left out and a warning says so). This is a scatter: each
//! row j read adds its share to the dark patches. With top-k rows the two routes use
//! different truncations of F (row i versus column i taken from the rows j); both are
//! scaled as [`super::rowview`] describes. The pool of [`super::DroppedMass::Pool`]
//! gives its light to reflecting patches only (`pool.rs`): a dark patch's irradiance
//! holds what the stored entries of the other rows carry to it.

use super::error::SolveError;
use super::rowview::RowView;
use super::source::RowSource;
use super::system::{
    check_index, missing_error, nan_max, skipped_error, Presence, System, FOR_GATHER,
};

/// What the final pass computes besides H.
pub(crate) enum Mode {
    /// Gather H for reflecting patches (and their residual), scatter H for dark ones.
    Full,
    /// H of reflecting patches is already known (a Jacobi sweep computed it from the
    /// same B): only scatter H for dark patches.
    DarkOnly,
}

pub(crate) struct FinalPass {
    /// Per column max_i |B_i − E_i − ρ_i H_i| (only for [`Mode::Full`]).
    pub(crate) residual_abs: Vec<f64>,
    /// Dark emitters whose rows were not available to the scatter: (first, count).
    pub(crate) dark_sources_missing: Option<(u32, usize)>,
}

/// Run the final pass over `src` for radiosity `b` (`n × m`), writing H into `h`.
///
/// # Errors
/// A missing, Skipped, duplicated or malformed row of a reflecting patch; the source's
/// read error.
pub(crate) fn final_pass(
    sys: &System,
    src: &dyn RowSource,
    b: &[f64],
    h: &mut [f64],
    mode: Mode,
) -> Result<FinalPass, SolveError> {
    let (n, m) = (sys.n, sys.m);
    let full = matches!(mode, Mode::Full);
    let scatter = !sys.dark.is_empty();
    for &i in &sys.dark {
        h[i as usize * m..(i as usize + 1) * m].fill(0.0);
    }
    let mut residual_abs = vec![0.0f64; m];
    let mut acc = vec![0.0; m];
    let mut presence = Presence::new(n);
    let mut dark_source_skipped = Vec::new();
    let patches = src.patches();
    let beta = sys.beta(b);

    src.scan(&mut |row| {
        let j = check_index(row.index, n)?;
        // Inert rows (no reflection, no emission in any case) send nothing: never read.
        if !sys.reflects[j] && !sys.emits[j] {
            return Ok(());
        }
        presence.mark(row.index)?;
        let Some(view) = sys.view(row)? else {
            if sys.reflects[j] {
                return Err(skipped_error(patches, j, FOR_GATHER));
            }
            dark_source_skipped.push(row.index);
            return Ok(());
        };
        if full && sys.reflects[j] {
            sys.gather(&view, b, &beta, &mut acc)?;
            for c in 0..m {
                let k = j * m + c;
                h[k] = acc[c];
                let r = (b[k] - sys.e[k] - sys.rho_col(j, c) * acc[c]).abs();
                residual_abs[c] = nan_max(residual_abs[c], r);
            }
        }
        if scatter {
            scatter_to_dark(sys, &view, j, b, h)?;
        }
        Ok(())
    })?;

    if let Some(first) = presence.missing(|i| sys.reflects[i]) {
        return Err(missing_error(patches, first, FOR_GATHER));
    }
    let mut dark_missing: Vec<u32> = dark_source_skipped;
    if scatter {
        dark_missing.extend((0..n as u32).filter(|&i| {
            !sys.reflects[i as usize] && sys.emits[i as usize] && !presence.seen(i as usize)
        }));
    }
    dark_missing.sort_unstable();
    Ok(FinalPass {
        residual_abs,
        dark_sources_missing: dark_missing.first().map(|&f| (f, dark_missing.len())),
    })
}

/// Add row j's light to the irradiance of every dark patch i:
/// H_i += (A_j / A_i) F_ji B_j.
fn scatter_to_dark(
    sys: &System,
    view: &RowView<'_>,
    j: usize,
    b: &[f64],
    h: &mut [f64],
) -> Result<(), SolveError> {
    let m = sys.m;
    let bj = &b[j * m..(j + 1) * m];
    if bj.iter().all(|&x| x == 0.0) {
        return Ok(());
    }
    let aj = sys.area[j];
    let add = |i: usize, f: f64, h: &mut [f64]| {
        let w = f * aj / sys.area[i];
        for (hc, &bc) in h[i * m..(i + 1) * m].iter_mut().zip(bj) {
            *hc += w * bc;
        }
    };
    if view.is_dense() {
        // Few dark patches among many columns: look them up instead of walking the row.
        for &i in &sys.dark {
            let f = view.get(i as usize);
            if !f.is_finite() {
                return Err(SolveError::BadRow {
                    row: view.index,
                    message: format!("value at column {i} is not finite"),
                });
            }
            if f != 0.0 {
                add(i as usize, f, h);
            }
        }
        Ok(())
    } else {
        view.visit(sys.n, |i, f| {
            if !sys.reflects[i] {
                add(i, f, h);
            }
        })
    }
}
