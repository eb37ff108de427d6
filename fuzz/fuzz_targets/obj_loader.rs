//! The OBJ/MTL loader on arbitrary text: the input is the OBJ file; next to it is
//! the bad-input corpus's `common.mtl` (materials `white`, `light`). Ok or Err are both
//! fine; a loaded scene must be valid and subdivide; a crash is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

const MTL: &str = "newmtl white\nKd 0.5 0.5 0.5\n\nnewmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n";

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("ffstream-fuzz-obj-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join("common.mtl"), MTL);
    let path = dir.join("input.obj");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(s) = ffstream::scene::load_obj(&path) {
        assert_eq!(s.validate(), Ok(()));
        let e = ffstream::geometry::subdivide::default_max_edge(&s, 50);
        assert!(ffstream::geometry::subdivide::patch_count(&s, e) >= s.faces.len());
    }
});
