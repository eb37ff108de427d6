//! What the pair kernels write into: the work counters and the sample buffers of one
//! thread ([`PairScratch`]), part of the row engine's per-thread [`super::Scratch`].
//! Kernels see only this, not the engine's own buffers and caches.

/// Work done, for reports and benchmarks. Summed over scratches by the caller.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Rows computed.
    pub rows: u64,
    /// Pairs (i ≠ j) whose kernel was evaluated.
    pub pairs_evaluated: u64,
    /// Pairs skipped without kernel work because one faces away from the other
    /// (including coplanar pairs).
    pub pairs_facing_away: u64,
    /// `contour` pairs far enough apart for the tensor Gauss rule
    /// ([`super::farfield`]) instead of the contour integral.
    pub pairs_far_field: u64,
    /// Top-k tail pairs (sampled mode) whose visibility was never needed.
    pub pairs_topk_tail_skipped: u64,
    /// Evaluated pairs between which no occluder can come (no rays needed).
    pub pairs_unoccludable: u64,
    /// Shadow rays cast.
    pub rays_cast: u64,
    /// Pairs whose visibility was estimated by rays (`contour`'s ratio estimate,
    /// `point`'s one ray, `mc`'s samples), counted where the estimate is made.
    pub pairs_rays: u64,
    /// Rays the per-pair budget allowed but that were not cast: all of them for pairs
    /// no occluder can come between, the rest of the budget when the adaptive
    /// estimate stopped after its first batch (`contour`), samples with a
    /// non-positive kernel (`mc`).
    pub rays_skipped: u64,
    /// Pairs that may be occluded whose blocked part was computed exactly
    /// (`--visibility exact`).
    pub pairs_exact: u64,
    /// Points of the outer rule those pairs took.
    pub exact_points: u64,
    /// Of the exact pairs, those proven fully visible (no candidate crosses a segment
    /// between the two patches): no points at all.
    pub pairs_exact_visible: u64,
    /// Of the exact pairs, those proven fully hidden (one candidate hides one patch
    /// from every point of the other): no points.
    pub pairs_exact_hidden: u64,
    /// Pairs meant for exact visibility that went to rays (more candidates than the
    /// exact route takes, or shadows cut into too many pieces).
    pub pairs_exact_fallback: u64,
    /// Of the partly shadowed exact pairs, those whose outer rule stopped before its
    /// error estimate met the tolerance (at its most points or deepest refinement):
    /// their value is the rule's best, kept, but not within `--shadow-tol` as promised.
    pub pairs_exact_unmet: u64,
    /// Top-k tree search: nodes opened (their children's bounds computed, or a leaf's
    /// columns evaluated).
    pub tree_nodes_opened: u64,
    /// Top-k tree search: walks from an unopened node down to one column, for the
    /// dropped mass.
    pub tree_tail_samples: u64,
    /// Top-k tree search: nodes not opened because a blocker polygon, or the cell the
    /// blockers close, hides them from the whole row patch (rows that found many hidden
    /// columns).
    pub tree_nodes_hidden: u64,
    /// Hemisphere rays cast for top-k row totals (`engine/closure.rs`).
    pub closure_rays: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.rows += o.rows;
        self.pairs_evaluated += o.pairs_evaluated;
        self.pairs_facing_away += o.pairs_facing_away;
        self.pairs_far_field += o.pairs_far_field;
        self.pairs_topk_tail_skipped += o.pairs_topk_tail_skipped;
        self.tree_nodes_opened += o.tree_nodes_opened;
        self.tree_tail_samples += o.tree_tail_samples;
        self.tree_nodes_hidden += o.tree_nodes_hidden;
        self.closure_rays += o.closure_rays;
        self.pairs_unoccludable += o.pairs_unoccludable;
        self.rays_cast += o.rays_cast;
        self.pairs_rays += o.pairs_rays;
        self.rays_skipped += o.rays_skipped;
        self.pairs_exact += o.pairs_exact;
        self.exact_points += o.exact_points;
        self.pairs_exact_visible += o.pairs_exact_visible;
        self.pairs_exact_hidden += o.pairs_exact_hidden;
        self.pairs_exact_fallback += o.pairs_exact_fallback;
        self.pairs_exact_unmet += o.pairs_exact_unmet;
    }
}

/// A thread's counters and the sample buffers of the stratified samplers
/// (`sampling::latin_pairs`), reused from pair to pair.
#[derive(Debug, Default)]
pub(crate) struct PairScratch {
    pub(crate) counters: Counters,
    pub(crate) perms: Vec<u32>,
    pub(crate) samples: Vec<[f64; 4]>,
}
