//! How the pairs of a run got their visibility (spec §6.1): the counts `compute`
//! reports at its end and the index of the file keeps, so that `ffstream info` can
//! say it later, added up over the runs that wrote the file (`--resume`).

use super::spec::{self, record_len, Le};

/// How many evaluated pairs got their visibility which way (from the row engine's
/// [`Counters`](crate::formfactor::Counters), summed over a worker's threads, then
/// over the workers).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairRoutes {
    /// Pairs whose kernel was evaluated.
    pub evaluated: u64,
    /// Of those, pairs no occluder can come between: no visibility work at all.
    pub unoccludable: u64,
    /// Pairs whose blocked part was clipped exactly (`--visibility exact`).
    pub exact: u64,
    /// Pairs meant for exact visibility that went to rays.
    pub fallback: u64,
    /// Pairs whose visibility rays estimated (the fallbacks included).
    pub rays: u64,
    /// Of the exact pairs, those proven fully visible: no outer points.
    pub exact_visible: u64,
    /// Of the exact pairs, those proven fully hidden: no outer points.
    pub exact_hidden: u64,
    /// Outer points the other (partly shadowed) exact pairs took, together.
    pub exact_points: u64,
    /// Of the partly shadowed exact pairs, those whose outer rule stopped (at its most
    /// points or deepest refinement) before its error estimate met `--shadow-tol`
    /// (kept by the route record when not 0, spec §6.1).
    pub exact_unmet: u64,
}

/// Counts of [`PairRoutes`] that every route record keeps: all but `exact_unmet`, which
/// follows them when the index has [`spec::INDEX_FLAG_ROUTES_UNMET`].
const RECORD_WORDS: usize = 8;

impl PairRoutes {
    pub(crate) fn of(c: &crate::formfactor::Counters) -> Self {
        PairRoutes {
            evaluated: c.pairs_evaluated,
            unoccludable: c.pairs_unoccludable,
            exact: c.pairs_exact,
            fallback: c.pairs_exact_fallback,
            rays: c.pairs_rays,
            exact_visible: c.pairs_exact_visible,
            exact_hidden: c.pairs_exact_hidden,
            exact_points: c.exact_points,
            exact_unmet: c.pairs_exact_unmet,
        }
    }

    /// The nine counts in the order of MPI's DONE message; the route record keeps the
    /// first [`RECORD_WORDS`].
    pub(crate) fn to_words(self) -> [u64; 9] {
        [
            self.evaluated,
            self.unoccludable,
            self.exact,
            self.fallback,
            self.rays,
            self.exact_visible,
            self.exact_hidden,
            self.exact_points,
            self.exact_unmet,
        ]
    }

    /// [`PairRoutes::to_words`] read back.
    pub(crate) fn from_words(w: [u64; 9]) -> Self {
        let [evaluated, unoccludable, exact, fallback, rays, exact_visible, exact_hidden, exact_points, exact_unmet] =
            w;
        PairRoutes {
            evaluated,
            unoccludable,
            exact,
            fallback,
            rays,
            exact_visible,
            exact_hidden,
            exact_points,
            exact_unmet,
        }
    }

    pub(crate) fn add(&mut self, o: &PairRoutes) {
        let (a, b) = (self.to_words(), o.to_words());
        *self = Self::from_words(std::array::from_fn(|k| a[k] + b[k]));
    }

    /// Evaluated pairs whose visibility neither route worked out because their
    /// unoccluded value alone decided them: it came out 0 (a sliver of a clipped
    /// pair), or in top-k rows it kept them out of the row (a sampled tail needs no
    /// visibility for them).
    pub(crate) fn undecided(&self) -> u64 {
        self.evaluated
            .saturating_sub(self.unoccludable)
            .saturating_sub(self.exact)
            .saturating_sub(self.rays)
    }

    /// One line for the report.
    pub(crate) fn summary(&self) -> String {
        let share = |x: u64| 100.0 * x as f64 / self.evaluated.max(1) as f64;
        let mut line = format!(
            "pairs: {} evaluated; visibility: {} ({:.1}%) need none, {} ({:.1}%) exact, {} ({:.1}%) by rays ({} of them fell back from exact)",
            self.evaluated,
            self.unoccludable,
            share(self.unoccludable),
            self.exact,
            share(self.exact),
            self.rays,
            share(self.rays),
            self.fallback
        );
        let rest = self.undecided();
        if rest > 0 {
            line += &format!(
                ", {rest} ({:.1}%) decided by their unoccluded value alone (0, or too small for a top-k row)",
                share(rest)
            );
        }
        if self.exact > 0 {
            // Where the exact route's time goes: the shortcuts cost no outer points,
            // the partly shadowed pairs cost their points (each a cut of j by every
            // candidate's shadow).
            let partly = self
                .exact
                .saturating_sub(self.exact_visible)
                .saturating_sub(self.exact_hidden);
            line += &format!(
                "; of the exact: {} fully visible, {} fully hidden, {partly} partly shadowed ({:.1} outer points each on average)",
                self.exact_visible,
                self.exact_hidden,
                self.exact_points as f64 / partly.max(1) as f64
            );
        }
        if self.exact_unmet > 0 {
            line += &format!(
                "; {} partly shadowed pair(s) did not reach --shadow-tol (the outer rule ran out of points or depth first: their values are its best estimates, not within the tolerance)",
                self.exact_unmet
            );
        }
        line
    }
}

/// The route counts an index keeps (spec §6.1): [`PairRoutes`] over the pairs of
/// `rows` rows, those computed by the runs that finished the file (a run that was
/// killed, or a worker that failed, leaves its rows present but not counted).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoredRoutes {
    /// Rows (half rows with `--symmetric`) whose pairs are counted.
    pub rows: u64,
    pub pairs: PairRoutes,
}

impl StoredRoutes {
    pub(crate) fn add(&mut self, o: &StoredRoutes) {
        self.rows += o.rows;
        self.pairs.add(&o.pairs);
    }

    /// The index flags this record needs: [`spec::INDEX_FLAG_ROUTES`], and
    /// [`spec::INDEX_FLAG_ROUTES_UNMET`] when some pair was short of its tolerance.
    pub(crate) fn flags(&self) -> u32 {
        if self.pairs.exact_unmet > 0 {
            spec::INDEX_FLAG_ROUTES | spec::INDEX_FLAG_ROUTES_UNMET
        } else {
            spec::INDEX_FLAG_ROUTES
        }
    }

    /// The record's bytes, [`record_len`]`(self.flags())` of them.
    pub(crate) fn encode(&self) -> Vec<u8> {
        let pairs = self.pairs.to_words();
        let words = std::iter::once(self.rows).chain(pairs[..RECORD_WORDS].iter().copied());
        let unmet = (self.pairs.exact_unmet > 0).then_some(self.pairs.exact_unmet);
        words.chain(unmet).flat_map(|v| v.to_le_bytes()).collect()
    }

    /// The record at the reader's position, checked: counts that cannot hold together
    /// (more routed pairs than evaluated ones, more rows than the file has) make the
    /// index unusable, as any other damage does. Err: the byte offset inside the
    /// record and the reason.
    /// `flags`: the index's, which say whether the tenth count is there.
    pub(crate) fn decode(r: &mut Le<'_>, n: u32, flags: u32) -> Result<Self, (usize, String)> {
        let mut v = [0u64; 10];
        for (k, x) in v.iter_mut().take(record_len(flags) / 8).enumerate() {
            *x = r
                .u64()
                .ok_or((8 * k, "route record cut short".to_string()))?;
        }
        let [rows, pairs @ ..] = v;
        let s = StoredRoutes {
            rows,
            pairs: PairRoutes::from_words(pairs),
        };
        let p = s.pairs;
        let routed = p
            .unoccludable
            .checked_add(p.exact)
            .and_then(|x| x.checked_add(p.rays));
        if rows > u64::from(n) {
            return Err((
                0,
                format!("route record counts {rows} rows, the file has {n}"),
            ));
        }
        if routed.is_none_or(|x| x > p.evaluated) {
            return Err((
                8,
                format!(
                    "route record: {} + {} + {} routed pairs exceed the {} evaluated",
                    p.unoccludable, p.exact, p.rays, p.evaluated
                ),
            ));
        }
        let proven = p.exact_visible.checked_add(p.exact_hidden);
        if p.fallback > p.rays || proven.is_none_or(|x| x > p.exact) {
            return Err((
                32,
                "route record: fallbacks above the rays' pairs, or proven pairs above the exact ones".into(),
            ));
        }
        let partly = proven.map(|x| p.exact - x);
        if flags & spec::INDEX_FLAG_ROUTES_UNMET != 0
            && (p.exact_unmet == 0 || partly.is_none_or(|x| p.exact_unmet > x))
        {
            return Err((
                72,
                format!(
                    "route record: {} pairs short of the tolerance, of {} partly shadowed",
                    p.exact_unmet,
                    partly.unwrap_or(0)
                ),
            ));
        }
        Ok(s)
    }
}

/// Drops a route record a resume kept that counts more rows than the file holds
/// (`present`), returning a note for the run's warnings. Such a record cannot be added
/// to: with the rows of the resume it would pass n and every reader would refuse the
/// index. Runs before issue 48, item 4 wrote them (a half-row run that lost a worker
/// counted the half rows of blocks never merged); the rows they miscounted are in the
/// file, uncounted, as after any run that did not finish.
pub(crate) fn drop_overcount(
    kept: &mut Option<StoredRoutes>,
    present: &super::RowPresence,
) -> Option<String> {
    let have = present.present_count();
    let r = kept.take_if(|r| r.rows > have)?;
    Some(format!(
        "the file's pair-count record counted {} rows of the {have} present (a run that lost some of its half rows wrote it): dropped; the rows this run computes are counted afresh",
        r.rows
    ))
}

/// The route record the index gets: none when it would count more rows than the file
/// holds (`present`). Runs count only rows they wrote (a caller bug otherwise, hence
/// the assertion), but an index that every reader refuses is the worse outcome for a
/// file of sound rows, so a release build leaves the record out instead.
pub(crate) fn to_write<'a>(
    r: Option<&'a StoredRoutes>,
    present: &super::RowPresence,
) -> Option<&'a StoredRoutes> {
    let have = present.present_count();
    let r = r?;
    debug_assert!(
        r.rows <= have,
        "route record of {} rows, {have} present",
        r.rows
    );
    (r.rows <= have).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> StoredRoutes {
        StoredRoutes {
            rows: 7,
            pairs: PairRoutes {
                evaluated: 100,
                unoccludable: 30,
                exact: 50,
                fallback: 2,
                rays: 15,
                exact_visible: 5,
                exact_hidden: 20,
                exact_points: 12_345,
                exact_unmet: 0,
            },
        }
    }

    #[test]
    fn a_route_record_reads_back_and_impossible_counts_are_refused() {
        let s = sample();
        let f = s.flags();
        assert_eq!(f, spec::INDEX_FLAG_ROUTES);
        let bytes = s.encode();
        assert_eq!(bytes.len(), record_len(f));
        assert_eq!(StoredRoutes::decode(&mut Le::new(&bytes), 10, f), Ok(s));
        // More rows than the file has.
        assert!(StoredRoutes::decode(&mut Le::new(&bytes), 6, f).is_err());
        // More routed pairs than evaluated, fallbacks above rays, proven above exact.
        for (field, value) in [(1, 90u64), (4, 16), (7, 46)] {
            let mut b = bytes.clone();
            b[8 * field..8 * field + 8].copy_from_slice(&value.to_le_bytes());
            assert!(
                StoredRoutes::decode(&mut Le::new(&b), 10, f).is_err(),
                "field {field}"
            );
        }
        assert!(StoredRoutes::decode(&mut Le::new(&bytes[..70]), 10, f).is_err());
    }

    /// Pairs short of the tolerance make the record ten counts long, with the flag
    /// that says so; the count must be among the partly shadowed pairs (50 exact, 25
    /// of them proven: 25), and not 0 when flagged.
    #[test]
    fn the_pairs_short_of_the_tolerance_take_a_tenth_count() {
        let mut s = sample();
        s.pairs.exact_unmet = 3;
        let f = s.flags();
        assert_eq!(f, spec::INDEX_FLAG_ROUTES | spec::INDEX_FLAG_ROUTES_UNMET);
        let bytes = s.encode();
        assert_eq!(bytes.len(), 80);
        assert_eq!(StoredRoutes::decode(&mut Le::new(&bytes), 10, f), Ok(s));
        for bad in [0u64, 26] {
            let mut b = bytes.clone();
            b[72..80].copy_from_slice(&bad.to_le_bytes());
            assert!(
                StoredRoutes::decode(&mut Le::new(&b), 10, f).is_err(),
                "{bad}"
            );
        }
        assert!(StoredRoutes::decode(&mut Le::new(&bytes[..75]), 10, f).is_err());
        // Read without the flag, the record is the first nine counts.
        let mut nine = s;
        nine.pairs.exact_unmet = 0;
        assert_eq!(
            StoredRoutes::decode(&mut Le::new(&bytes[..72]), 10, spec::INDEX_FLAG_ROUTES),
            Ok(nine)
        );
    }

    /// A kept record that counts more rows than the file holds (what a half-row run
    /// that lost a worker wrote before issue 48, item 4: 2,831 of 748) is dropped with
    /// a note; one within the rows present is kept; `to_write` leaves out one above.
    #[test]
    fn a_record_counting_more_rows_than_present_is_dropped_not_added_to() {
        let mut present = crate::ffz::RowPresence::new(10);
        for i in 0..7 {
            present.set(i, crate::ffz::RowState::Present);
        }
        let mut kept = Some(sample());
        assert_eq!(drop_overcount(&mut kept, &present), None);
        assert_eq!(kept, Some(sample()));
        assert_eq!(to_write(kept.as_ref(), &present), Some(&sample()));
        present.set(6, crate::ffz::RowState::Missing);
        let note = drop_overcount(&mut kept, &present).expect("a note");
        assert!(note.contains("counted 7 rows of the 6 present"), "{note}");
        assert_eq!(kept, None);
    }
}
