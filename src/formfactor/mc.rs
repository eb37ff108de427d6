//! The `mc` kernel: stratified area-to-area Monte Carlo.
//!
//! F_ij ≈ 1/(A_i S) Σ_k J_i(k) J_j(k) cosθ_i cosθ_j / (π r²) V(x_k, y_k)
//!
//! over S point pairs (x_k on i, y_k on j) from a Latin hypercube over the two unit
//! squares ([`super::sampling::latin_pairs`]), mapped onto the patches with their
//! area Jacobians J, and one ray per pair with a positive kernel (none when nothing
//! can come between the patches). Unbiased for separated patches; for neighbours the
//! 1/r² kernel gives a heavy-tailed estimator (infinite variance for patches sharing
//! an edge), which is what the method comparison is meant to show. An entry is
//! clamped to 1.

use super::geom::PatchGeom;
use super::sampling::{latin_pairs, pair_seed, SplitMix64, Stream};
use super::scratch::PairScratch;
use super::FormFactorConfig;
use crate::geometry::occluders::Occluders;

/// F_ij by Monte Carlo with `cfg.samples` point pairs. The caller has checked that the
/// pair is not facing away.
pub(crate) fn pair(
    i: u32,
    j: u32,
    gi: &PatchGeom,
    gj: &PatchGeom,
    occ: &Occluders,
    cfg: &FormFactorConfig,
    scratch: &mut PairScratch,
) -> f64 {
    let s = cfg.samples.max(1) as usize;
    let need_rays = occ.any_between(&gi.between(gj));
    if !need_rays {
        scratch.counters.pairs_unoccludable += 1;
        scratch.counters.rays_skipped += s as u64;
    }
    let mut rng = SplitMix64::new(pair_seed(cfg.seed, i, j, Stream::Mc));
    latin_pairs(&mut rng, s, &mut scratch.perms, &mut scratch.samples);
    let mut sum = 0.0;
    let mut cast = 0u64;
    for q in &scratch.samples {
        let Some((x, y, w)) = gi.kernel_point(gj, *q) else {
            continue;
        };
        if need_rays {
            cast += 1;
            if occ.occluded(x, y, (gi.face, gj.face)) {
                continue;
            }
        }
        sum += w;
    }
    if need_rays {
        scratch.counters.pairs_rays += 1;
        scratch.counters.rays_cast += cast;
        scratch.counters.rays_skipped += s as u64 - cast;
    }
    (sum / (std::f64::consts::PI * gi.area * s as f64)).min(1.0)
}
