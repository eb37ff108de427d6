//! [`RowSource`] for the `.ffz` reader: the solver reads a file row by row through
//! its memory map, never loading the matrix.
//!

use crate::ffz::FfzReader;
use crate::patch::PatchSet;
use crate::rows::Row;

use super::error::SolveError;
use super::source::RowSource;

impl RowSource for FfzReader {
    fn patches(&self) -> &PatchSet {
        &self.meta().patches
    }

    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError> {
        // The first error of the solver's callback is kept and returned after the scan;
        // later rows are passed over without work. (If the reader's scan can stop
        // early on a callback error, stop it instead.)
        let mut failed: Option<SolveError> = None;
        FfzReader::scan(self, |row: &Row| {
            if failed.is_none() {
                if let Err(e) = f(row) {
                    failed = Some(e);
                }
            }
        })
        .map_err(SolveError::source_error)?;
        match failed {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    fn row(&self, i: u32) -> Result<Option<Row>, SolveError> {
        FfzReader::row(self, i).map_err(SolveError::source_error)
    }

    fn has_row(&self, i: u32) -> bool {
        self.presence().get(i) != crate::ffz::RowState::Missing
    }

    fn may_drop(&self) -> bool {
        self.layout() != crate::ffz::Layout::Dense
    }

    fn cluster_order(&self) -> Option<&[u32]> {
        self.meta().clusters.as_deref()
    }
}
