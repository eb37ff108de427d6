//! Building a job from its settings ([`build_job`]): the scene loaded and checked, the
//! plan said and checked against the disk, the patches, the occluders (loaded, merged,
//! hashed), the row engine, the file header with its run parameters. Every MPI rank
//! builds its own job this way; its [`Role`] decides what it builds and says.

use std::path::Path;
use std::sync::Arc;

use crate::ffz::FileMeta;
use crate::formfactor::{FormFactorConfig, RowEngine};
use crate::geometry::merge::OccluderMesh;
use crate::geometry::subdivide::{default_max_edge, patch_count, subdivide};
use crate::patch::PatchSet;
use crate::scene::{self, Scene};
use crate::service::{ComputeJob, Role};

use super::params::{EngineParams, RunParams};
use super::plan::Plan;
use super::settings::{layout_of, JobSettings, PatchBudget};
use super::{JobError, MAX_PATCHES};

/// Builds the job `s` asks for, as `role` needs it (the I/O master's has no engine);
/// what was chosen is said through `say` (by every role but a worker's).
///
/// # Errors
/// [`JobError`]: settings that do not go together (refused before the scene is read),
/// a scene that does not load or, with `strict`, has warnings, too many patches or
/// none, a file the disk cannot hold, an occluder mesh that does not load.
pub fn build_job(s: &JobSettings, role: Role, say: &dyn Fn(&str)) -> Result<ComputeJob, JobError> {
    // The settings first: a refused option costs no scene loading.
    s.check_gather()?;
    let cfg = s.form.config(s.half_rows)?;
    let setup_start = std::time::Instant::now();
    let scene = tracing::info_span!("load_scene").in_scope(|| s.scene.open())?;
    let announce = role.announces();
    for w in scene_warnings(&scene, s.strict, s.daylight)? {
        if announce {
            say(&format!("ffstream: warning: {w}"));
        }
    }
    let symmetric = s.half_rows(&cfg)?;
    let threads = s.threads_or_all();
    let (count, max_edge) = patch_budget(s.scene.as_str(), s.budget, &scene)?;
    if announce {
        // Said and checked before subdividing: a file the disk cannot hold costs no
        // subdivision.
        Plan {
            scene: s.scene.as_str(),
            output: &s.output,
            n: count as u64,
            faces: scene.faces.len() as u64,
            target: match s.budget {
                PatchBudget::Target(n) => Some(n as u64),
                PatchBudget::MaxEdge(_) => None,
            },
            layout: layout_of(&cfg, count),
            threshold: cfg.min_ff,
            symmetric,
            threads: threads as u64,
            chunk_bytes: s.writer.chunk_bytes as u64,
            occluder_triangles: scene.triangles().count() as u64,
            resume: s.resume,
            no_space_check: !s.space_check,
        }
        .check(say)?;
    }
    let patches = subdivided(s, &scene, max_edge, announce, say)?;
    let (engine, engine_params, occluders) = engine_for(role, s, &scene, &patches, &cfg, say)?;
    let took = setup_start.elapsed().as_secs_f64();
    match role {
        // Every process that computes does this set-up itself; this is its cost
        // (docs/cluster.md §2: why ranks load the scene rather than receive it).
        Role::Alone => say(&format!(
            "ffstream: set-up (load, subdivide, Bvh, engine) took {took:.3} s"
        )),
        Role::Master => say(&format!(
            "ffstream: set-up of rank 0 (load, subdivide) took {took:.3} s; it builds no \
             Bvh or engine, every worker builds its own"
        )),
        Role::Worker(_) => {}
    }
    let params = RunParams {
        version: RunParams::VERSION,
        engine: engine_params,
        occluders_merged: occluders.merged,
        occluders_hash: occluders.hash,
        max_edge,
        scene_path: s.scene.as_str().to_string(),
        // Half rows give (slightly) different numbers from full rows, so a resume
        // must use the same mode: the header says which one.
        half_rows: symmetric,
        occluders_path: s
            .occluders
            .as_ref()
            .map(|p| p.to_string_lossy().into_owned()),
        unknown: Vec::new(),
    };
    let meta = FileMeta {
        layout: layout_of(&cfg, patches.len()),
        method: cfg.method.to_string(),
        params: params.to_string(),
        scene_hash: patches.content_hash(),
        created: creation_info(),
        patches: (*patches).clone(),
        clusters: match symmetric {
            true => None,
            false => RowEngine::cluster_order_of(&patches, &cfg),
        },
    };
    Ok(ComputeJob {
        output: s.output.clone(),
        meta,
        patches,
        engine,
        resume: s.resume,
        overwrite: s.overwrite,
        schedule: s.schedule,
        symmetric,
        rows: s.rows,
        threads,
        writer: s.writer,
        flush_seconds: s.flush_seconds,
        progress: s.progress,
        stall_seconds: s.stall_seconds,
    })
}

/// The scene's load warnings that matter for how it is lit (`daylight`: no emitter
/// is no fault), to be said; under `strict` the first is an error instead.
///
/// # Errors
/// [`JobError::Refused`] under `strict` when there is a warning.
pub fn scene_warnings(
    scene: &Scene,
    strict: bool,
    daylight: bool,
) -> Result<Vec<&String>, JobError> {
    let warnings: Vec<&String> = scene.warnings_for(daylight).collect();
    if let (true, Some(first)) = (strict, warnings.first()) {
        let more = match warnings.len() - 1 {
            0 => String::new(),
            m => format!(" (and {m} more warning(s))"),
        };
        return Err(JobError::Refused(format!(
            "--strict refuses this scene: {first}{more}"
        )));
    }
    Ok(warnings)
}

/// The edge (given, or the one that gives about the target count) and the number of
/// patches it makes, refused before anything is allocated when there would be too
/// many.
fn patch_budget(name: &str, budget: PatchBudget, scene: &Scene) -> Result<(usize, f64), JobError> {
    let max_edge = match budget {
        PatchBudget::MaxEdge(e) => e,
        PatchBudget::Target(n) => default_max_edge(scene, n),
    };
    // Refuse before allocating: a tiny edge (or a huge target) would otherwise abort on
    // a failed allocation instead of giving an error.
    let count = patch_count(scene, max_edge);
    if count > MAX_PATCHES {
        return Err(JobError::Refused(format!(
            "{name}: max edge {max_edge:e} gives {count} patches, more than the {MAX_PATCHES} \
             supported (row ids are 32-bit and the patch table is held in memory); \
             use a larger --max-edge or a smaller --patches"
        )));
    }
    Ok((count, max_edge))
}

/// The patches of the scene at `max_edge` (said when `announce`); an error when there
/// are none.
fn subdivided(
    s: &JobSettings,
    scene: &Scene,
    max_edge: f64,
    announce: bool,
    say: &dyn Fn(&str),
) -> Result<Arc<PatchSet>, JobError> {
    let patches =
        Arc::new(tracing::info_span!("subdivide").in_scope(|| subdivide(scene, max_edge)));
    if announce {
        let how = match s.budget {
            PatchBudget::MaxEdge(_) => "given",
            PatchBudget::Target(_) => "chosen for about --patches",
        };
        // Six decimals as always, but never the 309 digits of 1.8e308.
        let edge = match max_edge {
            e if (1e-4..1e6).contains(&e) => format!("{e:.6}"),
            e => crate::brief_number(e),
        };
        say(&format!(
            "ffstream: {} faces -> {} patches (max edge {edge} scene units, {how})",
            scene.faces.len(),
            patches.len()
        ));
    }
    if patches.is_empty() {
        return Err(JobError::Refused(format!(
            "{}: the scene has no patches",
            s.scene
        )));
    }
    Ok(patches)
}

/// What the header records of the occluders beside the engine's parameters.
struct OccluderNote {
    /// Triangles left after merging, when planes were merged.
    merged: Option<usize>,
    /// XXH3-64 of a foreign mesh's triangles.
    hash: Option<u64>,
}

/// The row engine of a process that computes (none for the I/O master, which only
/// needs the header's parameters), its parameters and the occluders' note.
fn engine_for(
    role: Role,
    s: &JobSettings,
    scene: &Scene,
    patches: &PatchSet,
    cfg: &FormFactorConfig,
    say: &dyn Fn(&str),
) -> Result<(Option<Arc<RowEngine>>, EngineParams, OccluderNote), JobError> {
    let announce = role.announces();
    let occluder_triangles: Vec<_> = match &s.occluders {
        Some(path) => scene::load_file(path, scene::SceneFormat::of_path(path))?
            .triangles()
            .collect(),
        None => scene.triangles().collect(),
    };
    // A foreign occluder mesh is not in the scene hash: its content goes into the
    // header (a resume compares it; where it was read from it does not).
    let hash = s
        .occluders
        .as_ref()
        .map(|_| triangles_hash(&occluder_triangles));
    // Coplanar triangles merged (they then belong to no one face: foreign); the header
    // keeps the count as given and records the merged count beside it.
    let mesh = tracing::info_span!("merge_occluders").in_scope(|| {
        OccluderMesh::prepare(occluder_triangles, s.occluders.is_some(), s.merge_occluders)
    });
    if let (Some((groups, kept)), true) = (mesh.merged, announce) {
        say(&format!(
            "ffstream: occluders: {} triangles, those of {groups} planes merged: {kept} \
             triangles block the same (--no-merge-occluders keeps them as given)",
            mesh.given
        ));
    }
    let params = EngineParams::new(cfg, mesh.given, mesh.other_mesh);
    let note = OccluderNote {
        merged: mesh.merged.map(|(_, kept)| kept),
        hash,
    };
    if role == Role::Master {
        return Ok((None, params, note));
    }
    let occluders = Arc::new(tracing::info_span!("build_bvh").in_scope(|| mesh.build()));
    let engine = tracing::info_span!("prepare_engine")
        .in_scope(|| RowEngine::with_threads(patches, occluders, cfg.clone(), s.threads_or_all()));
    // Under mpirun rank 0 builds no engine: the first worker says it (every rank
    // finds the same solids in the same scene).
    let who = match role {
        Role::Worker(1) => "rank 1: ",
        _ => "",
    };
    if let (Some(took), true) = (
        engine.links_setup_seconds(),
        announce || role == Role::Worker(1),
    ) {
        say(&format!(
            "ffstream: {who}links: their set-up (mostly the first-bounce radiosity that \
             steers them) took {took:.3} s of the set-up"
        ));
    }
    if let (Some((solids, triangles)), true) =
        (engine.solids_found(), announce || role == Role::Worker(1))
    {
        say(&format!(
            "ffstream: {who}exact visibility: {solids} convex solids ({triangles} occluder \
             triangles) cast their shadows whole"
        ));
    }
    Ok((Some(Arc::new(engine)), params, note))
}

/// XXH3-64 of triangles (their ids and the bits of their coordinates, in order).
fn triangles_hash(triangles: &[(u32, [glam::DVec3; 3])]) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    for (id, t) in triangles {
        h.update(&id.to_le_bytes());
        for c in t.iter().flat_map(|v| v.to_array()) {
            h.update(&c.to_bits().to_le_bytes());
        }
    }
    h.digest()
}

/// "ffstream VERSION, YYYY-MM-DD HH:MM:SS UTC, host HOST": for the file header.
fn creation_info() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let (year, month, day) = crate::daylight::sun::civil_from_days(days);
    let host = std::fs::read_to_string(Path::new("/etc/hostname"))
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    format!(
        "ffstream {}, {year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC, host {}",
        env!("CARGO_PKG_VERSION"),
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        if host.is_empty() { "unknown" } else { &host }
    )
}
