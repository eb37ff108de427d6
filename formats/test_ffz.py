"""Tests of the Python `.ffz` reader (run: `python3 -m pytest formats/`).

- The golden files of spec section 11 decode to the numbers the spec writes down.
- Damage is detected (errors name the chunk and byte, a cut file is recovered).
- The lazy reader (`ffz.open`): row(i), chunks() and to_csr() agree with `ffz.read` on
  the golden files, on files written here from the spec (dense and top-k, shuffled or
  not, rows of different lengths, rows in random order) and on FFZ_FILE; a damaged
  chunk fails only its own rows; cut files are recovered at every length.
- With FFZ_FILE (and optionally FFZ_MTX, FFZ_CSV) set to a file written by the Rust side
  and its `ffstream export` output, the reader agrees with the export exactly.
- With FFZ_INSTALLED=1 (`make test`, after `pip install ./formats` into a fresh venv,
  pytest --import-mode=importlib): the module under test is the installed one, with
  the crc32c package.
"""

import csv
import os
import pathlib
import re
import struct
import warnings

import numpy as np
import pytest
import scipy.io

import ffz

HERE = pathlib.Path(__file__).resolve().parent
SPEC = (HERE / "ffz-v1.md").read_text()


def block(tag):
    m = re.search(r"^```" + re.escape(tag) + r"\n(.*?)^```", SPEC, re.S | re.M)
    assert m, f"spec has no ```{tag} block"
    return m.group(1).splitlines()


def spec_rows(name):
    rows = {}
    for line in block(f"text golden-values:{name}"):
        head, body = line.split(":", 1)
        i = int(head.split()[1])
        t = body.split()
        if t[0] == "skipped":
            rows[i] = ("skipped",)
        elif t[0] == "dense":
            rows[i] = ("dense", [float(x) for x in t[1:]])
        else:
            v, d = t.index("vals"), t.index("dropped")
            rows[i] = ("sparse", [int(x) for x in t[1:v]], [float(x) for x in t[v + 1 : d]], float(t[d + 1]))
    return rows


def spec_hex(name):
    out = bytearray()
    for line in block(f"text golden-hex:{name}"):
        parts = line.split("|")
        assert int(parts[0], 16) == len(out)
        out += bytes(int(b, 16) for b in parts[1].split())
    return bytes(out)


@pytest.mark.parametrize("name", ["tiny-v1.ffz", "tiny-dense-v1.ffz", "tiny-links-v1.ffz"])
def test_golden_file_decodes_to_spec_numbers(name):
    f = ffz.read(HERE / "golden" / name)
    assert f.indexed and not f.warnings
    rows = spec_rows(name)
    assert sorted(rows) == list(range(f.n))
    dense = f.matrix.toarray()
    for i, r in rows.items():
        if r[0] == "skipped":
            assert f.presence[i] == ffz.SKIPPED_STATE
            assert f.matrix[i].nnz == 0
        elif r[0] == "dense":
            assert f.presence[i] == ffz.PRESENT
            np.testing.assert_array_equal(dense[i], np.float32(r[1]))
        else:
            assert f.presence[i] == ffz.PRESENT
            row = f.matrix[i]
            assert list(row.indices) == r[1]
            np.testing.assert_array_equal(row.data, np.float32(r[2]))
            assert f.dropped[i] == np.float32(r[3])
    facts = "\n".join(block(f"text golden-facts:{name}"))
    assert "groups " + ",".join(f.groups) in facts
    assert "areas [" + ", ".join(repr(float(a)) for a in f.patches["area"]) + "]" in facts


def test_golden_links_are_the_spec_links_and_expand_by_the_slope_rule():
    """Spec 11.3: the links and slopes the values block lists, the cluster order, and
    link_matrix()'s expansion (spec 5.7's weights) equal to the fractions worked out
    by hand there."""
    r = ffz.open(HERE / "golden" / "tiny-links-v1.ffz")
    facts = "\n".join(block("text golden-facts:tiny-links-v1.ffz"))
    assert "cluster order " + " ".join(str(int(x)) for x in r.cluster_order) in facts
    for line in block("text golden-values:tiny-links-v1.ffz"):
        i = int(line.split(":")[0].split()[1])
        want = line.split(" links ")[1].split()
        starts, lens, values, slopes = r.links(i)
        got = [f"{a}+{b}:{v:g}:" + ",".join(f"{q:g}" for q in qs) for a, b, v, qs in zip(starts, lens, values, slopes)]
        assert got == want, (i, got, want)
    m = r.link_matrix().toarray()
    b = np.array([[1.0, 2.0], [-3.0, 0.5], [7.0, 1.0]])
    np.testing.assert_allclose(r.link_operator() @ b, m @ b, rtol=1e-14, atol=1e-15)
    want = np.zeros((3, 3))
    want[0, 1], want[1, 0], want[1, 2], want[2, 1] = 0.125, 23 / 122, 19 / 61, 0.125
    np.testing.assert_allclose(m, want, rtol=1e-12, atol=0)
    full = r.read()
    np.testing.assert_allclose(np.asarray(full.matrix.sum(axis=1)).ravel() + m.sum(axis=1), full.true_row_sums(), rtol=1e-6)


def test_golden_bytes_are_the_spec_hex_dump():
    for name in ["tiny-v1.ffz", "tiny-dense-v1.ffz", "tiny-links-v1.ffz"]:
        assert (HERE / "golden" / name).read_bytes() == spec_hex(name)


def test_no_light_lost_scaling_matches_spec_example():
    # Spec 11: F_02 = F_20 = 0.5 * 0.625 / 0.5 = 0.625, true row sums 0.625.
    f = ffz.read(HERE / "golden" / "tiny-v1.ffz")
    np.testing.assert_allclose(f.true_row_sums(), [0.625, 0.0, 0.625])
    s = f.no_light_lost().toarray()
    assert s[0, 2] == pytest.approx(0.625) and s[2, 0] == pytest.approx(0.625)


def test_crc32c_check_value():
    # Spec 2: CRC-32C("123456789") = 0xE3069283.
    assert ffz.crc32c_pure(b"123456789") == 0xE3069283
    assert ffz.crc32c(b"123456789") == 0xE3069283


def test_damaged_chunk_is_an_error_naming_chunk_and_byte(tmp_path):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    bad = bytearray(good)
    bad[0x2C0] ^= 0xFF  # inside chunk 0's zstd frame
    p = tmp_path / "bad.ffz"
    p.write_bytes(bytes(bad))
    with pytest.raises(ffz.FfzError, match=r"chunk 0 at byte 657: compressed payload checksum"):
        ffz.read(p)


def test_every_byte_flip_is_detected_or_harmless(tmp_path):
    good = (HERE / "golden" / "tiny-dense-v1.ffz").read_bytes()
    ref = ffz.read(HERE / "golden" / "tiny-dense-v1.ffz").matrix.toarray()
    p = tmp_path / "flip.ffz"
    for pos in range(len(good)):
        b = bytearray(good)
        b[pos] ^= 0xFF
        p.write_bytes(bytes(b))
        try:
            f = ffz.read(p)
        except ffz.FfzError:
            continue
        # Opened: the damage hit index or footer, the rows were recovered by a scan.
        assert f.warnings, f"flip at {pos} unnoticed"
        np.testing.assert_array_equal(f.matrix.toarray(), ref)


def test_cut_file_recovers_complete_chunks(tmp_path):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    p = tmp_path / "cut.ffz"
    # Cut inside chunk 1 (starts at 736): chunk 0 (rows 2 and 1) survives.
    p.write_bytes(good[:760])
    f = ffz.read(p)
    assert not f.indexed and "recovered 1 chunks" in f.warnings[0]
    assert list(f.presence) == [ffz.MISSING, ffz.SKIPPED_STATE, ffz.PRESENT]
    assert f.matrix[2, 0] == np.float32(0.5)


# Row table of tiny-v1.ffz (spec 11.1): chunk 0 (byte 657) holds rows 2 and 1 (skipped),
# chunk 1 (byte 736) holds row 0.
TINY_TABLE = [(1, ffz.PRESENT), (0, ffz.SKIPPED_STATE), (0, ffz.PRESENT)]


def reindex(data, table, n_chunks=None, routes=None, flags=None):
    """The finished file `data` with a new index (spec 6) whose row table is `table`
    [(chunk, state) per row], keeping only its first n_chunks chunks (the rest cut away),
    with a route record (spec 6.1: nine counts, or ten with the flag of the tenth) when
    `routes` is given; index checksum
    and footer (spec 7) recomputed, so only what `table` (or `routes`, `flags`) says is
    wrong."""
    ioff = struct.unpack_from("<Q", data, len(data) - 32)[0]
    nch = struct.unpack_from("<Q", data, ioff + 8)[0]
    offsets = list(struct.unpack_from(f"<{nch}Q", data, ioff + 24))
    end = ioff
    if n_chunks is not None and n_chunks < nch:
        end, offsets = offsets[n_chunks], offsets[:n_chunks]
    if flags is None:
        flags = 0 if routes is None else ffz.INDEX_FLAG_ROUTES
        if routes is not None and len(routes) == 10:
            flags |= ffz.INDEX_FLAG_ROUTES_UNMET
    ix = ffz.INDEX_MAGIC + struct.pack("<IQQ", flags, len(offsets), len(table))
    ix += struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(struct.pack("<II", c, s) for c, s in table)
    if routes is not None:
        ix += struct.pack(f"<{len(routes)}Q", *routes)
    foot = struct.pack("<QQI", end, len(ix), ffz.crc32c(ix))
    foot += struct.pack("<I", ffz.crc32c(foot)) + ffz.FOOTER_MAGIC
    return data[:end] + ix + foot


def read_reindexed(tmp_path, table, n_chunks=None):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    assert reindex(good, TINY_TABLE) == good  # the helper changes nothing but the table
    p = tmp_path / "bad.ffz"
    p.write_bytes(reindex(good, table, n_chunks))
    return ffz.read(p)


# rows, evaluated, unoccludable, exact, fallback, rays, exact_visible, exact_hidden, points
ROUTES = (2, 10, 2, 5, 1, 3, 1, 2, 500)


def test_route_record_reads_back(tmp_path):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    p = tmp_path / "routes.ffz"
    p.write_bytes(reindex(good, TINY_TABLE, routes=ROUTES))
    with ffz.open(p) as r:
        assert r.indexed and not r.warnings
        assert r.routes == dict(zip(ffz.ROUTE_FIELDS, ROUTES + (0,)))
    f = ffz.read(p)
    assert f.routes == dict(zip(ffz.ROUTE_FIELDS, ROUTES + (0,)))
    assert ffz.read(HERE / "golden" / "tiny-v1.ffz").routes is None
    # The tenth count (pairs short of --shadow-tol), with its flag.
    p.write_bytes(reindex(good, TINY_TABLE, routes=ROUTES + (2,)))
    f = ffz.read(p)
    assert f.indexed and f.routes == dict(zip(ffz.ROUTE_FIELDS, ROUTES + (2,)))


@pytest.mark.parametrize(
    "routes, flags",
    [
        ((4,) + ROUTES[1:], None),  # more rows than the file has (n = 3)
        (ROUTES[:1] + (8,) + ROUTES[2:], None),  # 2 + 5 + 3 routed of 8 evaluated
        (ROUTES[:4] + (4,) + ROUTES[5:], None),  # 4 fallbacks, 3 pairs by rays
        (ROUTES[:6] + (4,) + ROUTES[7:], None),  # 4 + 2 proven of 5 exact
        (ROUTES, 5),  # an unknown flag
        (None, 1),  # the flag without its record: the length is off
        (ROUTES, 3),  # the tenth count's flag, nine counts: the length is off
        (ROUTES + (0,), 3),  # the tenth count flagged but 0
        (ROUTES + (3,), 3),  # 3 short of 2 partly shadowed (5 exact, 3 proven)
        (None, 2),  # the tenth count's flag alone
    ],
    ids=["rows", "routed", "fallback", "proven", "flag", "short", "nine", "zero", "unmet", "alone"],
)
def test_impossible_route_record_means_no_index(tmp_path, routes, flags):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    p = tmp_path / "bad-routes.ffz"
    p.write_bytes(reindex(good, TINY_TABLE, routes=routes, flags=flags))
    f = ffz.read(p)
    assert not f.indexed and f.routes is None and "recovered 2 chunks" in f.warnings[0]
    assert list(f.presence) == [ffz.PRESENT, ffz.SKIPPED_STATE, ffz.PRESENT]


@pytest.mark.skipif(not os.environ.get("FFZ_FILE"), reason="set FFZ_FILE to a Rust-written file")
def test_rust_file_keeps_its_route_counts():
    # FFZ_FILE is a whole `ffstream compute` run: every row counted.
    f = ffz.read(os.environ["FFZ_FILE"])
    r = f.routes
    assert r is not None and r["rows"] == f.n and r["evaluated"] > 0
    assert r["unoccludable"] + r["exact"] + r["rays"] <= r["evaluated"]


@pytest.mark.parametrize("state", [ffz.PRESENT, ffz.SKIPPED_STATE], ids=["present", "skipped"])
def test_index_marks_present_a_row_its_chunk_does_not_hold(tmp_path, state):
    # Chunk 1 (the only one holding row 0) is cut away; the index still puts row 0 in chunk 0.
    table = [(0, state)] + TINY_TABLE[1:]
    with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 0 at byte 657: the index puts row 0 here but the chunk does not hold it"):
        read_reindexed(tmp_path, table, n_chunks=1)


def test_chunk_holds_a_row_the_index_marks_missing(tmp_path):
    table = [(ffz.NO_CHUNK, ffz.MISSING)] + TINY_TABLE[1:]
    with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 1 at byte 736: holds row 0 which the index puts in chunk 4294967295"):
        read_reindexed(tmp_path, table)


def test_chunk_holds_a_row_the_index_assigns_to_another_chunk(tmp_path):
    table = TINY_TABLE[:2] + [(1, ffz.PRESENT)]
    with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 0 at byte 657: holds row 2 which the index puts in chunk 1"):
        read_reindexed(tmp_path, table)


def test_index_marks_skipped_a_row_its_chunk_holds_computed(tmp_path):
    table = TINY_TABLE[:2] + [(0, ffz.SKIPPED_STATE)]
    with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 0 at byte 657: row 2: skipped flag disagrees with the index"):
        read_reindexed(tmp_path, table)


def test_index_marks_present_a_row_its_chunk_holds_skipped(tmp_path):
    table = [TINY_TABLE[0], (0, ffz.PRESENT), TINY_TABLE[2]]
    with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 0 at byte 657: row 1: skipped flag disagrees with the index"):
        read_reindexed(tmp_path, table)


@pytest.mark.skipif(not os.environ.get("FFZ_FILE"), reason="set FFZ_FILE (and FFZ_MTX, FFZ_CSV) to a Rust-written file and its export")
def test_matches_rust_export():
    f = ffz.read(os.environ["FFZ_FILE"])
    if os.environ.get("FFZ_MTX"):
        m = scipy.io.mmread(os.environ["FFZ_MTX"]).tocsr()
        assert m.shape == f.matrix.shape
        a = f.matrix.tocoo()
        b = m.tocoo()
        # Exact: the export prints the shortest decimal that reads back as the same f32.
        ka = sorted(zip(a.row.tolist(), a.col.tolist(), a.data.view(np.uint32).tolist()))
        kb = sorted(zip(b.row.tolist(), b.col.tolist(), b.data.astype(np.float32).view(np.uint32).tolist()))
        assert ka == kb
    if os.environ.get("FFZ_CSV"):
        with open(os.environ["FFZ_CSV"], newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == f.n
        for i, r in enumerate(rows):
            assert int(r["patch"]) == i
            assert r["group"] == f.groups[f.patches["group"][i]]
            assert float(r["area"]) == f.patches["area"][i]
            assert [float(r[c]) for c in ("nx", "ny", "nz")] == list(f.patches["normal"][i])
            assert np.float32(float(r["rho_g"])) == f.patches["rho"][i][1]
            assert np.float32(float(r["e_b"])) == f.patches["emission"][i][2]


# --- The lazy reader (ffz.open) --------------------------------------------------------

GOLDEN = ["tiny-v1.ffz", "tiny-dense-v1.ffz", "tiny-links-v1.ffz"]
NEEDS_FFZ_FILE = pytest.mark.skipif(not os.environ.get("FFZ_FILE"), reason="set FFZ_FILE to a Rust-written file")
FILES = [pytest.param(HERE / "golden" / g, id=g) for g in GOLDEN] + [
    pytest.param(os.environ.get("FFZ_FILE", ""), id="FFZ_FILE", marks=NEEDS_FFZ_FILE)
]


def bits(a):
    return np.asarray(a, dtype=np.float32).view(np.uint32)


def assert_row_is_csr_row(r, f, i):
    """ffz.open(...).row(i) against row i of ffz.read(...) (an FfzFile f)."""
    a, b = f.matrix.indptr[i], f.matrix.indptr[i + 1]
    if f.presence[i] == ffz.MISSING:
        assert r is None, f"row {i}"
        return
    cols, vals, dropped = r
    if f.presence[i] == ffz.SKIPPED_STATE:
        assert len(cols) == 0 and len(vals) == 0 and dropped == 0.0, f"row {i}"
        return
    if cols is None:  # dense: all n values, the CSR keeps the non-zero ones
        assert f.layout == "dense" and len(vals) == f.n, f"row {i}"
        cols = np.flatnonzero(vals)
        vals = vals[cols]
    assert list(cols) == list(f.matrix.indices[a:b]), f"row {i}"
    assert list(bits(vals)) == list(bits(f.matrix.data[a:b])), f"row {i}"
    assert bits(dropped) == bits(f.dropped[i]), f"row {i}"


def assert_same_csr(a, b):
    assert a.shape == b.shape
    for x, y in [(a.indptr, b.indptr), (a.indices, b.indices)]:
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert a.data.dtype == b.data.dtype == np.float32 and np.array_equal(bits(a.data), bits(b.data))


@pytest.mark.parametrize("path", FILES)
def test_lazy_row_is_the_csr_row_of_read(path):
    full = ffz.read(path)
    with ffz.open(path) as f:
        assert (f.n, f.layout, f.k, f.method, f.params, f.groups) == (full.n, full.layout, full.k, full.method, full.params, full.groups)
        assert list(f.presence) == list(full.presence) and f.indexed == full.indexed
        for name, arr in full.patches.items():
            np.testing.assert_array_equal(f.patches[name], arr)
        for i in range(f.n):
            assert_row_is_csr_row(f.row(i), full, i)
        with pytest.raises(IndexError):
            f.row(f.n)
    with pytest.raises(ValueError, match="closed"):
        f.row(0)


@pytest.mark.parametrize("path", FILES)
def test_chunks_cover_every_present_row_once(path):
    full = ffz.read(path)
    with ffz.open(path) as f:
        seen = []
        for c, ch in enumerate(f.chunks()):
            assert ch.index == c and ch.offset == f.chunk_offsets[c]
            for rec in ch:
                seen.append(rec.row)
                assert rec.state == full.presence[rec.row]
                assert_row_is_csr_row(ffz.RowData(rec.cols, rec.vals, rec.dropped), full, rec.row)
        assert c + 1 == f.n_chunks == full.chunks
    assert sorted(seen) == list(np.flatnonzero(full.presence != ffz.MISSING))


@pytest.mark.parametrize("path", FILES)
def test_to_csr_is_read_matrix(path):
    full = ffz.read(path)
    with ffz.open(path) as f:
        assert_same_csr(f.to_csr(), full.matrix)
        assert list(bits(f.dropped)) == list(bits(full.dropped))
    with ffz.open(path, threads=1) as f:  # the dropped pass without to_csr, one thread
        assert list(bits(f.dropped)) == list(bits(full.dropped))
        assert_same_csr(f.to_csr(), full.matrix)


def test_corrupt_chunk_fails_only_its_rows(tmp_path):
    bad = bytearray((HERE / "golden" / "tiny-v1.ffz").read_bytes())
    bad[0x2C0] ^= 0xFF  # inside chunk 0's zstd frame: chunk 0 holds rows 2 and 1 (skipped)
    p = tmp_path / "bad.ffz"
    p.write_bytes(bytes(bad))
    with ffz.open(p) as f:  # header, meta block and index are intact
        assert f.indexed and not f.warnings
        with pytest.raises(ffz.FfzError, match=r"bad\.ffz: chunk 0 at byte 657: compressed payload checksum"):
            f.row(2)
        cols, vals, dropped = f.row(0)  # chunk 1
        assert list(cols) == [2] and list(vals) == [0.5] and dropped == 0.125
        assert len(f.row(1).vals) == 0  # skipped: the index says so, no chunk is read
        with pytest.raises(ffz.FfzError, match="chunk 0 at byte 657"):
            f.to_csr()
        with pytest.raises(ffz.FfzError, match="chunk 0 at byte 657"):
            next(f.chunks())


@NEEDS_FFZ_FILE
def test_corrupt_chunk_of_a_computed_file_fails_only_its_rows(tmp_path):
    path = os.environ["FFZ_FILE"]
    full = ffz.read(path)
    with ffz.open(path) as f:
        assert f.n_chunks >= 2, "FFZ_FILE has one chunk: compute it with e.g. --chunk-kib 64 (as make test does)"
        c = f.n_chunks // 2
        victims = set(int(r) for r, s in zip(f.chunk(c).rows, f.chunk(c).state) if s == ffz.PRESENT)
        off = f.chunk_offsets[c]
    data = bytearray(pathlib.Path(path).read_bytes())
    clen = struct.unpack_from("<Q", data, off + 8)[0]
    data[off + 40 + clen // 2] ^= 0x5A
    p = tmp_path / "bad.ffz"
    p.write_bytes(bytes(data))
    assert victims
    with ffz.open(p, cache_chunks=2) as f:
        for i in range(f.n):
            if i in victims:
                with pytest.raises(ffz.FfzError, match=rf"bad\.ffz: chunk {c} at byte {off}: compressed payload checksum"):
                    f.row(i)
            else:
                assert_row_is_csr_row(f.row(i), full, i)


def test_open_on_a_cut_file_recovers_like_read(tmp_path):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    p = tmp_path / "cut.ffz"
    p.write_bytes(good[:760])  # inside chunk 1 (starts at 736): chunk 0 survives
    with ffz.open(p) as f:
        assert not f.indexed and "recovered 1 chunks" in f.warnings[0]
        assert list(f.presence) == [ffz.MISSING, ffz.SKIPPED_STATE, ffz.PRESENT]
        assert f.row(0) is None
        assert len(f.row(1).cols) == 0
        cols, vals, dropped = f.row(2)
        assert list(cols) == [0] and list(vals) == [0.5] and dropped == 0.125
        assert f.to_csr()[2, 0] == np.float32(0.5)
        assert f.warnings == ffz.read(p).warnings


def test_open_recovers_complete_chunks_at_every_cut(tmp_path):
    # tiny-v1.ffz: meta block to 657, chunk 0 (rows 2, 1 skipped) to 736, chunk 1 (row 0)
    # to 813, index and footer to 909.
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    p = tmp_path / "cut.ffz"
    for cut in range(657, len(good) + 1):
        p.write_bytes(good[:cut])
        with ffz.open(p) as f:
            assert f.indexed == (cut == len(good)), cut
            want = [ffz.PRESENT if cut >= 813 else ffz.MISSING, ffz.SKIPPED_STATE, ffz.PRESENT] if cut >= 736 else [ffz.MISSING] * 3
            assert list(f.presence) == want, cut
            assert f.to_csr().nnz == int(cut >= 736) + int(cut >= 813), cut
            assert (f.row(0) is None) == (cut < 813), cut


# A writer of version 1 files (spec 3-7), written from the spec, for what the golden files
# do not have: unshuffled chunks, top-k rows of different lengths in one chunk, rows in
# random order, several chunks, files without an index holding a row twice.


def shuffle_words(a):
    """Spec 5.5: byte b of every word, b = 0..3."""
    return np.asarray(a, dtype="<u4").view(np.uint8).reshape(-1, 4).T.tobytes()


def write_ffz(path, n, k, chunks, shuffled=True, index=True):
    """chunks: lists of (row, data), data None (skipped), (vals, dropped) (dense, k = 0)
    or (cols, vals, dropped) (top-k)."""
    zstd = __import__("zstandard").ZstdCompressor(level=1)
    method, params, created = b"point", b"writer=test", b"test_ffz.py"
    rec = np.zeros(n, dtype=ffz.PATCH_DTYPE)
    rec["n_corners"] = 4
    rec["face"] = np.arange(n)
    rec["area"] = 1.0 + np.arange(n)
    groups = struct.pack("<I", 2) + b"".join(struct.pack("<I", len(g)) + g for g in (b"floor", b"wall"))
    body = method + params + created + rec.tobytes() + groups
    meta_len = 64 + len(body) + 4
    head = ffz.FILE_MAGIC + struct.pack("<IIIIIiQQIII", 1, 0, n, 1 if k else 0, k, 1, 0x1234, meta_len, len(method), len(params), len(created))
    out = bytearray(head + struct.pack("<I", ffz.crc32c(head)) + body + struct.pack("<I", ffz.crc32c(body)))
    words = shuffle_words if shuffled else (lambda a: np.asarray(a, dtype="<u4").tobytes())
    offsets, table = [], {}
    for c, rows in enumerate(chunks):
        directory, data = b"", b""
        start = 24 * len(rows)
        for row, d in rows:
            if d is None:
                flags, nnz, dropped, blob = ffz.SKIPPED, 0, 0.0, b""
            elif k:
                cols, vals, dropped = d
                flags, nnz = ffz.SPARSE, len(cols)
                blob = words(np.diff(cols, prepend=0)) + words(np.float32(vals).view(np.uint32))
            else:
                vals, dropped = d
                flags, nnz, blob = 0, n, words(np.float32(vals).view(np.uint32))
            directory += struct.pack("<IIIfQ", row, flags, nnz, dropped, start + len(data))
            data += blob
            table.setdefault(row, (c, ffz.SKIPPED_STATE if d is None else ffz.PRESENT))
        raw = directory + data
        z = zstd.compress(raw)
        h = ffz.CHUNK_MAGIC + struct.pack("<IQQIII", ffz.SHUFFLED if shuffled else 0, len(z), len(raw), len(rows), ffz.crc32c(z), ffz.crc32c(raw))
        offsets.append(len(out))
        out += h + struct.pack("<I", ffz.crc32c(h)) + z
    if index:
        ix = ffz.INDEX_MAGIC + struct.pack("<IQQ", 0, len(offsets), n) + struct.pack(f"<{len(offsets)}Q", *offsets)
        ix += b"".join(struct.pack("<II", *table.get(i, (ffz.NO_CHUNK, ffz.MISSING))) for i in range(n))
        foot = struct.pack("<QQI", len(out), len(ix), ffz.crc32c(ix))
        out += ix + foot + struct.pack("<I", ffz.crc32c(foot)) + ffz.FOOTER_MAGIC
    pathlib.Path(path).write_bytes(bytes(out))


def random_rows(rng, n, k, uniform):
    """Rows 0..n-1 in random order, a few missing and skipped; top-k rows of k entries
    (uniform) or of 0..k entries, dense rows with zeros."""
    rows = []
    for i in rng.permutation(n):
        u = rng.random()
        if u < 0.1:
            continue  # missing
        if u < 0.2:
            rows.append((int(i), None))
        elif k:
            m = k if uniform else int(rng.integers(0, k + 1))
            cols = np.sort(rng.choice(n, size=m, replace=False))
            rows.append((int(i), (cols, rng.random(m).astype(np.float32), float(np.float32(rng.random())))))
        else:
            vals = rng.random(n).astype(np.float32)
            vals[rng.random(n) < 0.4] = 0
            rows.append((int(i), (vals, 0.0)))
    return rows


@pytest.mark.parametrize("copies", ["runs", "gathers"])
@pytest.mark.parametrize("shuffled", [True, False], ids=["shuffled", "plain"])
@pytest.mark.parametrize("kind", ["dense", "topk-uniform", "topk-varied"])
def test_lazy_reader_on_written_files(tmp_path, monkeypatch, kind, shuffled, copies):
    # The reader copies runs of rows with slices when they are long and gathers elements
    # otherwise (ffz.MIN_RUN_*): both ways, whatever the sizes here.
    monkeypatch.setattr(ffz, "MIN_RUN_WORDS", 0 if copies == "runs" else 1 << 60)
    monkeypatch.setattr(ffz, "MIN_RUN_ENTRIES", 0 if copies == "runs" else 1 << 60)
    rng = np.random.default_rng(7)
    n, k = 53, (0 if kind == "dense" else 9)
    rows = random_rows(rng, n, k, kind == "topk-uniform")
    if copies == "runs":  # rows ascending in each chunk, so chunks have runs of rows
        rows = sorted(rows[:20]) + sorted(rows[20:])
    chunks = [rows[a : a + 7] for a in range(0, len(rows), 7)]
    p = tmp_path / "w.ffz"
    write_ffz(p, n, k, chunks, shuffled)
    want = dict(rows)
    dense = np.zeros((n, n), dtype=np.float32)
    for i, d in want.items():
        if d is not None and k:
            dense[i, d[0]] = d[1]
        elif d is not None:
            dense[i] = d[0]
    full = ffz.read(p)
    assert full.indexed and not full.warnings and full.chunks == len(chunks)
    np.testing.assert_array_equal(full.matrix.toarray(), dense)
    if k:  # top-k: every stored entry, even a zero one
        assert full.matrix.nnz == sum(len(d[0]) for d in want.values() if d is not None)
    for threads in (1, 3):
        with ffz.open(p, threads=threads, cache_chunks=2) as f:
            for i in range(n):
                r = f.row(i)
                if i not in want:
                    assert r is None and f.presence[i] == ffz.MISSING
                elif want[i] is None:
                    assert len(r.vals) == 0 and f.presence[i] == ffz.SKIPPED_STATE
                elif k:
                    assert list(r.cols) == list(want[i][0]) and list(bits(r.vals)) == list(bits(want[i][1]))
                    assert r.dropped == want[i][2] == f.dropped[i]
                else:
                    assert r.cols is None and list(bits(r.vals)) == list(bits(want[i][0]))
                assert_row_is_csr_row(r, full, i)
            got = [rec.row for ch in f.chunks() for rec in ch]
            assert got == [i for i, _ in rows]  # file order, each row once
            assert_same_csr(f.to_csr(), full.matrix)


def test_written_file_with_a_row_in_two_chunks_keeps_the_first(tmp_path):
    n, k = 6, 2
    first = ([1, 4], [0.25, 0.5], 0.125)
    chunks = [[(3, first), (0, None)], [(5, ([0], [0.75], 0.0)), (3, ([2], [1.0], 0.0))]]
    p = tmp_path / "twice.ffz"
    write_ffz(p, n, k, chunks, index=False)
    with ffz.open(p) as f:
        assert not f.indexed
        assert f.warnings[1:] == [f"{p}: row 3 repeated in chunk 1; first copy kept"]
        cols, vals, dropped = f.row(3)
        assert list(cols) == [1, 4] and list(vals) == [0.25, 0.5] and dropped == 0.125
        assert [rec.row for ch in f.chunks() for rec in ch] == [3, 0, 5]
        assert list(f.presence) == [ffz.SKIPPED_STATE, 0, 0, ffz.PRESENT, 0, ffz.PRESENT]
        m = f.to_csr()
    assert m.nnz == 3 and m[3, 4] == np.float32(0.5) and m[3, 2] == 0
    assert ffz.read(p).warnings == f.warnings


@pytest.mark.parametrize("damage", ["delta", "column"])
def test_bad_row_data_names_row_chunk_and_byte(tmp_path, damage):
    # Chunk 1 holds a top-k row with a column delta of 0 after the first, or a column >= n.
    cols = [1, 1] if damage == "delta" else [2, 9]
    chunks = [[(0, ([1], [0.5], 0.0))], [(1, ([0], [0.5], 0.0)), (2, (cols, [0.25, 0.25], 0.0))]]
    p = tmp_path / "rows.ffz"
    n = 4
    write_ffz(p, n, 2, chunks)
    with ffz.open(p) as f:
        off = f.chunk_offsets[1]
        why = "column delta 0" if damage == "delta" else "column >= n"
        for i in (1, 2):  # the whole chunk is refused, not only the bad row
            with pytest.raises(ffz.FfzError, match=rf"rows\.ffz: chunk 1 at byte {off}: row 2: {why}"):
                f.row(i)
        assert list(f.row(0).cols) == [1]


@pytest.mark.skipif(not os.environ.get("FFZ_INSTALLED"), reason="set FFZ_INSTALLED=1 when testing the pip-installed package")
def test_installed_package_is_tested_with_its_crc32c():
    # make test runs this file against `pip install ./formats` in a fresh venv.
    assert not pathlib.Path(ffz.__file__).resolve().is_relative_to(HERE), ffz.__file__
    assert ffz.CRC_IMPLEMENTATION.startswith("crc32c package"), ffz.CRC_IMPLEMENTATION
    from importlib.metadata import version

    assert version("ffstream-ffz") == ffz.__version__


BAD = HERE.parent / "tests" / "data" / "bad"


@pytest.mark.parametrize(
    "name, fault",
    [
        ("ffz_value_inf", r"row 1: value inf at column 1 is not finite"),
        ("ffz_value_negative", r"row 1: value -0\.25 at column 0 is negative"),
        ("ffz_value_huge", r"row 1: value 1e\+30 at column 2 is above 1\.5"),
        ("ffz_value_dropped_nan", r"dropped mass .* first: row 1: nan"),
        ("ffz_value_dropped_negative", r"dropped mass .* first: row 1: -0\.25"),
        ("ffz_value_dropped_huge", r"dropped mass .* first: row 1: 1e\+30"),
    ],
)
def test_numbers_that_cannot_be_form_factors_are_named_never_silent(name, fault, capsys):
    # The bad-value corpus of the Rust tests (tests/it/ffz_bad_values.rs): intact chunks,
    # row 1 holds the bad number. The reader returns it as stored but says so.
    path = str(BAD / f"{name}.ffz")
    with pytest.warns(RuntimeWarning, match=fault):
        f = ffz.read(path)
    assert len(f.warnings) == 1 and re.search(fault, f.warnings[0]), f.warnings
    assert f.warnings[0].startswith(path)
    dense = f.matrix.toarray()
    assert np.isfinite(dense[[0, 2, 3]]).all() and np.isfinite(f.dropped[[0, 2, 3]]).all()
    capsys.readouterr()
    # The command line says each fault once, as a printed warning (no second copy as
    # a RuntimeWarning on stderr).
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert ffz.main([path]) == 3
    said = capsys.readouterr()
    assert len(re.findall(fault, said.out + said.err)) == 1, said


@pytest.mark.parametrize("name", ["tiny-v1.ffz", "tiny-dense-v1.ffz", "tiny-links-v1.ffz"])
def test_sound_files_have_no_value_faults(name):
    f = ffz.read(str(HERE / "golden" / name))
    assert f.warnings == [] and ffz.value_faults(f.matrix, f.dropped) == []
    assert ffz.main([str(HERE / "golden" / name)]) == 0


def test_value_faults_counts_rows_and_names_the_first():
    import scipy.sparse

    m = scipy.sparse.csr_matrix(
        np.array([[0, 0.5, 0], [-1e-3, 0, -2.0], [0, 0, 0], [np.nan, 1.6, -1.0]], dtype=np.float32)
    )
    dropped = np.array([0, 0, np.inf, 1.5], dtype=np.float32)  # 1.5 itself is allowed
    got = ffz.value_faults(m, dropped)
    assert got == [
        "entries that cannot be form factors in 1 row; first: row 3: value nan at column 0 is not finite",
        "entries that cannot be form factors in 2 rows; first: row 1: value -0.001 at column 0 is negative",
        "entries that cannot be form factors in 1 row; first: row 3: value 1.6 at column 1 is above 1.5: not a form factor",
        "a dropped mass that is not a finite number in [0, 1.5] in 1 row; first: row 2: inf",
    ]


def _with_checksums(b):
    """`b` with its header checksum, and its meta block checksum where the header's
    meta_len places one inside the file, recomputed (spec 3.1, 4): a mutation that
    only a parser can catch."""
    meta_len = struct.unpack_from("<Q", b, 40)[0]
    if ffz.HEADER_LEN + 4 <= meta_len <= len(b):
        struct.pack_into("<I", b, meta_len - 4, ffz.crc32c(bytes(b[ffz.HEADER_LEN : meta_len - 4])))
    struct.pack_into("<I", b, 60, ffz.crc32c(bytes(b[:60])))
    return b


def _header_and_meta_mutants(good, count, seed):
    """`count` checksum-valid mutants of the header and meta block of `good`: random
    bytes, header fields and the meta block's own lengths (string lengths, group count,
    a group name's length) set to edge values, and bytes that are not UTF-8 in its
    strings."""
    rng = np.random.default_rng(seed)
    meta_len = struct.unpack_from("<Q", good, 40)[0]
    mlen, plen, clen = struct.unpack_from("<III", good, 48)
    n = struct.unpack_from("<I", good, 16)[0]
    strings = ffz.HEADER_LEN + mlen + plen + clen
    groups_at = strings + n * ffz.PATCH_LEN
    edges = [0, 1, 2, 3, 4, 5, 7, 8, 63, 64, 65, 168, 255, 256, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFE, 0xFFFFFFFF]
    # (offset, width) of every length or count the parser trusts.
    fields = [(12, 4), (16, 4), (20, 4), (24, 4), (28, 4), (40, 8), (48, 4), (52, 4), (56, 4), (groups_at, 4), (groups_at + 4, 4)]
    for _ in range(count):
        b = bytearray(good)
        kind = rng.integers(0, 5)
        if kind == 0:
            pos = int(rng.integers(8, 60))
            b[pos] = int(rng.integers(0, 256))
        elif kind == 1:
            pos = int(rng.integers(ffz.HEADER_LEN, meta_len - 4))
            b[pos] = int(rng.integers(0, 256))
        elif kind == 2:
            at, width = fields[int(rng.integers(0, len(fields)))]
            v = edges[int(rng.integers(0, len(edges)))]
            if rng.integers(0, 2):
                v = struct.unpack_from("<I", b, at)[0] + int(rng.integers(-3, 4))
            b[at : at + width] = (v % (1 << (8 * width))).to_bytes(width, "little")
        elif kind == 3:
            # Not UTF-8: a lone continuation byte, a cut sequence, an overlong one.
            pos = int(rng.integers(ffz.HEADER_LEN, strings)) if strings > ffz.HEADER_LEN else ffz.HEADER_LEN
            bad = [b"\x80", b"\xff", b"\xc3", b"\xe2\x82", b"\xc0\xaf"][int(rng.integers(0, 5))]
            b[pos : pos + len(bad)] = bad
        else:
            pos = int(rng.integers(groups_at + 8, meta_len - 4))
            b[pos] = [0x80, 0xFF, 0xC3][int(rng.integers(0, 3))]
        yield bytes(_with_checksums(b))


@pytest.mark.parametrize("name", ["tiny-v1.ffz", "tiny-dense-v1.ffz", "tiny-links-v1.ffz"])
def test_header_and_meta_mutations_with_valid_checksums_raise_only_ffz_error(tmp_path, name):
    """Issue 48, item 17: 19 of 300 checksum-valid header and meta mutations raised
    UnicodeDecodeError or struct.error. Each of these mutants opens (the parser found
    nothing wrong, the file is read as the index or a scan says) or raises FfzError,
    nothing else."""
    good = (HERE / "golden" / name).read_bytes()
    p = tmp_path / "mutant.ffz"
    refused = 0
    for k, mutant in enumerate(_header_and_meta_mutants(good, 400, 48)):
        p.write_bytes(mutant)
        try:
            with ffz.open(p) as f:
                assert isinstance(f.method, str) and all(isinstance(g, str) for g in f.groups)
        except ffz.FfzError:
            refused += 1
        except Exception as e:  # noqa: BLE001 - the point of the test
            pytest.fail(f"mutant {k}: {type(e).__name__}: {e}")
    assert refused > 100, f"only {refused} of 400 mutants refused"
