//! Tests of the writer: rows buffered by a dropped writer survive for a resume, route
//! counts survive a resume and add up, and an I/O error names the path.

use super::*;
use crate::ffz::FfzReader;
use crate::patch::{Patch, PatchSet};

fn meta(n: u32) -> FileMeta {
    let p = Patch {
        corners: [
            glam::DVec3::ZERO,
            glam::DVec3::X,
            glam::DVec3::Y,
            glam::DVec3::ZERO,
        ],
        n_corners: 3,
        normal: glam::DVec3::Z,
        area: 0.5,
        group: 0,
        face: 0,
        rho: [0.5; 3],
        emission: [0.0; 3],
    };
    let patches = PatchSet {
        patches: vec![p; n as usize],
        groups: vec!["g".into()],
    };
    FileMeta {
        layout: Layout::Dense,
        method: "point".into(),
        params: String::new(),
        scene_hash: patches.content_hash(),
        created: String::new(),
        patches,
        clusters: None,
    }
}

#[test]
fn dropped_writer_keeps_buffered_rows_for_resume() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.ffz");
    let m = meta(3);
    let opts = WriterOptions {
        fsync: false,
        ..Default::default()
    };
    let mut w = FfzWriter::create(&path, &m, opts).unwrap();
    w.push_row(Row::dense(1, vec![0.25, 0.0, 0.5])).unwrap();
    assert_eq!(
        w.stats().chunks,
        0,
        "1 MiB chunks: the row is still buffered"
    );
    drop(w); // an error path: no finish
    let r = FfzReader::open(&path).unwrap();
    assert!(!r.is_indexed());
    assert_eq!(r.row(1).unwrap(), Some(Row::dense(1, vec![0.25, 0.0, 0.5])));
    assert_eq!(r.presence().missing(), vec![0, 2]);
    drop(r);
    let (w, presence) = FfzWriter::resume(&path, &m, opts).unwrap();
    assert_eq!(presence.missing(), vec![0, 2]);
    let st = w.finish().unwrap();
    assert_eq!((st.rows, st.chunks), (1, 1));
    assert_eq!(st.bytes_on_disk, std::fs::metadata(&path).unwrap().len());
}

/// The route record (spec §6.1): written only when a run counted something, read
/// back, added to by a resume, and lost (not guessed) when a scan rebuilds the
/// index.
#[test]
fn route_counts_survive_a_resume_and_add_up() {
    use crate::ffz::{PairRoutes, StoredRoutes};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.ffz");
    let m = meta(3);
    let opts = WriterOptions {
        fsync: false,
        ..Default::default()
    };
    let counts = |rows: u64, evaluated: u64, exact: u64| StoredRoutes {
        rows,
        pairs: PairRoutes {
            evaluated,
            unoccludable: 1,
            exact,
            exact_points: 100 * exact,
            ..Default::default()
        },
    };
    // No counts: no record, the index as before.
    let mut w = FfzWriter::create(&path, &m, opts).unwrap();
    w.push_row(Row::dense(0, vec![0.0, 0.5, 0.25])).unwrap();
    let plain = w.finish().unwrap().bytes_on_disk;
    assert_eq!(FfzReader::open(&path).unwrap().routes(), None);
    // A run that counted its row.
    let mut w = FfzWriter::create(&path, &m, opts).unwrap();
    w.push_row(Row::dense(0, vec![0.0, 0.5, 0.25])).unwrap();
    w.add_routes(&counts(1, 2, 1));
    let with = w.finish().unwrap().bytes_on_disk;
    assert_eq!(with, plain + super::super::spec::ROUTES_LEN as u64);
    let r = FfzReader::open(&path).unwrap();
    assert!(
        r.is_indexed() && r.warnings().is_empty(),
        "{:?}",
        r.warnings()
    );
    assert_eq!(r.routes(), Some(&counts(1, 2, 1)));
    drop(r);
    // A resume adds the rows it computes.
    let (mut w, present) = FfzWriter::resume(&path, &m, opts).unwrap();
    assert_eq!(present.present_count(), 1);
    w.push_row(Row::dense(1, vec![0.5, 0.0, 0.25])).unwrap();
    w.push_row(Row::dense(2, vec![0.25, 0.25, 0.0])).unwrap();
    w.add_routes(&counts(2, 4, 2));
    w.finish().unwrap();
    let r = FfzReader::open(&path).unwrap();
    let want = StoredRoutes {
        rows: 3,
        pairs: PairRoutes {
            evaluated: 6,
            unoccludable: 2,
            exact: 3,
            exact_points: 300,
            ..Default::default()
        },
    };
    assert_eq!(r.routes(), Some(&want));
    drop(r);
    // Cut the footer off: the scan finds the rows, and no counts.
    let len = std::fs::metadata(&path).unwrap().len();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len - 1).unwrap();
    drop(f);
    let r = FfzReader::open(&path).unwrap();
    assert!(!r.is_indexed());
    assert_eq!(r.presence().present_count(), 3);
    assert_eq!(r.routes(), None);
}

#[test]
fn io_error_names_the_path() {
    // /dev/full accepts the open and fails every write with ENOSPC.
    let path = Path::new("/dev/full");
    assert!(
        path.exists(),
        "this test needs /dev/full (every Linux has it)"
    );
    let e = FfzWriter::create(path, &meta(2), WriterOptions::default())
        .err()
        .unwrap();
    let msg = e.to_string();
    assert!(
        msg.contains("/dev/full") && msg.contains("write header"),
        "{msg}"
    );
}
