//! The fixed choices of the command line, as clap value enums: a misspelt value is a
//! usage error (exit 2) that lists the possible values, given before any scene is
//! loaded, and `--help` lists them with what each means. Each maps onto the library's
//! own type (the library never sees clap).

use ffstream::formfactor::{Method, Preset, Visibility};
use ffstream::service::{RowSelection, Schedule};
use ffstream::solve::SolveMethod;

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

/// `--symmetric`: whether each unordered pair is computed once (half rows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SymmetricArg {
    /// On for dense files with --method contour, off otherwise.
    Auto,
    /// Half rows: each unordered pair once, the other direction by reciprocity.
    On,
    /// Full rows: every row on its own.
    Off,
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
