//! Exact visibility in the row engine ([`Visibility::Exact`]): a pair whose candidate
//! occluders are listed (at most [`EXACT_MAX_CANDIDATES`] triangles) gets its blocked
//! part from [`shadow`]; other pairs, and pairs whose shadows cannot be cut into few
//! enough pieces, get rays.

use super::{ClippedPair, RowEngine, Scratch};
use crate::formfactor::shadow::solids::NO_SOLID;
use crate::formfactor::shadow::{self, Blocked, Caster, Pair};
#[cfg(doc)]
use crate::formfactor::Visibility;

/// Most candidate triangles of a pair handled exactly (more: rays). Measured: see
/// bench/PERF.md §14.
pub(crate) const EXACT_MAX_CANDIDATES: usize = 32;

/// Relative remainder of F⁰ below which an exactly handled pair counts as hidden.
const SNAP: f64 = 1e-8;

impl RowEngine {
    /// F_ij of a pair that may be occluded (`pair`: its patches and clipped polygons),
    /// unoccluded value `f0`, whose candidate occluders are `candidates` (triangle
    /// ids): F⁰ minus the blocked part, or None when the shadows need rays after all.
    pub(super) fn exact_occluded(
        &self,
        (gi, _, pi, pj): &ClippedPair<'_>,
        f0: f64,
        candidates: &[u32],
        scratch: &mut Scratch,
    ) -> Option<f64> {
        let mut casters = std::mem::take(&mut scratch.casters);
        casters.clear();
        casters.extend(candidates.iter().filter_map(|&k| {
            let solid = self.solids.of.get(k as usize).copied();
            Caster::new(self.occluders.world_triangle(k))
                .map(|c| c.in_solid(solid.unwrap_or(NO_SOLID)))
        }));
        let pair = Pair {
            pi,
            ni: gi.normal,
            pj,
            casters: &casters,
            solids: &self.solids.solids,
            tol: self.tol,
            params: self.params,
        };
        let tol_abs = self.cfg.shadow_tol * f0 * gi.area;
        let result = shadow::blocked_integral(&pair, tol_abs, &mut scratch.shadow);
        scratch.casters = casters;
        let c = &mut scratch.pair.counters;
        let Some(blocked) = result else {
            c.pairs_exact_fallback += 1;
            return None;
        };
        c.pairs_exact += 1;
        c.rays_skipped += u64::from(self.cfg.samples);
        Some(match blocked {
            Blocked::Nothing => {
                c.pairs_exact_visible += 1;
                f0
            }
            Blocked::All => {
                c.pairs_exact_hidden += 1;
                0.0
            }
            Blocked::Part {
                blocked,
                points,
                met,
            } => {
                c.exact_points += u64::from(points);
                c.pairs_exact_unmet += u64::from(!met);
                // What is left within the method's resolution of nothing is
                // nothing: a patch hidden behind several occluders (a floor cell
                // under a box) gets an exact 0, not the quadrature's remainder or the
                // slivers the clipping tolerance leaves where shadows meet (~1e-10
                // of F⁰). The resolution is a small share of the tolerance: a pair
                // that shows 1 % of itself keeps its 1 % at `--shadow-tol 1e-2`.
                let f = f0 - blocked / gi.area;
                let resolution =
                    (self.cfg.shadow_tol / f64::from(shadow::UNRESOLVED)).max(SNAP) * f0;
                if f <= resolution {
                    0.0
                } else {
                    f
                }
            }
        })
    }
}
