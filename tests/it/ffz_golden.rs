//! The worked example of `formats/ffz-v1.md` §11: the golden files
//! `formats/golden/tiny-v1.ffz` (top-k), `tiny-dense-v1.ffz` (dense) and
//! `tiny-links-v1.ffz` (top-k with a cluster order and links with slopes) decode to the
//! numbers the spec writes down, and their bytes are the spec's hex dumps.
//!
//! Regenerate deliberately (then paste the printed dumps into the spec):
//!     cargo test --no-default-features --test it ffz_golden::regenerate -- --ignored --nocapture

use ffstream::ffz::spec::{self, ChunkHeaderV1, HeaderV1, PatchRecordV1, RowDirEntryV1};
use ffstream::ffz::{encode_chunk, FfzReader, FfzWriter, FileMeta, Layout, WriterOptions};
use ffstream::patch::{Patch, PatchSet};
use ffstream::rows::{Link, Row, RowValues};
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn spec_text() -> String {
    std::fs::read_to_string(root().join("formats/ffz-v1.md")).unwrap()
}

/// Lines of the fenced block whose info string is `tag`.
fn block(spec: &str, tag: &str) -> Vec<String> {
    let open = format!("```{tag}");
    let mut lines = spec.lines().skip_while(|l| l.trim() != open);
    assert!(lines.next().is_some(), "spec has no ```{tag} block");
    lines
        .take_while(|l| l.trim() != "```")
        .map(str::to_string)
        .collect()
}

/// Bytes of a hex-dump block: `OFFSET | HEX BYTES | comment`, offsets continuous.
fn hex_bytes(lines: &[String]) -> Vec<u8> {
    let mut out = Vec::new();
    for l in lines {
        let parts: Vec<&str> = l.split('|').collect();
        if parts.len() < 2 {
            continue;
        }
        let off = u64::from_str_radix(parts[0].trim(), 16)
            .unwrap_or_else(|_| panic!("bad offset in {l:?}"));
        assert_eq!(off, out.len() as u64, "offset out of step at {l:?}");
        for b in parts[1].split_whitespace() {
            out.push(
                u8::from_str_radix(b, 16).unwrap_or_else(|_| panic!("bad byte {b:?} in {l:?}")),
            );
        }
    }
    out
}

/// Rows of a values block: `row I: skipped` | `row I: dense v v v` |
/// `row I: cols c c vals v v dropped d [links START+LEN:VALUE:QX,QY,QZ ...]`.
fn spec_rows(lines: &[String]) -> Vec<Row> {
    lines
        .iter()
        .filter(|l| l.starts_with("row "))
        .map(|l| {
            let (head, body) = l.split_once(':').unwrap();
            let index: u32 = head[4..].trim().parse().unwrap();
            let t: Vec<&str> = body.split_whitespace().collect();
            match t[0] {
                "skipped" => Row::skipped(index),
                "dense" => Row::dense(index, t[1..].iter().map(|x| x.parse().unwrap()).collect()),
                "cols" => {
                    let v = t.iter().position(|&x| x == "vals").unwrap();
                    let d = t.iter().position(|&x| x == "dropped").unwrap();
                    let links = match t.iter().position(|&x| x == "links") {
                        Some(k) => t[k + 1..].iter().map(|x| spec_link(x)).collect(),
                        None => Vec::new(),
                    };
                    Row {
                        index,
                        values: RowValues::Sparse {
                            cols: t[1..v].iter().map(|x| x.parse().unwrap()).collect(),
                            vals: t[v + 1..d].iter().map(|x| x.parse().unwrap()).collect(),
                        },
                        dropped: t[d + 1].parse().unwrap(),
                        links,
                        link_error: None,
                    }
                }
                other => panic!("unknown row kind {other}"),
            }
        })
        .collect()
}

/// A link of a values block: `START+LEN:VALUE:QX,QY,QZ`.
fn spec_link(x: &str) -> Link {
    let parts: Vec<&str> = x.split(':').collect();
    let (start, len) = parts[0].split_once('+').unwrap();
    let q: Vec<f32> = parts[2].split(',').map(|c| c.parse().unwrap()).collect();
    Link {
        start: start.parse().unwrap(),
        len: len.parse().unwrap(),
        value: parts[1].parse().unwrap(),
        slope: [q[0], q[1], q[2]],
    }
}

fn quad(c: [[f64; 3]; 4], normal: [f64; 3], group: u32, rho: f32, e: f32) -> Patch {
    Patch {
        corners: c.map(DVec3::from_array),
        n_corners: 4,
        normal: DVec3::from_array(normal),
        area: 1.0,
        group,
        face: group,
        rho: [rho; 3],
        emission: [e; 3],
    }
}

/// Which golden file.
#[derive(Clone, Copy, PartialEq)]
enum Example {
    TopK,
    Dense,
    Links,
}

/// The example scene: floor (ρ 0.5), an inert wall triangle (skipped row), a light.
fn example(kind: Example) -> (FileMeta, Vec<Vec<Row>>) {
    let floor = quad(
        [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
        [0., 0., 1.],
        0,
        0.5,
        0.0,
    );
    let light = quad(
        [[0., 0., 1.], [0., 1., 1.], [1., 1., 1.], [1., 0., 1.]],
        [0., 0., -1.],
        2,
        0.0,
        4.0,
    );
    let wall = Patch {
        corners: [[0., 0., 1.], [0., 0., 0.], [0., 1., 0.], [0., 0., 0.]].map(DVec3::from_array),
        n_corners: 3,
        normal: DVec3::X,
        area: 0.5,
        group: 1,
        face: 1,
        rho: [0.0; 3],
        emission: [0.0; 3],
    };
    let groups = vec!["floor".to_string(), "wall".to_string(), "light".to_string()];
    if kind == Example::Links {
        // Spec §11.3: cluster order 2, 0, 1; every row links what it does not keep.
        let patches = PatchSet {
            patches: vec![floor, wall, light],
            groups,
        };
        let link = |start, len, value, slope| Link {
            start,
            len,
            value,
            slope,
        };
        let row = |i, cols: Vec<u32>, vals: Vec<f32>, links: Vec<Link>| Row {
            index: i,
            values: RowValues::Sparse { cols, vals },
            dropped: links.iter().map(|l| l.value).sum(),
            links,
            link_error: None,
        };
        let chunks = vec![vec![
            row(0, vec![2], vec![0.5], vec![link(1, 2, 0.125, [0.0; 3])]),
            row(1, vec![], vec![], vec![link(0, 3, 0.5, [0.0, 0.0, 0.5])]),
            row(2, vec![0], vec![0.5], vec![link(1, 2, 0.125, [0.0; 3])]),
        ]];
        let mut m = meta(Layout::TopK { k: 1 }, patches);
        m.clusters = Some(vec![2, 0, 1]);
        return (m, chunks);
    }
    if kind == Example::TopK {
        let patches = PatchSet {
            patches: vec![floor, wall, light],
            groups,
        };
        let sparse = |i, cols: Vec<u32>, vals: Vec<f32>, dropped| Row {
            index: i,
            values: RowValues::Sparse { cols, vals },
            dropped,
            links: Vec::new(),
            link_error: None,
        };
        let chunks = vec![
            vec![sparse(2, vec![0], vec![0.5], 0.125), Row::skipped(1)],
            vec![sparse(0, vec![2], vec![0.5], 0.125)],
        ];
        (meta(Layout::TopK { k: 1 }, patches), chunks)
    } else {
        let mut light = light;
        light.group = 1;
        let patches = PatchSet {
            patches: vec![floor, light],
            groups: vec!["floor".into(), "light".into()],
        };
        let chunks = vec![vec![
            Row::dense(1, vec![0.5, 0.0]),
            Row::dense(0, vec![0.0, 0.5]),
        ]];
        (meta(Layout::Dense, patches), chunks)
    }
}

fn meta(layout: Layout, patches: PatchSet) -> FileMeta {
    FileMeta {
        layout,
        method: "point".into(),
        params: "golden".into(),
        scene_hash: patches.content_hash(),
        created: "2026-01-01T00:00:00Z ffstream golden example".into(),
        patches,
        clusters: None,
    }
}

fn golden(name: &str) -> PathBuf {
    root().join("formats/golden").join(name)
}

const FILES: [(&str, Example); 3] = [
    ("tiny-v1.ffz", Example::TopK),
    ("tiny-dense-v1.ffz", Example::Dense),
    ("tiny-links-v1.ffz", Example::Links),
];

#[test]
fn golden_files_decode_to_the_spec_numbers() {
    let spec = spec_text();
    for (name, _) in FILES {
        let path = golden(name);
        let rd = FfzReader::open(&path).unwrap();
        assert!(rd.warnings().is_empty(), "{:?}", rd.warnings());
        assert!(rd.verify().ok());
        let expect = spec_rows(&block(&spec, &format!("text golden-values:{name}")));
        assert_eq!(expect.len() as u32, rd.n(), "{name}: spec lists every row");
        for r in &expect {
            assert_eq!(
                rd.row(r.index).unwrap().as_ref(),
                Some(r),
                "{name} row {}",
                r.index
            );
        }
        // Patch areas and group names the spec states.
        let areas: Vec<f64> = rd.meta().patches.patches.iter().map(|p| p.area).collect();
        let groups = rd.meta().patches.groups.join(",");
        let facts = block(&spec, &format!("text golden-facts:{name}")).join("\n");
        assert!(
            facts.contains(&format!("areas {areas:?}")),
            "{name}: {facts}"
        );
        assert!(
            facts.contains(&format!("groups {groups}")),
            "{name}: {facts}"
        );
        assert!(
            facts.contains(&format!("layout {}", rd.layout())),
            "{name}: {facts}"
        );
    }
}

#[test]
fn golden_files_are_the_spec_hex_dumps() {
    let spec = spec_text();
    for (name, _) in FILES {
        let file = std::fs::read(golden(name)).unwrap();
        let dump = hex_bytes(&block(&spec, &format!("text golden-hex:{name}")));
        assert_eq!(dump, file, "{name}: spec hex dump and golden file differ");
        // And the decompressed payload of each chunk matches its dump.
        let rd = FfzReader::open(golden(name)).unwrap();
        for k in 0..rd.chunk_count() as u32 {
            let tag = format!("text golden-payload:{name}#{k}");
            let want = hex_bytes(&block(&spec, &tag));
            let (h, _) = rd.chunk_record(k).unwrap();
            let o = rd.chunk_offsets()[k as usize] as usize + spec::CHUNK_HEADER_LEN;
            let raw =
                zstd::bulk::decompress(&file[o..o + h.compressed_len as usize], h.raw_len as usize)
                    .unwrap();
            assert_eq!(raw, want, "{tag}");
        }
    }
}

/// The example is what `example()` builds (so a regeneration writes the same file).
#[test]
fn golden_files_hold_the_example() {
    for (name, kind) in FILES {
        let (m, chunks) = example(kind);
        let rd = FfzReader::open(golden(name)).unwrap();
        assert_eq!(rd.meta(), &m, "{name}");
        for c in chunks.iter().flatten() {
            assert_eq!(rd.row(c.index).unwrap().as_ref(), Some(c));
        }
    }
}

fn write_example(path: &Path, kind: Example) {
    let (m, chunks) = example(kind);
    let opts = WriterOptions {
        zstd_level: 1,
        chunk_bytes: 1 << 20,
        fsync: true,
    };
    let mut w = FfzWriter::create(path, &m, opts).unwrap();
    for c in chunks {
        w.append_chunk(encode_chunk(&c, m.layout, m.n(), 1).unwrap())
            .unwrap();
    }
    w.finish().unwrap();
}

/// One dump line per field: offset | bytes (16 per line at most) | meaning.
struct Dump {
    out: String,
    pos: usize,
}

impl Dump {
    fn field(&mut self, bytes: &[u8], what: &str) {
        for (k, piece) in bytes.chunks(16).enumerate() {
            let hex: Vec<String> = piece.iter().map(|b| format!("{b:02x}")).collect();
            let note = if k == 0 { what } else { "  ..." };
            writeln!(
                self.out,
                "{:06x} | {:<47} | {note}",
                self.pos,
                hex.join(" ")
            )
            .unwrap();
            self.pos += piece.len();
        }
    }
}

fn le32(b: &[u8]) -> u32 {
    u32::from_le_bytes(b[..4].try_into().unwrap())
}

fn dump_payload(raw: &[u8], rows: u32, shuffled: bool) -> String {
    let mut d = Dump {
        out: String::new(),
        pos: 0,
    };
    let mut entries = Vec::new();
    for k in 0..rows as usize {
        let e = RowDirEntryV1::decode(&raw[24 * k..]).unwrap();
        let b = &raw[24 * k..24 * k + 24];
        d.field(&b[0..4], &format!("dir[{k}].row = {}", e.row));
        let kind = match e.flags {
            0 => "dense",
            1 => "SKIPPED",
            2 => "SPARSE",
            14 => "SPARSE | LINKS | SLOPES",
            _ => "?",
        };
        d.field(&b[4..8], &format!("dir[{k}].flags = {} ({kind})", e.flags));
        d.field(&b[8..12], &format!("dir[{k}].nnz = {}", e.nnz));
        d.field(
            &b[12..16],
            &format!("dir[{k}].dropped = {} (f32)", e.dropped),
        );
        d.field(&b[16..24], &format!("dir[{k}].offset = {}", e.offset));
        entries.push(e);
    }
    let sh = if shuffled { ", byte-shuffled" } else { "" };
    for e in entries {
        let m = e.nnz as usize;
        let at = e.offset as usize;
        if e.flags & spec::ROW_FLAG_SKIPPED != 0 {
            continue;
        }
        if e.flags & spec::ROW_FLAG_SPARSE != 0 {
            d.field(
                &raw[at..at + 4 * m],
                &format!("row {}: {m} column deltas (u32{sh})", e.row),
            );
            d.field(
                &raw[at + 4 * m..at + 8 * m],
                &format!("row {}: {m} values (f32{sh})", e.row),
            );
            if e.flags & spec::ROW_FLAG_LINKS != 0 {
                let at = at + 8 * m;
                let l = le32(&raw[at..]) as usize;
                d.field(&raw[at..at + 4], &format!("row {}: §5.7 {l} links", e.row));
                let arrays = [
                    "start gaps",
                    "lengths",
                    "values",
                    "slopes x",
                    "slopes y",
                    "slopes z",
                ];
                for (k, what) in arrays.iter().enumerate() {
                    let o = at + 4 + 4 * l * k;
                    d.field(
                        &raw[o..o + 4 * l],
                        &format!("row {}: link {what}{sh}", e.row),
                    );
                }
            }
        } else {
            d.field(
                &raw[at..at + 4 * m],
                &format!("row {}: {m} values (f32{sh})", e.row),
            );
        }
    }
    d.out
}

fn dump_file(b: &[u8]) -> (String, Vec<String>) {
    let mut d = Dump {
        out: String::new(),
        pos: 0,
    };
    let h = HeaderV1::decode(b[..64].try_into().unwrap()).unwrap();
    d.field(&b[0..8], "§3.1 magic \\x89 F F Z \\r \\n \\x1a \\n");
    d.field(&b[8..12], "version = 1");
    let flags = le32(&b[12..]);
    d.field(
        &b[12..16],
        &format!(
            "flags = {flags}{}",
            if flags == 1 { " (CLUSTERS)" } else { "" }
        ),
    );
    d.field(&b[16..20], &format!("n = {}", h.n));
    d.field(
        &b[20..24],
        &format!(
            "layout = {} ({})",
            h.layout,
            if h.layout == 0 { "dense" } else { "top-k" }
        ),
    );
    d.field(&b[24..28], &format!("k = {}", h.k));
    d.field(&b[28..32], &format!("zstd_level = {}", h.zstd_level));
    d.field(&b[32..40], &format!("scene_hash = {:#018x}", h.scene_hash));
    d.field(&b[40..48], &format!("meta_len = {}", h.meta_len));
    d.field(&b[48..52], &format!("method_len = {}", h.method_len));
    d.field(&b[52..56], &format!("params_len = {}", h.params_len));
    d.field(&b[56..60], &format!("created_len = {}", h.created_len));
    d.field(
        &b[60..64],
        &format!("header_crc = {:#010x}", le32(&b[60..])),
    );
    let mut p = 64;
    for (len, what) in [
        (h.method_len, "method"),
        (h.params_len, "params"),
        (h.created_len, "created"),
    ] {
        let s = &b[p..p + len as usize];
        d.field(
            s,
            &format!("§3.2 {what} = \"{}\"", String::from_utf8_lossy(s)),
        );
        p += len as usize;
    }
    for i in 0..h.n as usize {
        let r = PatchRecordV1::decode(&b[p..p + 168]).unwrap();
        d.field(
            &b[p..p + 4],
            &format!("§4.1 patch {i}: n_corners = {}", r.n_corners),
        );
        d.field(&b[p + 4..p + 8], &format!("  group = {}", r.group));
        d.field(&b[p + 8..p + 12], &format!("  face = {}", r.face));
        d.field(&b[p + 12..p + 16], "  reserved = 0");
        for c in 0..4 {
            let o = p + 16 + 24 * c;
            d.field(
                &b[o..o + 24],
                &format!("  corner {c} = {:?} (f64 x, y, z)", r.corners[c]),
            );
        }
        d.field(&b[p + 112..p + 136], &format!("  normal = {:?}", r.normal));
        d.field(&b[p + 136..p + 144], &format!("  area = {}", r.area));
        d.field(
            &b[p + 144..p + 156],
            &format!("  rho = {:?} (f32 r, g, b)", r.rho),
        );
        d.field(
            &b[p + 156..p + 168],
            &format!("  emission = {:?}", r.emission),
        );
        p += 168;
    }
    let ng = le32(&b[p..]);
    d.field(&b[p..p + 4], &format!("§4.2 n_groups = {ng}"));
    p += 4;
    for g in 0..ng {
        let len = le32(&b[p..]) as usize;
        d.field(&b[p..p + 4], &format!("  group {g} name length = {len}"));
        d.field(
            &b[p + 4..p + 4 + len],
            &format!(
                "  group {g} name = \"{}\"",
                String::from_utf8_lossy(&b[p + 4..p + 4 + len])
            ),
        );
        p += 4 + len;
    }
    if flags & spec::HEADER_FLAG_CLUSTERS != 0 {
        for k in 0..h.n as usize {
            let j = le32(&b[p..]);
            d.field(
                &b[p..p + 4],
                &format!("§4.3 cluster order: position {k} = patch {j}"),
            );
            p += 4;
        }
    }
    d.field(
        &b[p..p + 4],
        &format!("§3.3 meta_crc = {:#010x}", le32(&b[p..])),
    );
    p += 4;
    let foot = b.len() - 32;
    let index_offset = u64::from_le_bytes(b[foot..foot + 8].try_into().unwrap()) as usize;
    let mut payloads = Vec::new();
    let mut k = 0;
    while p < index_offset {
        let c = ChunkHeaderV1::decode(&b[p..]).unwrap();
        d.field(&b[p..p + 4], &format!("§5.1 chunk {k}: magic \"FFZC\""));
        d.field(
            &b[p + 4..p + 8],
            &format!("  flags = {} (SHUFFLED)", c.flags),
        );
        d.field(
            &b[p + 8..p + 16],
            &format!("  compressed_len = {}", c.compressed_len),
        );
        d.field(&b[p + 16..p + 24], &format!("  raw_len = {}", c.raw_len));
        d.field(
            &b[p + 24..p + 28],
            &format!("  row_count = {}", c.row_count),
        );
        d.field(
            &b[p + 28..p + 32],
            &format!("  crc_compressed = {:#010x}", c.crc_compressed),
        );
        d.field(
            &b[p + 32..p + 36],
            &format!("  crc_raw = {:#010x}", c.crc_raw),
        );
        d.field(
            &b[p + 36..p + 40],
            &format!("  header_crc = {:#010x}", le32(&b[p + 36..])),
        );
        let q = p + 40;
        let z = &b[q..q + c.compressed_len as usize];
        d.field(z, "  zstd frame (payload, decompressed below)");
        let raw = zstd::bulk::decompress(z, c.raw_len as usize).unwrap();
        payloads.push(dump_payload(&raw, c.row_count, c.flags & 1 != 0));
        p = q + c.compressed_len as usize;
        k += 1;
    }
    let nch = u64::from_le_bytes(b[p + 8..p + 16].try_into().unwrap()) as usize;
    let nrows = u64::from_le_bytes(b[p + 16..p + 24].try_into().unwrap()) as usize;
    d.field(&b[p..p + 4], "§6 index magic \"FFZI\"");
    d.field(&b[p + 4..p + 8], "  flags = 0");
    d.field(&b[p + 8..p + 16], &format!("  n_chunks = {nch}"));
    d.field(&b[p + 16..p + 24], &format!("  n_rows = {nrows}"));
    p += 24;
    for c in 0..nch {
        let o = u64::from_le_bytes(b[p..p + 8].try_into().unwrap());
        d.field(&b[p..p + 8], &format!("  chunk {c} offset = {o}"));
        p += 8;
    }
    for r in 0..nrows {
        let c = le32(&b[p..]) as i64;
        let s = le32(&b[p + 4..]);
        let st = ["missing", "present", "skipped"]
            .get(s as usize)
            .copied()
            .unwrap_or("?");
        d.field(
            &b[p..p + 8],
            &format!("  row {r}: chunk {c}, state {s} ({st})"),
        );
        p += 8;
    }
    let f = &b[p..];
    d.field(
        &f[0..8],
        &format!(
            "§7 footer: index_offset = {}",
            u64::from_le_bytes(f[0..8].try_into().unwrap())
        ),
    );
    d.field(
        &f[8..16],
        &format!(
            "  index_len = {}",
            u64::from_le_bytes(f[8..16].try_into().unwrap())
        ),
    );
    d.field(
        &f[16..20],
        &format!("  index_crc = {:#010x}", le32(&f[16..])),
    );
    d.field(
        &f[20..24],
        &format!("  footer_crc = {:#010x}", le32(&f[20..])),
    );
    d.field(&f[24..32], "  magic \"FFZ-END\\n\"");
    (d.out, payloads)
}

#[test]
#[ignore = "regenerates formats/golden/*.ffz; run deliberately, then update the spec"]
fn regenerate() {
    for (name, kind) in FILES {
        let path = golden(name);
        write_example(&path, kind);
        let (dump, payloads) = dump_file(&std::fs::read(&path).unwrap());
        println!("```text golden-hex:{name}\n{dump}```\n");
        for (k, p) in payloads.iter().enumerate() {
            println!("```text golden-payload:{name}#{k}\n{p}```\n");
        }
    }
}
