//! The fixed choices of the command line, as clap value enums: a misspelt value is a
//! usage error (exit 2) that lists the possible values, given before any scene is
//! loaded, and `--help` lists them with what each means. Each maps onto the library's
//! own type (the library never sees clap).

use ffstream::formfactor::{Method, Preset, TopKSearch, TopKTail, Visibility};
use ffstream::job::HalfRows;
use ffstream::scene::SceneFormat;
use ffstream::service::{RowSelection, Schedule};
use ffstream::solve::{DroppedMass, SolveMethod};

/// A clap value enum and its conversion into the library type it stands for.
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $name:ident => $lib:ty {
            $( $(#[$vmeta:meta])* $variant:ident => $value:expr ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
        pub enum $name {
            $( $(#[$vmeta])* $variant ),+
        }

        impl From<$name> for $lib {
            fn from(choice: $name) -> Self {
                match choice {
                    $( $name::$variant => $value ),+
                }
            }
        }
    };
}

choice! {
    /// `--format`: the scene file's format when its extension does not say it.
    FormatArg => SceneFormat {
        /// Wavefront OBJ with its MTL materials.
        Obj => SceneFormat::Obj,
        /// STL, ASCII or binary; materials from NAME.mtl beside it.
        Stl => SceneFormat::Stl,
        /// PLY, ASCII or binary; materials from NAME.mtl beside it.
        Ply => SceneFormat::Ply,
        /// glTF 2.0 (.gltf with its buffers, or .glb).
        Gltf => SceneFormat::Gltf,
    }
}

impl FormatArg {
    /// The prefix of a scene spec that names this format (`stl:PATH`).
    pub(crate) fn prefix(self) -> &'static str {
        match self {
            FormatArg::Obj => "obj",
            FormatArg::Stl => "stl",
            FormatArg::Ply => "ply",
            FormatArg::Gltf => "gltf",
        }
    }
}

choice! {
    /// `--preset`: named settings of the form-factor computation.
    PresetArg => Preset {
        /// 4 visibility rays, quadrature to 1e-6, sampled top-k tail.
        Fast => Preset::Fast,
        /// 16 rays for every pair that can be occluded, quadrature to 1e-8 (default).
        Accurate => Preset::Accurate,
        /// Exact visibility to 1e-6 of each entry (256 rays for pairs it leaves to rays),
        /// quadrature near machine precision; ~1000x the CPU of accurate with occluders.
        Reference => Preset::Reference,
    }
}

choice! {
    /// `--method` of compute and run: the form-factor kernel.
    MethodArg => Method {
        /// Centroid-to-centroid kernel and one ray (the paper's baseline).
        Point => Method::Point,
        /// Stratified area-to-area Monte Carlo with --samples point pairs.
        Mc => Method::Mc,
        /// Exact unoccluded double contour integral times a kernel-weighted visibility.
        Contour => Method::Contour,
    }
}

choice! {
    /// `--schedule`: how rows are dealt to workers.
    ScheduleArg => Schedule {
        /// Workers ask for batches that shrink toward the end (default).
        Dynamic => Schedule::Dynamic,
        /// The paper's static assignment: rows i and n-1-i dealt together.
        Folded => Schedule::Folded,
    }
}

choice! {
    /// `--rows`: which rows a run computes.
    RowsArg => RowSelection {
        /// Every row.
        All => RowSelection::All,
        /// Skip rows of patches that neither reflect nor emit (marked skipped).
        Needed => RowSelection::Needed,
    }
}

choice! {
    /// `--solver`: the iterative method of solve and run.
    SolverArg => SolveMethod {
        /// Gauss–Seidel sweeps in file order (default).
        GaussSeidel => SolveMethod::GaussSeidel,
        /// Jacobi sweeps in file order.
        Jacobi => SolveMethod::Jacobi,
        /// Progressive refinement: random row access, reciprocity.
        Shooting => SolveMethod::Shooting,
    }
}

choice! {
    /// `--dropped-mass`: what the solve does with the light top-k rows left out.
    DroppedArg => DroppedMass {
        /// Pool it and share it among the receivers in proportion to what each row
        /// dropped: power is conserved (default).
        Pool => DroppedMass::Pool,
        /// Scale each row's kept entries up to its true sum (rows sum right, columns
        /// do not: power is not conserved).
        Scale => DroppedMass::Scale,
        /// Use the kept entries as stored: the dropped light is absorbed.
        Absorb => DroppedMass::Absorb,
    }
}

choice! {
    /// `--symmetric`: whether each unordered pair is computed once (half rows).
    SymmetricArg => HalfRows {
        /// On for dense files with --method contour, off otherwise.
        Auto => HalfRows::Auto,
        /// Half rows: each unordered pair once, the other direction by reciprocity.
        On => HalfRows::On,
        /// Full rows: every row on its own.
        Off => HalfRows::Off,
    }
}

choice! {
    /// `--visibility`: how `contour` finds what the occluders take from a pair.
    VisibilityArg => Visibility {
        /// A kernel-weighted estimate from --samples stratified rays.
        Rays => Visibility::Rays,
        /// The shadows clipped from the receiver and integrated (pairs with few
        /// candidate occluders; the others by rays).
        Exact => Visibility::Exact,
    }
}

choice! {
    /// `--top-k-search`: how a top-k row finds its largest entries.
    TopKSearchArg => TopKSearch {
        /// Best-first over a hierarchy of the patches: only nodes whose bound can still
        /// enter the top k are opened; the dropped mass of the others is sampled
        /// (default of fast and accurate).
        Tree => TopKSearch::Tree,
        /// Every column's unoccluded value first (work grows as n per row; default of
        /// reference).
        Exhaustive => TopKSearch::Exhaustive,
    }
}

/// `--top-k-tail`: `exact` or a sample count 1 to 65536.
pub(crate) fn top_k_tail(s: &str) -> Result<TopKTail, String> {
    match s.trim() {
        "exact" => Ok(TopKTail::Exact),
        n => match n.parse::<u32>() {
            Ok(t) if (1..=1 << 16).contains(&t) => Ok(TopKTail::Sampled(t)),
            _ => Err(format!(
                "`{s}` is neither `exact` nor a sample count 1 to 65536"
            )),
        },
    }
}

/// Numbers with a range, as clap value parsers: a value outside it is a usage error
/// (exit 2, before any scene is loaded) that states the range. Integers use clap's
/// ranged parsers (`value_parser!(u32).range(..)`); these are the real-valued ones.
pub(crate) mod number {
    fn real(s: &str) -> Result<f64, String> {
        s.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{s}` is not a number"))
    }

    /// A finite number > 0.
    pub(crate) fn positive(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x.is_finite() && x > 0.0 => Ok(x),
            x => Err(format!(
                "{} is not a finite number > 0",
                ffstream::brief_number(x)
            )),
        }
    }

    /// A finite number ≥ 0.
    pub(crate) fn non_negative(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x.is_finite() && x >= 0.0 => Ok(x),
            x => Err(format!(
                "{} is not a finite number ≥ 0",
                ffstream::brief_number(x)
            )),
        }
    }

    /// A finite number.
    pub(crate) fn finite(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x.is_finite() => Ok(x),
            x => Err(format!(
                "{} is not a finite number",
                ffstream::brief_number(x)
            )),
        }
    }

    /// Longest duration an option takes, in seconds: about 31.7 years. Far above any
    /// run, and far below the 1.8e19 s where turning a number of seconds into a
    /// `Duration` panics.
    pub(crate) const MAX_SECONDS: f64 = 1e9;

    /// A duration in seconds: a finite number ≥ 0, at most [`MAX_SECONDS`].
    pub(crate) fn seconds(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if (0.0..=MAX_SECONDS).contains(&x) => Ok(x),
            x => Err(format!(
                "{} is not a duration from 0 to {MAX_SECONDS:e} s",
                ffstream::brief_number(x)
            )),
        }
    }

    /// A duration in seconds > 0, at most [`MAX_SECONDS`].
    pub(crate) fn positive_seconds(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x > 0.0 && x <= MAX_SECONDS => Ok(x),
            x => Err(format!(
                "{} is not a duration > 0 and at most {MAX_SECONDS:e} s",
                ffstream::brief_number(x)
            )),
        }
    }

    /// A tolerance: a number in (0, 0.1].
    pub(crate) fn tolerance(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x > 0.0 && x <= 0.1 => Ok(x),
            x => Err(format!("{} is outside (0, 0.1]", ffstream::brief_number(x))),
        }
    }

    /// A number in (0, 1): a relative residual, a threshold.
    pub(crate) fn open_unit(s: &str) -> Result<f64, String> {
        match real(s)? {
            x if x > 0.0 && x < 1.0 => Ok(x),
            x => Err(format!("{} is outside (0, 1)", ffstream::brief_number(x))),
        }
    }
}
