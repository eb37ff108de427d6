//! Form factors: the kernels and the row engine (docs/numerics.md §5).
//!
//! F_ij = 1/A_i ∫_Ai ∫_Aj cosθ_i cosθ_j / (π r²) V_ij dA_j dA_i  (eq. (1) of the paper)
//!
//! Three methods behind one interface ([`Method`]), selected by [`FormFactorConfig`]:
//!
//! | method | unoccluded part | visibility | file |
//! |---|---|---|---|
//! | `point` | centroid-to-centroid differential kernel cosθ_i cosθ_j A_j/(π r²) | 1 ray between centroids | [`point`] |
//! | `mc` | stratified area-to-area Monte Carlo, S point pairs | the same S pairs, 1 ray each | [`mc`] |
//! | `contour` | exact to `quad_tol`: double contour integral (Stokes), tensor Gauss rule for well-separated pairs | kernel-weighted ratio estimator, adaptive, ≤ S rays | [`contour`], [`farfield`], [`visibility`] |
//!
//! [`RowEngine`] computes whole rows: it precomputes per-patch data once, skips pairs
//! facing away, asks the [`Occluders`](crate::geometry::occluders::Occluders) whether
//! anything can come between a pair before casting rays, accumulates in f64 and
//! emits f32 (dense, or top-k with the dropped mass recorded). Every random number is
//! drawn from a stream seeded by (i, j, seed), so a row is bitwise the same on any
//! thread or rank.

pub(crate) mod clip;
pub(crate) mod clusters;
pub(crate) mod contour;
pub(crate) mod engine;
pub(crate) mod farfield;
pub(crate) mod geom;
pub(crate) mod mc;
pub(crate) mod point;
pub(crate) mod quadrature;
pub mod sampling;
pub(crate) mod scratch;
pub(crate) mod shadow;
pub(crate) mod topk;
pub(crate) mod tree;
pub(crate) mod visibility;

use std::fmt;

pub use engine::{RowEngine, Scratch};
pub use scratch::Counters;

/// Errors of the form-factor layer (configuration only: the kernels themselves do
/// not fail).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FormFactorError {
    #[error("invalid form-factor configuration: {0}")]
    InvalidConfig(String),
}

/// The form-factor kernel (a fixed set, docs/conventions.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Centroid-to-centroid differential kernel with one ray: the paper's baseline.
    Point,
    /// Stratified area-to-area Monte Carlo with `samples` point pairs and rays.
    Mc,
    /// Exact unoccluded form factor (double contour integral) times a kernel-weighted
    /// visibility fraction.
    Contour,
}

impl Method {
    pub const ALL: [Method; 3] = [Method::Point, Method::Mc, Method::Contour];

    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Method::Point => "point",
            Method::Mc => "mc",
            Method::Contour => "contour",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Named settings of the form-factor computation (`--preset`): how many visibility
/// rays and how tight a quadrature (see [`FormFactorConfig::fast`], `accurate`,
/// `reference`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Preset {
    Fast,
    #[default]
    Accurate,
    Reference,
}

impl Preset {
    pub(crate) const ALL: [Preset; 3] = [Preset::Fast, Preset::Accurate, Preset::Reference];

    pub(crate) fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Accurate => "accurate",
            Preset::Reference => "reference",
        }
    }
}

/// Most visibility samples per pair (`samples`, `first_batch`): 65 536 rays per pair
/// is far past the point where exact visibility is the better route, and bounds the
/// per-thread sample buffers (about 12 bytes a sample).
pub const MAX_SAMPLES: u32 = 1 << 16;

/// Parameters of a form-factor run. Everything that changes the numbers is here, and
/// the file header records it (the job layer's run parameters, `src/job/params.rs`).
#[derive(Clone, Debug, PartialEq)]
pub struct FormFactorConfig {
    pub method: Method,
    /// Visibility samples per pair: the number of rays (`mc`), the most rays of the
    /// adaptive visibility estimate (`contour`). `point` always casts one.
    pub samples: u32,
    /// `contour`: size of the first batch of visibility rays; when all of them agree
    /// (all blocked or all free) the pair stops there, else it goes on to `samples`.
    pub first_batch: u32,
    /// Seed of the sampling streams (each pair (i, j) draws from hash(i, j, seed)).
    pub seed: u64,
    /// Keep only the k largest entries of each row (the rest goes to `Row::dropped`).
    pub top_k: Option<u32>,
    /// With `top_k` and `contour`: how the dropped mass of the pairs that cannot make
    /// the top k is obtained (see [`TopKTail`]).
    pub top_k_tail: TopKTail,
    /// With `top_k` and `contour`: how the candidates of a row are found (see
    /// [`TopKSearch`]).
    pub top_k_search: TopKSearch,
    /// Keep only the entries ≥ this value (threshold rows, as View3D/uDALES store them;
    /// the rest goes to `Row::dropped`); with `top_k`, the k largest of those.
    pub min_ff: Option<f64>,
    /// `contour`: most Gauss–Legendre points per panel of the outer line integral
    /// (1..=24); panels needing more are split.
    pub quad_order: u32,
    /// `contour`: target relative error of the unoccluded form factor per quadrature
    /// panel (double contour integral) or per pair (tensor rule for far pairs).
    pub quad_tol: f64,
    /// `contour`: how the visibility of a pair that may be occluded is obtained.
    pub visibility: Visibility,
    /// `contour` with [`Visibility::Exact`]: target error of an entry's blocked part,
    /// relative to the entry's unoccluded value.
    pub shadow_tol: f64,
    /// Sparse rows of the tree search: the most links to clusters of patches a row
    /// carries for the mass it does not keep (`engine/links.rs`, spec §5.7); `None`:
    /// that mass is one number per row (the solver pools it).
    pub links: Option<u32>,
    /// With `links`: a cluster is opened into its two halves while the spread of the
    /// kernel over it (an estimate of the mass a link to it would misplace) exceeds
    /// this fraction of the row's total.
    pub link_tol: f64,
}

/// Most links a sparse row carries in every preset.
pub const DEFAULT_LINKS: u32 = 256;
/// Default link tolerance ([`FormFactorConfig::link_tol`]).
pub const DEFAULT_LINK_TOL: f64 = 1e-3;

/// How `contour` finds what the occluders take away from a pair that may be occluded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Visibility {
    /// A kernel-weighted ratio estimate from `samples` stratified rays
    /// ([`visibility`]).
    #[default]
    Rays,
    /// The shadows clipped from the receiver and integrated ([`shadow`]), for pairs
    /// with few enough candidate occluders; the others as `Rays`.
    Exact,
}

impl Visibility {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Visibility::Rays => "rays",
            Visibility::Exact => "exact",
        }
    }
}

/// Top-k rows of the `contour` method: candidates are visited in decreasing order of
/// their unoccluded value F⁰_ij, an upper bound of the occluded value. Once F⁰ falls
/// below the k-th largest final value found so far, no later candidate can enter the
/// top k, so their rays are needed only for the dropped mass (docs/numerics.md §8, §9).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TopKTail {
    /// Cast their rays anyway: `dropped` is the same as for a dense row.
    Exact,
    /// Estimate Σ F⁰_j V_j over the tail pairs that need rays from this many of them,
    /// drawn with probability ∝ F⁰_j (systematic sampling, seeded by (i, seed)):
    /// unbiased, with an error of order (tail mass)/√samples. The kept entries are
    /// exactly those of `Exact`; only `dropped` differs.
    Sampled(u32),
}

/// How a top-k row of the `contour` method finds its candidates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TopKSearch {
    /// F⁰_ij of every column j, then visibility in decreasing F⁰ until the bound stops
    /// (work ∝ n per row).
    Exhaustive,
    /// Best-first over a hierarchy of the patches (`tree`): nodes are opened in
    /// decreasing bound on their F⁰ and only while that bound can still enter the top
    /// k; the dropped mass of unopened nodes is sampled through the tree. The kept
    /// entries are bitwise those of `Exhaustive`; needs a sampled tail.
    #[default]
    Tree,
}

impl TopKSearch {
    pub(crate) fn name(self) -> &'static str {
        match self {
            TopKSearch::Exhaustive => "exhaustive",
            TopKSearch::Tree => "tree",
        }
    }
}

impl fmt::Display for TopKTail {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TopKTail::Exact => f.write_str("exact"),
            TopKTail::Sampled(t) => write!(f, "sampled:{t}"),
        }
    }
}

/// How the dropped mass of sparse rows is found ([`RowEngine::dropped_mass`]), as
/// the file header records it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DroppedMassRoute {
    /// Every column evaluated: the exhaustive search with an exact tail, or a baseline
    /// kernel.
    Exact,
    /// The row's total estimated (`total`) from `points` sampled points, the dropped
    /// mass being what the kept entries leave of it; with the tree search and links,
    /// the most links and their split tolerance.
    Estimated {
        total: RowTotal,
        points: u32,
        links: Option<(u32, f64)>,
    },
}

/// Where an estimated row total comes from ([`DroppedMassRoute::Estimated`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowTotal {
    /// Hemisphere rays against the patches' own occluders (tree search).
    Hemisphere,
    /// The tree walk's own estimate (tree search with a foreign occluder mesh, or none).
    TreeWalk,
    /// Points sampled in proportion to the unoccluded values (exhaustive search).
    Sampled,
}

impl FormFactorConfig {
    /// Cheapest settings: unoccluded part to ~1e-6 relative, 4 visibility rays, top-k
    /// tail mass sampled at 128 points.
    pub fn fast() -> Self {
        FormFactorConfig {
            method: Method::Contour,
            samples: 4,
            first_batch: 4,
            seed: 0,
            top_k: None,
            top_k_tail: TopKTail::Sampled(128),
            top_k_search: TopKSearch::Tree,
            min_ff: None,
            quad_order: 6,
            quad_tol: 1e-6,
            visibility: Visibility::Rays,
            shadow_tol: 1e-2,
            links: Some(DEFAULT_LINKS),
            link_tol: DEFAULT_LINK_TOL,
        }
    }

    /// The default: unoccluded part to ~1e-8 relative (below the f32 storage
    /// resolution), 16 visibility rays for every pair that may be occluded. No early
    /// stop (first batch = samples): the early stop's bias (see [`visibility`]) cost
    /// 1.3e-4 on the obstructed plates and up to 2e-2 on row sums next to the room's
    /// boxes; casting all 16 rays costs ~30% more time on the Cornell box and gives
    /// 6e-6 on the obstructed plates (bench/RESULTS.md).
    pub fn accurate() -> Self {
        FormFactorConfig {
            method: Method::Contour,
            samples: 16,
            first_batch: 16,
            seed: 0,
            top_k: None,
            top_k_tail: TopKTail::Sampled(256),
            top_k_search: TopKSearch::Tree,
            min_ff: None,
            quad_order: 8,
            quad_tol: 1e-8,
            visibility: Visibility::Rays,
            shadow_tol: 1e-3,
            links: Some(DEFAULT_LINKS),
            link_tol: DEFAULT_LINK_TOL,
        }
    }

    /// For reference solutions: quadrature near machine precision, exact visibility to
    /// 1e-6 of each entry's unoccluded value (largest entry error 2.3e-8 on the Cornell
    /// box at 2k patches, about 1000 times the CPU of `accurate`: bench/PERF.md §14),
    /// and 256 rays (no early stop) for the pairs it leaves to rays.
    pub fn reference() -> Self {
        FormFactorConfig {
            method: Method::Contour,
            samples: 256,
            first_batch: 256,
            seed: 0,
            top_k: None,
            top_k_tail: TopKTail::Exact,
            top_k_search: TopKSearch::Exhaustive,
            min_ff: None,
            quad_order: 16,
            quad_tol: 1e-13,
            visibility: Visibility::Exact,
            shadow_tol: 1e-6,
            links: Some(DEFAULT_LINKS),
            link_tol: DEFAULT_LINK_TOL,
        }
    }

    /// The settings of `preset`.
    pub fn preset(preset: Preset) -> Self {
        match preset {
            Preset::Fast => Self::fast(),
            Preset::Accurate => Self::accurate(),
            Preset::Reference => Self::reference(),
        }
    }

    /// Every preset, with its name (tests run all of them).
    pub fn presets() -> [(&'static str, FormFactorConfig); 3] {
        Preset::ALL.map(|p| (p.name(), Self::preset(p)))
    }

    pub fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// `samples` rays for every pair that may be occluded, all of them cast (first
    /// batch = samples: no early stop). Keeping the preset's first batch would stop a
    /// pair after its first 16 rays when they agree, which biases partly hidden pairs
    /// the more the more hidden they are (a pair 1 % visible came out 88 % low with
    /// 4,096 rays); [`FormFactorConfig::with_first_batch`] asks for the stop.
    pub fn with_samples(mut self, samples: u32) -> Self {
        self.samples = samples;
        self.first_batch = samples;
        self
    }

    /// Stop a pair after a first batch of `first_batch` rays when they all agree (see
    /// [`visibility`]); biased, cheaper.
    pub fn with_first_batch(mut self, first_batch: u32) -> Self {
        self.first_batch = first_batch;
        self
    }

    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    pub fn with_top_k(mut self, top_k: Option<u32>) -> Self {
        self.top_k = top_k;
        self
    }

    /// Threshold rows: keep only the entries ≥ `min_ff`.
    pub fn with_min_ff(mut self, min_ff: Option<f64>) -> Self {
        self.min_ff = min_ff;
        self
    }

    /// Whether rows are sparse (top-k, threshold or both) rather than dense.
    pub fn sparse_rows(&self) -> bool {
        self.top_k.is_some() || self.min_ff.is_some()
    }

    /// Checks the ranges of every field.
    ///
    /// # Errors
    /// [`FormFactorError::InvalidConfig`] naming the offending field.
    pub fn validate(&self) -> Result<(), FormFactorError> {
        let bad = |m: String| Err(FormFactorError::InvalidConfig(m));
        if !(1..=MAX_SAMPLES).contains(&self.samples) {
            return bad(format!(
                "samples {} outside 1..={MAX_SAMPLES}",
                self.samples
            ));
        }
        if !(1..=MAX_SAMPLES).contains(&self.first_batch) {
            return bad(format!(
                "first_batch {} outside 1..={MAX_SAMPLES}",
                self.first_batch
            ));
        }
        if !(1..=quadrature::MAX_ORDER as u32).contains(&self.quad_order) {
            return bad(format!(
                "quad_order {} outside 1..={}",
                self.quad_order,
                quadrature::MAX_ORDER
            ));
        }
        if !(self.quad_tol > 0.0 && self.quad_tol <= 0.1) {
            return bad(format!("quad_tol {} outside (0, 0.1]", self.quad_tol));
        }
        if self.top_k == Some(0) {
            return bad("top_k must be at least 1".into());
        }
        if let Some(eps) = self.min_ff {
            if !(eps > 0.0 && eps < 1.0) {
                return bad(format!("min_ff {eps} outside (0, 1)"));
            }
        }
        if !(self.shadow_tol > 0.0 && self.shadow_tol <= 0.1) {
            return bad(format!("shadow_tol {} outside (0, 0.1]", self.shadow_tol));
        }
        if self.links == Some(0) {
            return bad("links must be at least 1 (or none)".into());
        }
        if !(self.link_tol > 0.0 && self.link_tol <= 1.0) {
            return bad(format!("link_tol {} outside (0, 1]", self.link_tol));
        }
        if self.top_k_tail == TopKTail::Sampled(0) {
            return bad("top_k_tail sample count must be at least 1".into());
        }
        if self.top_k_search == TopKSearch::Tree && self.top_k_tail == TopKTail::Exact {
            return bad(
                "top_k_search tree estimates the dropped mass: it needs a sampled top_k_tail \
                 (an exact tail evaluates every column; use the exhaustive search)"
                    .into(),
            );
        }
        Ok(())
    }

    /// Whether sparse rows are found by the tree search (which links need).
    pub(crate) fn searches_tree(&self) -> bool {
        self.sparse_rows()
            && self.method == Method::Contour
            && self.top_k_search == TopKSearch::Tree
            && matches!(self.top_k_tail, TopKTail::Sampled(_))
    }

    /// Whether the rows carry links to clusters (spec §5.7).
    pub fn links_rows(&self) -> bool {
        self.searches_tree() && self.links.is_some()
    }

    pub(crate) fn contour_params(&self) -> contour::ContourParams {
        contour::ContourParams {
            max_order: self.quad_order as usize,
            tol: self.quad_tol,
        }
    }
}

impl Default for FormFactorConfig {
    fn default() -> Self {
        Self::accurate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate() {
        for (_, cfg) in FormFactorConfig::presets() {
            cfg.validate().unwrap();
        }
        assert_eq!(
            FormFactorConfig::preset(Preset::default()),
            FormFactorConfig::default()
        );
        assert!(FormFactorConfig::default()
            .with_samples(0)
            .validate()
            .is_err());
        let c = FormFactorConfig {
            quad_order: 99,
            ..Default::default()
        };
        assert!(c.validate().is_err());
        assert!(FormFactorConfig::default()
            .with_top_k(Some(0))
            .validate()
            .is_err());
    }
}
