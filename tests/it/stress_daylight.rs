//! Stress, bad or unusual input to `ffstream annual` (issue 48): a southern site on the
//! command line, weather files that are not a plain year, sensor sets too large for
//! memory or whose names clash, and the exit codes of usage mistakes.

use crate::common::{ffstream, path_str};
use crate::stress_cli::assert_no_panic;

/// `--location -33.9,18.4,2` (Cape Town) was read by clap as the option `-3`
/// ("unexpected argument '-3'"): a negative latitude must reach the site check. The
/// run stops later, at the missing grid group, which proves the location was read;
/// `-95,...` is refused by the site check itself, naming the latitude.
#[test]
fn a_southern_latitude_is_a_value_not_an_option() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let base = [
        "annual",
        "builtin:office",
        "--grid",
        "no_such_group:1",
        "-o",
        path_str(&out),
        "--location",
    ];
    let mut a = base.to_vec();
    a.push("-33.9,18.4,2");
    let o = ffstream(&a);
    assert_no_panic(&o, "--location -33.9,18.4,2");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!stderr.contains("unexpected argument"), "{stderr}");
    assert!(stderr.contains("no_such_group"), "{stderr}");
    let mut a = base.to_vec();
    a.push("-95,18.4,2");
    let o = ffstream(&a);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("latitude"), "{stderr}");
}
