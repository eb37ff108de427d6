//! The header's run parameters (spec §3.2) as one typed, versioned structure:
//! [`RunParams`], with the engine's part in [`EngineParams`]. It writes itself as the
//! params string of the file header (through the format's [`ParamList`]), reads
//! itself back from one, and says how a file's params differ from its own the way a
//! resume refuses them (spec §9.2).
//!
//! Version 1 is the key set below, in this order; it writes no version key, so the
//! headers are those every earlier release wrote. A later version that changes what a
//! key means writes `params_version=N` first. A resume compares settings as the
//! format does ([`ParamList::difference`]), so a file of any version is judged by the
//! keys it holds, unknown ones included.

use crate::ffz::params::{decode_value, ParamList};
use crate::formfactor::{
    DroppedMassRoute, FormFactorConfig, Method, RowEngine, RowTotal, TopKSearch, TopKTail,
    Visibility,
};
use crate::geometry::occluders::RAY_EPSILON;

use super::JobError;

/// Everything of the engine that changes the numbers, as the header records it.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineParams {
    pub method: Method,
    pub visibility: Visibility,
    pub shadow_tol: f64,
    pub samples: u32,
    pub first_batch: u32,
    pub seed: u64,
    pub top_k: Option<u32>,
    pub top_k_tail: TopKTail,
    pub top_k_search: TopKSearch,
    pub min_ff: Option<f64>,
    pub quad_order: u32,
    pub quad_tol: f64,
    /// The occluders' relative ray offset (a constant of the build).
    pub ray_epsilon: f64,
    /// Occluder triangles as given (before any merge).
    pub occluder_triangles: usize,
    /// Sparse rows: how their dropped mass is found.
    pub dropped_mass: Option<DroppedMassRoute>,
}

impl EngineParams {
    /// The parameters of an engine with `cfg` over that many occluder triangles, from
    /// another mesh than the patches' (`other_mesh`) or not, without building it.
    pub fn new(cfg: &FormFactorConfig, occluder_triangles: usize, other_mesh: bool) -> Self {
        EngineParams {
            method: cfg.method,
            visibility: cfg.visibility,
            shadow_tol: cfg.shadow_tol,
            samples: cfg.samples,
            first_batch: cfg.first_batch,
            seed: cfg.seed,
            top_k: cfg.top_k,
            top_k_tail: cfg.top_k_tail,
            top_k_search: cfg.top_k_search,
            min_ff: cfg.min_ff,
            quad_order: cfg.quad_order,
            quad_tol: cfg.quad_tol,
            ray_epsilon: RAY_EPSILON,
            occluder_triangles,
            dropped_mass: RowEngine::dropped_mass(cfg, occluder_triangles, other_mesh),
        }
    }

    /// The parameters of a built engine, its occluders counted as built (after any
    /// merge: a job's header counts them as given, see `build_job`).
    pub fn of_engine(engine: &RowEngine) -> Self {
        let (cfg, triangles, other_mesh) = engine.header_inputs();
        Self::new(cfg, triangles, other_mesh)
    }

    /// Adds the engine's keys to `list`, in the header's order.
    fn write(&self, list: &mut ParamList) {
        let none_or = |v: Option<String>| v.unwrap_or_else(|| "none".into());
        list.push("method", self.method);
        list.push("visibility", self.visibility.name());
        list.push("shadow_tol", format!("{:e}", self.shadow_tol));
        list.push("samples", self.samples);
        list.push("first_batch", self.first_batch);
        list.push("seed", self.seed);
        list.push("top_k", none_or(self.top_k.map(|k| k.to_string())));
        list.push("top_k_tail", self.top_k_tail);
        list.push("top_k_search", self.top_k_search.name());
        list.push("min_ff", none_or(self.min_ff.map(|e| format!("{e:e}"))));
        list.push("quad_order", self.quad_order);
        list.push("quad_tol", format!("{:e}", self.quad_tol));
        list.push("ray_epsilon", format!("{:e}", self.ray_epsilon));
        list.push("occluder_triangles", self.occluder_triangles);
        match self.dropped_mass {
            None => {}
            Some(DroppedMassRoute::Exact) => list.push("dropped_mass", "exact"),
            Some(DroppedMassRoute::Estimated {
                total,
                points,
                links,
            }) => {
                list.push("dropped_mass", format!("{}:{points}", total_name(total)));
                if let Some((most, tol)) = links {
                    list.push("links", most);
                    list.push("link_tol", format!("{tol:e}"));
                }
            }
        }
    }

    /// The engine's keys of `list`.
    fn read(list: &Fields) -> Result<Self, JobError> {
        let dropped_mass = match list.get("dropped_mass") {
            None => None,
            Some("exact") => Some(DroppedMassRoute::Exact),
            Some(v) => {
                let (total, points) = v.split_once(':').ok_or_else(|| list.bad("dropped_mass"))?;
                let total = [RowTotal::Hemisphere, RowTotal::TreeWalk, RowTotal::Sampled]
                    .into_iter()
                    .find(|t| total_name(*t) == total)
                    .ok_or_else(|| list.bad("dropped_mass"))?;
                let links = match list.get("links") {
                    Some(_) => Some((list.number("links")?, list.number("link_tol")?)),
                    None => None,
                };
                Some(DroppedMassRoute::Estimated {
                    total,
                    points: points.parse().map_err(|_| list.bad("dropped_mass"))?,
                    links,
                })
            }
        };
        Ok(EngineParams {
            method: list.named("method", &Method::ALL, |m| m.as_str())?,
            visibility: list.named("visibility", &[Visibility::Rays, Visibility::Exact], |v| {
                v.name()
            })?,
            shadow_tol: list.number("shadow_tol")?,
            samples: list.number("samples")?,
            first_batch: list.number("first_batch")?,
            seed: list.number("seed")?,
            top_k: list.optional("top_k")?,
            top_k_tail: match list.required("top_k_tail")? {
                "exact" => TopKTail::Exact,
                v => TopKTail::Sampled(
                    v.strip_prefix("sampled:")
                        .and_then(|t| t.parse().ok())
                        .ok_or_else(|| list.bad("top_k_tail"))?,
                ),
            },
            top_k_search: list.named(
                "top_k_search",
                &[TopKSearch::Tree, TopKSearch::Exhaustive],
                |s| s.name(),
            )?,
            min_ff: list.optional("min_ff")?,
            quad_order: list.number("quad_order")?,
            quad_tol: list.number("quad_tol")?,
            ray_epsilon: list.number("ray_epsilon")?,
            occluder_triangles: list.number("occluder_triangles")?,
            dropped_mass,
        })
    }
}

impl std::fmt::Display for EngineParams {
    /// The engine's part of the params string (what `ffstream compute` writes before
    /// `occluders_merged=` or `max_edge=`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut list = ParamList::default();
        self.write(&mut list);
        list.fmt(f)
    }
}

/// The header's name of a row total's route.
fn total_name(t: RowTotal) -> &'static str {
    match t {
        RowTotal::Hemisphere => "hemisphere",
        RowTotal::TreeWalk => "tree-walk",
        RowTotal::Sampled => "sampled",
    }
}

/// The run parameters of a file header: the engine's, the occluders', the patches'
/// edge, the scene, the row mode (full or half rows).
#[derive(Clone, Debug, PartialEq)]
pub struct RunParams {
    /// The key set's version ([`RunParams::VERSION`] for what this build writes).
    pub version: u32,
    pub engine: EngineParams,
    /// Occluder triangles left after the coplanar ones were merged, when any were.
    pub occluders_merged: Option<usize>,
    /// `--occluders`: XXH3-64 of the foreign mesh's triangles (its content; where it
    /// was read from is `occluders_path`).
    pub occluders_hash: Option<u64>,
    /// The longest patch edge the scene was subdivided with.
    pub max_edge: f64,
    /// The scene as named (for information: the scene hash stands for its content).
    pub scene_path: String,
    /// Half rows mirrored by reciprocity (`pairs=half`): slightly other numbers than
    /// full rows, so a resume must keep the mode.
    pub half_rows: bool,
    /// `--occluders`: the mesh as named (for information).
    pub occluders_path: Option<String>,
    /// Keys of a parsed string that this version does not know, in their order.
    pub unknown: Vec<(String, String)>,
}

impl RunParams {
    /// The version of the key set this build writes.
    pub const VERSION: u32 = 1;

    /// The params as the format's settings list, in the header's order.
    pub fn to_list(&self) -> ParamList {
        let mut list = ParamList::default();
        if self.version != 1 {
            list.push("params_version", self.version);
        }
        self.engine.write(&mut list);
        if let Some(kept) = self.occluders_merged {
            list.push("occluders_merged", kept);
        }
        if let Some(h) = self.occluders_hash {
            list.push("occluders_hash", format!("{h:#018x}"));
        }
        list.push("max_edge", self.max_edge);
        list.push_encoded("scene_path", &self.scene_path);
        if self.half_rows {
            list.push("pairs", "half");
        }
        if let Some(p) = &self.occluders_path {
            list.push_encoded("occluders_path", p);
        }
        for (k, v) in &self.unknown {
            list.push(k, v);
        }
        list
    }

    /// Reads a params string written by this version (or an earlier one with the same
    /// keys); keys it does not know are kept in [`RunParams::unknown`].
    ///
    /// # Errors
    /// [`JobError::Params`] naming a key that is missing or whose value does not read,
    /// or a version this build does not know.
    pub fn parse(params: &str) -> Result<Self, JobError> {
        let list = Fields(ParamList::parse(params));
        let version = list.optional("params_version")?.unwrap_or(1);
        if version != Self::VERSION {
            return Err(JobError::Params(format!(
                "params version {version}: this build reads version {}",
                Self::VERSION
            )));
        }
        let known = KEYS;
        Ok(RunParams {
            version,
            engine: EngineParams::read(&list)?,
            occluders_merged: list.optional("occluders_merged")?,
            occluders_hash: match list.get("occluders_hash") {
                Some(h) => Some(
                    h.strip_prefix("0x")
                        .and_then(|h| u64::from_str_radix(h, 16).ok())
                        .ok_or_else(|| list.bad("occluders_hash"))?,
                ),
                None => None,
            },
            max_edge: list.number("max_edge")?,
            scene_path: decode_value(list.required("scene_path")?),
            half_rows: match list.get("pairs") {
                None => false,
                Some("half") => true,
                Some(_) => return Err(list.bad("pairs")),
            },
            occluders_path: list.get("occluders_path").map(decode_value),
            unknown: list
                .0
                .iter()
                .filter(|(k, _)| !known.contains(k))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        })
    }

    /// Why a file whose header has `file_params` cannot be resumed by a run with these
    /// parameters: the first setting that differs (keys ending in `_path` excepted),
    /// said as the writer's resume check says it; None when they agree.
    pub fn difference_from_file(&self, file_params: &str) -> Option<String> {
        ParamList::parse(file_params).difference(&self.to_list())
    }
}

impl std::fmt::Display for RunParams {
    /// The params string of the file header.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.to_list().fmt(f)
    }
}

/// Every key version 1 writes.
const KEYS: [&str; 24] = [
    "params_version",
    "method",
    "visibility",
    "shadow_tol",
    "samples",
    "first_batch",
    "seed",
    "top_k",
    "top_k_tail",
    "top_k_search",
    "min_ff",
    "quad_order",
    "quad_tol",
    "ray_epsilon",
    "occluder_triangles",
    "dropped_mass",
    "links",
    "link_tol",
    "occluders_merged",
    "occluders_hash",
    "max_edge",
    "scene_path",
    "pairs",
    "occluders_path",
];

/// A parsed list read key by key, each failure naming its key.
struct Fields(ParamList);

impl Fields {
    fn get(&self, key: &str) -> Option<&str> {
        self.0.get(key)
    }

    fn bad(&self, key: &str) -> JobError {
        JobError::Params(match self.get(key) {
            Some(v) => format!("{key}={v} does not read"),
            None => format!("no {key}"),
        })
    }

    fn required(&self, key: &str) -> Result<&str, JobError> {
        self.get(key).ok_or_else(|| self.bad(key))
    }

    fn number<T: std::str::FromStr>(&self, key: &str) -> Result<T, JobError> {
        self.required(key)?.parse().map_err(|_| self.bad(key))
    }

    /// A number, or `none` (or no key) for None.
    fn optional<T: std::str::FromStr>(&self, key: &str) -> Result<Option<T>, JobError> {
        match self.get(key) {
            None | Some("none") => Ok(None),
            Some(_) => self.number(key).map(Some),
        }
    }

    /// The one of `all` whose `name` the key's value is.
    fn named<T: Copy>(
        &self,
        key: &str,
        all: &[T],
        name: fn(T) -> &'static str,
    ) -> Result<T, JobError> {
        let v = self.required(key)?;
        all.iter()
            .copied()
            .find(|x| name(*x) == v)
            .ok_or_else(|| self.bad(key))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(cfg: &FormFactorConfig) -> RunParams {
        RunParams {
            version: RunParams::VERSION,
            engine: EngineParams::new(cfg, 36, false),
            occluders_merged: Some(12),
            occluders_hash: None,
            max_edge: 0.1,
            scene_path: "builtin:cornell".into(),
            half_rows: false,
            occluders_path: None,
            unknown: Vec::new(),
        }
    }

    /// The string every release before the typed parameters wrote for this run (the
    /// accurate preset with top-k 12 on the Cornell box's 36 triangles, merged to 12).
    #[test]
    fn params_write_the_string_earlier_releases_wrote_and_read_it_back() {
        let cfg = FormFactorConfig::accurate().with_top_k(Some(12));
        let p = params(&cfg);
        let s = p.to_string();
        assert_eq!(
            s,
            "method=contour visibility=rays shadow_tol=1e-3 samples=16 first_batch=16 seed=0 \
             top_k=12 top_k_tail=sampled:256 top_k_search=tree min_ff=none quad_order=8 \
             quad_tol=1e-8 ray_epsilon=1e-6 occluder_triangles=36 \
             dropped_mass=hemisphere:256 links=256 link_tol=1e-3 occluders_merged=12 \
             max_edge=0.1 scene_path=builtin:cornell"
        );
        assert_eq!(RunParams::parse(&s).unwrap(), p);
        assert_eq!(p.difference_from_file(&s), None);
    }

    #[test]
    fn paths_are_encoded_unknown_keys_kept_and_differences_named() {
        let mut p = params(&FormFactorConfig::fast().with_min_ff(Some(1e-4)));
        p.half_rows = true;
        p.occluders_hash = Some(0xabc);
        p.occluders_path = Some("my dir/coarse.obj".into());
        let s = p.to_string();
        assert!(
            s.ends_with("occluders_hash=0x0000000000000abc max_edge=0.1 scene_path=builtin:cornell pairs=half occluders_path=my%20dir/coarse.obj"),
            "{s}"
        );
        assert_eq!(RunParams::parse(&s).unwrap(), p);
        let old = format!("{s} future_key=7");
        assert_eq!(
            RunParams::parse(&old).unwrap().unknown,
            vec![("future_key".to_string(), "7".to_string())]
        );
        assert_eq!(
            p.difference_from_file(&old).unwrap(),
            "the file was computed with future_key=7, this run has no future_key"
        );
        let mut q = p.clone();
        q.engine.seed = 3;
        assert_eq!(
            q.difference_from_file(&s).unwrap(),
            "seed differs: the file was computed with seed=0, this run has seed=3"
        );
        assert!(RunParams::parse("method=contour").is_err());
    }
}
