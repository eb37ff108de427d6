//! The `.ffz` reader on arbitrary bytes: open (header checks, index or recovery scan),
//! then every row, a scan, verify and compare. Any result is fine; a crash is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The reader maps files: give it one (one per process, reused per input).
    let dir = std::env::temp_dir().join(format!("ffstream-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join("input.ffz");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(rd) = ffstream::ffz::FfzReader::open(&path) {
        for i in 0..rd.n().min(4096) {
            let _ = rd.row(i);
        }
        let _ = rd.scan(|_| {});
        let _ = rd.verify().ok();
        let _ = ffstream::ffz::compare(&rd, &rd, Default::default());
    }
});
