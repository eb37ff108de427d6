//! Which rows a file holds: present, skipped on purpose, or missing (spec §6 row table).

/// State of one row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RowState {
    /// Not in the file (not computed yet, or lost in a crash).
    Missing,
    /// Stored with its values.
    Present,
    /// Deliberately not computed (`RowValues::Skipped`): a gathering solve does not need it.
    Skipped,
}

/// Per-row state of a file, one byte per row (memory O(n)).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RowPresence {
    states: Vec<RowState>,
    present: u64,
    skipped: u64,
}

impl RowPresence {
    /// All `n` rows missing.
    pub(crate) fn new(n: u32) -> Self {
        RowPresence {
            states: vec![RowState::Missing; n as usize],
            present: 0,
            skipped: 0,
        }
    }

    /// State of row `i`; `Missing` for `i >= n`.
    pub fn get(&self, i: u32) -> RowState {
        self.states
            .get(i as usize)
            .copied()
            .unwrap_or(RowState::Missing)
    }

    /// Set the state of row `i` (ignored for `i >= n`), keeping the counts right.
    pub(crate) fn set(&mut self, i: u32, state: RowState) {
        let Some(s) = self.states.get_mut(i as usize) else {
            return;
        };
        match *s {
            RowState::Present => self.present -= 1,
            RowState::Skipped => self.skipped -= 1,
            RowState::Missing => {}
        }
        match state {
            RowState::Present => self.present += 1,
            RowState::Skipped => self.skipped += 1,
            RowState::Missing => {}
        }
        *s = state;
    }

    /// Rows stored with values.
    pub fn present_count(&self) -> u64 {
        self.present
    }

    /// Rows skipped on purpose.
    pub fn skipped_count(&self) -> u64 {
        self.skipped
    }

    /// Rows not in the file.
    pub fn missing_count(&self) -> u64 {
        self.states.len() as u64 - self.present - self.skipped
    }

    /// True when no row is missing.
    pub fn is_complete(&self) -> bool {
        self.missing_count() == 0
    }

    /// Ids of the missing rows, ascending: what a resumed run must compute.
    pub fn missing(&self) -> Vec<u32> {
        self.ids(RowState::Missing)
    }

    /// Ids of the rows in `state`, ascending.
    pub(crate) fn ids(&self, state: RowState) -> Vec<u32> {
        (0..self.states.len() as u32)
            .filter(|&i| self.states[i as usize] == state)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_follow_state_changes() {
        let mut p = RowPresence::new(5);
        assert_eq!(p.missing(), vec![0, 1, 2, 3, 4]);
        p.set(1, RowState::Present);
        p.set(3, RowState::Skipped);
        p.set(3, RowState::Present);
        p.set(9, RowState::Present); // out of range: ignored
        assert_eq!(
            (p.present_count(), p.skipped_count(), p.missing_count()),
            (2, 0, 3)
        );
        assert_eq!(p.missing(), vec![0, 2, 4]);
        assert_eq!(p.get(9), RowState::Missing);
        assert!(!p.is_complete());
    }
}
