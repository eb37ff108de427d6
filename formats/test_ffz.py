"""Tests of the Python `.ffz` reader (run: `python3 -m pytest formats/`).

- The golden files of spec section 11 decode to the numbers the spec writes down.
- Damage is detected (errors name the chunk and byte, a cut file is recovered).
- With FFZ_FILE (and optionally FFZ_MTX, FFZ_CSV) set to a file written by the Rust side
  and its `ffstream export` output, the reader agrees with the export exactly.
"""

import csv
import os
import pathlib
import re
import struct

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


@pytest.mark.parametrize("name", ["tiny-v1.ffz", "tiny-dense-v1.ffz"])
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


def test_golden_bytes_are_the_spec_hex_dump():
    for name in ["tiny-v1.ffz", "tiny-dense-v1.ffz"]:
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


def reindex(data, table, n_chunks=None):
    """The finished file `data` with a new index (spec 6) whose row table is `table`
    [(chunk, state) per row], keeping only its first n_chunks chunks (the rest cut away);
    index checksum and footer (spec 7) recomputed, so only what `table` says is wrong."""
    ioff = struct.unpack_from("<Q", data, len(data) - 32)[0]
    nch = struct.unpack_from("<Q", data, ioff + 8)[0]
    offsets = list(struct.unpack_from(f"<{nch}Q", data, ioff + 24))
    end = ioff
    if n_chunks is not None and n_chunks < nch:
        end, offsets = offsets[n_chunks], offsets[:n_chunks]
    ix = ffz.INDEX_MAGIC + struct.pack("<IQQ", 0, len(offsets), len(table))
    ix += struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(struct.pack("<II", c, s) for c, s in table)
    foot = struct.pack("<QQI", end, len(ix), ffz.crc32c(ix))
    foot += struct.pack("<I", ffz.crc32c(foot)) + ffz.FOOTER_MAGIC
    return data[:end] + ix + foot


def read_reindexed(tmp_path, table, n_chunks=None):
    good = (HERE / "golden" / "tiny-v1.ffz").read_bytes()
    assert reindex(good, TINY_TABLE) == good  # the helper changes nothing but the table
    p = tmp_path / "bad.ffz"
    p.write_bytes(reindex(good, table, n_chunks))
    return ffz.read(p)


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
