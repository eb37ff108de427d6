"""Reader for `.ffz` version 1 files (the spec is `ffz-v1.md` beside this file).

    import ffz
    f = ffz.read("out.ffz")          # checks every checksum
    f.matrix                          # scipy.sparse.csr_matrix, n x n, float32: F_ij
    f.dropped, f.presence             # per-row dropped mass (spec 5.6) and state
    f.true_row_sums()                 # stored + dropped
    f.no_light_lost()                 # kept entries scaled by (stored + dropped) / stored
    f.patches["area"], f.groups       # the patch table (spec 4)

Command line: `python3 ffz.py FILE [--dump DIR]` prints a summary; `--dump` also writes
the arrays as raw little-endian files (used by the Rust test `tests/it/ffz_python.rs`).

Needs numpy, scipy and zstandard. CRC-32C: uses the `crc32c` package when it is
installed (fast), else the pure-Python table-driven implementation below (about 1 MB/s:
fine for tests and small files; install `crc32c`, or pass verify=False, for big ones).
"""

from __future__ import annotations

import json
import mmap
import os
import struct
import sys
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse
import zstandard

FILE_MAGIC = b"\x89FFZ\r\n\x1a\n"  # spec 3.1
CHUNK_MAGIC = b"FFZC"  # spec 5.1
INDEX_MAGIC = b"FFZI"  # spec 6
FOOTER_MAGIC = b"FFZ-END\n"  # spec 7
HEADER_LEN, PATCH_LEN, CHUNK_HEADER_LEN, DIR_LEN, FOOTER_LEN = 64, 168, 40, 24, 32
SHUFFLED, SKIPPED, SPARSE = 1, 1, 2
NO_CHUNK = 0xFFFFFFFF
MISSING, PRESENT, SKIPPED_STATE = 0, 1, 2

# --- CRC-32C (spec 2): reflected polynomial 0x82F63B78 --------------------------------

_TABLE = []
for _b in range(256):
    _c = _b
    for _ in range(8):
        _c = (_c >> 1) ^ 0x82F63B78 if _c & 1 else _c >> 1
    _TABLE.append(_c)


def crc32c_pure(data) -> int:
    """CRC-32C, one table lookup per byte."""
    c = 0xFFFFFFFF
    t = _TABLE
    for b in bytes(data):
        c = t[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


try:  # optional fast path
    import crc32c as _crc32c_pkg

    def crc32c(data) -> int:
        return _crc32c_pkg.crc32c(bytes(data))

    CRC_IMPLEMENTATION = "crc32c package"
except ImportError:  # pragma: no cover - depends on the machine
    crc32c = crc32c_pure
    CRC_IMPLEMENTATION = "pure Python"


_VERIFY = True


def _crc_ok(data, stored) -> bool:
    """True when CRC-32C of data equals stored (always, with read(verify=False))."""
    return not _VERIFY or crc32c(data) == stored


class FfzError(Exception):
    """A file that cannot be read; the message names the place (byte offset, chunk)."""


DIR_DTYPE = np.dtype([("row", "<u4"), ("flags", "<u4"), ("nnz", "<u4"), ("dropped", "<f4"), ("offset", "<u8")])
PATCH_DTYPE = np.dtype(
    [
        ("n_corners", "<u4"),
        ("group", "<u4"),
        ("face", "<u4"),
        ("reserved", "<u4"),
        ("corners", "<f8", (4, 3)),
        ("normal", "<f8", (3,)),
        ("area", "<f8"),
        ("rho", "<f4", (3,)),
        ("emission", "<f4", (3,)),
    ]
)
assert DIR_DTYPE.itemsize == DIR_LEN and PATCH_DTYPE.itemsize == PATCH_LEN


@dataclass
class FfzFile:
    path: str
    n: int
    layout: str  # "dense" | "topk"
    k: int
    zstd_level: int
    scene_hash: int
    method: str
    params: str
    created: str
    patches: dict  # name -> numpy array (PATCH_DTYPE fields)
    groups: list
    matrix: scipy.sparse.csr_matrix
    dropped: np.ndarray  # float32 (n,)
    presence: np.ndarray  # uint8 (n,): 0 missing, 1 present, 2 skipped
    chunks: int
    indexed: bool
    warnings: list = field(default_factory=list)

    def true_row_sums(self) -> np.ndarray:
        """Stored + dropped per row (spec 5.6), float64."""
        return np.asarray(self.matrix.sum(axis=1, dtype=np.float64)).ravel() + self.dropped.astype(np.float64)

    def no_light_lost(self) -> scipy.sparse.csr_matrix:
        """Kept entries scaled by (stored + dropped) / stored per row (spec 5.6)."""
        stored = np.asarray(self.matrix.sum(axis=1, dtype=np.float64)).ravel()
        scale = np.ones_like(stored)
        ok = stored > 0
        scale[ok] = (stored[ok] + self.dropped[ok]) / stored[ok]
        return scipy.sparse.diags(scale) @ self.matrix.astype(np.float64)


def _u32(b, o):
    return struct.unpack_from("<I", b, o)[0]


def _u64(b, o):
    return struct.unpack_from("<Q", b, o)[0]


def _words(data, m, shuffled) -> np.ndarray:
    """m little-endian 4-byte words, un-shuffling them (spec 5.5) when needed."""
    raw = np.frombuffer(data, dtype=np.uint8, count=4 * m)
    if shuffled:
        raw = raw.reshape(4, m).T.copy()
    return raw.view("<u4").ravel()


class _Chunk:
    """A checked, decompressed chunk (spec 5)."""

    def __init__(self, buf, pos, end, n, sparse, k):
        if end - pos < CHUNK_HEADER_LEN:
            raise ValueError(f"chunk header cut short ({end - pos} bytes)")
        h = bytes(buf[pos : pos + CHUNK_HEADER_LEN])
        if h[:4] != CHUNK_MAGIC:
            raise ValueError(f"bad chunk magic {h[:4].hex()}")
        flags, clen, rlen, rows, crc_c, crc_r, crc_h = struct.unpack_from("<IQQIIII", h, 4)
        if not _crc_ok(h[:36], crc_h):
            raise ValueError("chunk header checksum mismatch")
        if flags & ~SHUFFLED:
            raise ValueError(f"unknown chunk flags {flags:#x}")
        if pos + CHUNK_HEADER_LEN + clen > end:
            raise ValueError(f"chunk cut short: needs {CHUNK_HEADER_LEN + clen} bytes, {end - pos} remain")
        payload = bytes(buf[pos + CHUNK_HEADER_LEN : pos + CHUNK_HEADER_LEN + clen])
        if not _crc_ok(payload, crc_c):
            raise ValueError("compressed payload checksum mismatch")
        if rlen < DIR_LEN * rows or rlen > rows * (DIR_LEN + 8 * n) or rows > n:
            raise ValueError(f"raw length {rlen} impossible for {rows} rows")
        try:
            raw = zstandard.ZstdDecompressor().decompress(payload, max_output_size=rlen)
        except zstandard.ZstdError as e:
            raise ValueError(f"zstd payload does not decompress: {e}") from None
        if len(raw) != rlen:
            raise ValueError(f"payload decompresses to {len(raw)} bytes, header says {rlen}")
        if not _crc_ok(raw, crc_r):
            raise ValueError("decompressed payload checksum mismatch")
        self.pos = pos
        self.length = CHUNK_HEADER_LEN + clen
        self.shuffled = bool(flags & SHUFFLED)
        self.raw = raw
        self.dir = np.frombuffer(raw, dtype=DIR_DTYPE, count=rows)
        nxt = DIR_LEN * rows
        seen = set()
        for e in self.dir:
            row, fl, nnz, off = int(e["row"]), int(e["flags"]), int(e["nnz"]), int(e["offset"])
            skipped = bool(fl & SKIPPED)
            if row >= n or row in seen:
                raise ValueError(f"directory: row {row} out of range or repeated")
            seen.add(row)
            if fl & ~(SKIPPED | SPARSE):
                raise ValueError(f"row {row}: unknown flags {fl:#x}")
            if skipped and (nnz or fl & SPARSE or np.float32(e["dropped"]).view(np.uint32) != 0):
                raise ValueError(f"row {row}: skipped row with data")
            if not skipped and bool(fl & SPARSE) != sparse:
                raise ValueError(f"row {row}: row kind does not match the layout")
            if not skipped and not sparse and nnz != n:
                raise ValueError(f"row {row}: dense row with {nnz} values")
            if sparse and nnz > min(k, n):
                raise ValueError(f"row {row}: {nnz} entries > min(k, n)")
            if off != nxt:
                raise ValueError(f"row {row}: data offset {off}, expected {nxt}")
            nxt += 0 if skipped else (8 if sparse else 4) * nnz
        if nxt != rlen:
            raise ValueError(f"row data ends at {nxt}, payload is {rlen} bytes")

    def rows(self, n):
        """Yield (row, state, cols uint32, vals float32, dropped)."""
        for e in self.dir:
            row, fl, m, off = int(e["row"]), int(e["flags"]), int(e["nnz"]), int(e["offset"])
            if fl & SKIPPED:
                yield row, SKIPPED_STATE, None, None, 0.0
                continue
            data = self.raw[off:]
            if fl & SPARSE:
                deltas = _words(data, m, self.shuffled).astype(np.uint64)
                if m > 1 and np.any(deltas[1:] == 0):
                    raise ValueError(f"row {row}: column delta 0")
                cols = np.cumsum(deltas)
                if m and cols[-1] >= n:
                    raise ValueError(f"row {row}: column >= n")
                vals = _words(data[4 * m :], m, self.shuffled).view("<f4")
                yield row, PRESENT, cols.astype(np.uint32), vals, float(e["dropped"])
            else:
                vals = _words(data, m, self.shuffled).view("<f4")
                yield row, PRESENT, None, vals, float(e["dropped"])


def _read_index(buf, n, meta_len):
    """Footer then index (spec 7, 6); raises ValueError with the offset."""
    size = len(buf)
    if size < meta_len + FOOTER_LEN:
        raise ValueError(f"byte {size}: no room for a footer")
    f = size - FOOTER_LEN
    foot = bytes(buf[f:])
    if foot[24:] != FOOTER_MAGIC:
        raise ValueError(f"byte {f + 24}: no footer magic")
    ioff, ilen, icrc, fcrc = struct.unpack_from("<QQII", foot, 0)
    if not _crc_ok(foot[:20], fcrc):
        raise ValueError(f"byte {f + 20}: footer checksum mismatch")
    if ioff < meta_len or ioff + ilen != f:
        raise ValueError(f"byte {f}: index placed outside the file")
    ix = bytes(buf[ioff:f])
    if not _crc_ok(ix, icrc):
        raise ValueError(f"byte {f + 16}: index checksum mismatch")
    if ix[:4] != INDEX_MAGIC or _u32(ix, 4) != 0:
        raise ValueError(f"byte {ioff}: bad index magic")
    nch, nrows = _u64(ix, 8), _u64(ix, 16)
    if nrows != n or ilen != 24 + 8 * nch + 8 * nrows:
        raise ValueError(f"byte {ioff + 8}: index sizes disagree with n = {n}")
    offsets = np.frombuffer(ix, dtype="<u8", count=nch, offset=24).astype(np.int64)
    if nch and (offsets[0] < meta_len or np.any(np.diff(offsets) <= 0) or offsets[-1] + CHUNK_HEADER_LEN > ioff):
        raise ValueError(f"byte {ioff + 24}: chunk offsets out of order")
    table = np.frombuffer(ix, dtype="<u4", count=2 * n, offset=24 + 8 * nch).reshape(n, 2)
    chunk, state = table[:, 0], table[:, 1]
    ok = ((state == MISSING) & (chunk == NO_CHUNK)) | (((state == PRESENT) | (state == SKIPPED_STATE)) & (chunk < nch))
    if not np.all(ok):
        bad = int(np.argmin(ok))
        raise ValueError(f"byte {ioff + 24 + 8 * nch + 8 * bad}: row {bad} entry invalid")
    return [int(o) for o in offsets], chunk.copy(), state.astype(np.uint8), ioff


def read(path, verify: bool = True) -> FfzFile:
    """Read a whole `.ffz` file into memory as a CSR matrix plus metadata.

    verify=False skips the CRC-32C checks (not the structural ones): only for big files
    without the `crc32c` package, when speed matters more than detecting damage.
    """
    global _VERIFY
    saved, _VERIFY = _VERIFY, verify
    try:
        return _read(os.fspath(path))
    finally:
        _VERIFY = saved


def _read(path) -> FfzFile:
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size < HEADER_LEN:
            raise FfzError(f"{path}: header at byte {size}: file shorter than the 64-byte header")
        buf = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    try:
        return _parse(path, buf)
    finally:
        buf.close()


def _parse(path, buf) -> FfzFile:
    h = bytes(buf[:HEADER_LEN])
    if h[:8] != FILE_MAGIC:
        raise FfzError(f"{path}: not an .ffz file (magic at byte 0 is {h[:8].hex()})")
    version = _u32(h, 8)
    if version != 1:
        raise FfzError(f"{path}: .ffz version {version} is not supported")
    flags, n, layout, k, level = struct.unpack_from("<IIIIi", h, 12)
    scene_hash, meta_len = struct.unpack_from("<QQ", h, 32)
    mlen, plen, clen, hcrc = struct.unpack_from("<IIII", h, 48)
    if not _crc_ok(h[:60], hcrc):
        raise FfzError(f"{path}: header at byte 60: header checksum mismatch")
    if flags != 0 or layout not in (0, 1) or (layout == 0) != (k == 0):
        raise FfzError(f"{path}: header at byte 12: bad flags/layout/k")
    if meta_len > len(buf) or meta_len < HEADER_LEN + mlen + plen + clen + n * PATCH_LEN + 8:
        raise FfzError(f"{path}: header at byte 40: meta_len {meta_len} impossible (file has {len(buf)} bytes)")
    meta = bytes(buf[:meta_len])
    if not _crc_ok(meta[HEADER_LEN:-4], _u32(meta, meta_len - 4)):
        raise FfzError(f"{path}: header at byte {meta_len - 4}: meta block checksum mismatch")
    p = HEADER_LEN
    method = meta[p : p + mlen].decode()
    p += mlen
    params = meta[p : p + plen].decode()
    p += plen
    created = meta[p : p + clen].decode()
    p += clen
    rec = np.frombuffer(meta, dtype=PATCH_DTYPE, count=n, offset=p)
    p += n * PATCH_LEN
    ngroups = _u32(meta, p)
    p += 4
    groups = []
    for _ in range(ngroups):
        ln = _u32(meta, p)
        groups.append(meta[p + 4 : p + 4 + ln].decode())
        p += 4 + ln
    if p != meta_len - 4:
        raise FfzError(f"{path}: header at byte {p}: meta block length mismatch")
    if n and (np.any((rec["n_corners"] != 3) & (rec["n_corners"] != 4)) or np.any(rec["group"] >= ngroups) or np.any(rec["reserved"] != 0)):
        raise FfzError(f"{path}: header: bad patch record")
    patches = {name: rec[name].copy() for name in PATCH_DTYPE.names if name != "reserved"}

    sparse = layout == 1
    warnings = []
    try:
        offsets, row_chunk, presence, area_end = _read_index(buf, n, meta_len)
        indexed = True
        chunks = []
        for c, off in enumerate(offsets):
            end = offsets[c + 1] if c + 1 < len(offsets) else area_end
            try:
                chunks.append(_Chunk(buf, off, end, n, sparse, k))
            except ValueError as e:
                raise FfzError(f"{path}: chunk {c} at byte {off}: {e}") from None
    except ValueError as why:
        indexed = False
        chunks, bad = _scan(buf, meta_len, n, sparse, k)
        row_chunk = np.full(n, NO_CHUNK, dtype=np.uint32)
        presence = np.zeros(n, dtype=np.uint8)
        warnings.append(f"{path}: footer or index unusable ({why}); recovered {len(chunks)} chunks by scanning")
        warnings += [f"{path}: bytes {a}..{b} skipped: {r}" for a, b, r in bad]

    dropped = np.zeros(n, dtype=np.float32)
    row_ids, col_parts, val_parts = [], [], []
    counts = np.zeros(n, dtype=np.int64)
    held = np.zeros(n, dtype=bool)  # rows the chunks hold (checked against the index)
    for c, ch in enumerate(chunks):
        try:
            for row, state, cols, vals, dr in ch.rows(n):
                if indexed:  # spec 9.3: the chunk holds the row the index says it does
                    if row_chunk[row] != c:
                        raise ValueError(f"holds row {row} which the index puts in chunk {int(row_chunk[row])}")
                    if presence[row] != state:
                        raise ValueError(f"row {row}: skipped flag disagrees with the index")
                    held[row] = True
                else:
                    if row_chunk[row] != NO_CHUNK:
                        warnings.append(f"{path}: row {row} repeated in chunk {c}; first copy kept")
                        continue
                    row_chunk[row] = c
                    presence[row] = state
                if state != PRESENT:
                    continue
                if cols is None:  # dense: keep the non-zero entries
                    cols = np.flatnonzero(vals).astype(np.uint32)
                    vals = vals[cols]
                dropped[row] = dr
                counts[row] = len(cols)
                row_ids.append(row)
                col_parts.append(cols)
                val_parts.append(np.asarray(vals, dtype=np.float32))
        except ValueError as e:
            raise FfzError(f"{path}: chunk {c} at byte {ch.pos}: {e}") from None
    if indexed:
        unheld = np.flatnonzero((presence != MISSING) & ~held)
        if len(unheld):
            i = int(unheld[0])
            c = int(row_chunk[i])
            raise FfzError(f"{path}: chunk {c} at byte {offsets[c]}: the index puts row {i} here but the chunk does not hold it")
    # CSR in row order, whatever order the file holds the rows in.
    order = np.argsort(np.asarray(row_ids, dtype=np.int64), kind="stable")
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.concatenate([col_parts[i] for i in order]) if row_ids else np.zeros(0, np.uint32)
    data = np.concatenate([val_parts[i] for i in order]) if row_ids else np.zeros(0, np.float32)
    matrix = scipy.sparse.csr_matrix((data, indices.astype(np.int64), indptr), shape=(n, n))
    return FfzFile(
        path=path,
        n=n,
        layout="topk" if sparse else "dense",
        k=k,
        zstd_level=level,
        scene_hash=scene_hash,
        method=method,
        params=params,
        created=created,
        patches=patches,
        groups=groups,
        matrix=matrix,
        dropped=dropped,
        presence=presence,
        chunks=len(chunks),
        indexed=indexed,
        warnings=warnings,
    )


def _scan(buf, start, n, sparse, k):
    """Recovery scan (spec 8): every good chunk, skipping unreadable regions."""
    chunks, bad = [], []
    pos, end = start, len(buf)
    open_bad = None
    while pos < end:
        try:
            ch = _Chunk(buf, pos, end, n, sparse, k)
        except ValueError as e:
            if open_bad is None:
                open_bad = [pos, end, f"{e} (at byte {pos})"]
            nxt = buf.find(CHUNK_MAGIC, pos + 1)
            if nxt < 0:
                break
            pos = nxt
            continue
        if open_bad is not None:
            open_bad[1] = pos
            bad.append(tuple(open_bad))
            open_bad = None
        chunks.append(ch)
        pos += ch.length
    if open_bad is not None:
        bad.append(tuple(open_bad))
    return chunks, bad


def dump(f: FfzFile, out_dir: str) -> None:
    """Write the decoded arrays as raw little-endian files plus meta.json."""
    os.makedirs(out_dir, exist_ok=True)
    m = f.matrix
    m.indptr.astype("<i8").tofile(os.path.join(out_dir, "indptr.i64"))
    m.indices.astype("<u4").tofile(os.path.join(out_dir, "indices.u32"))
    m.data.astype("<f4").tofile(os.path.join(out_dir, "data.f32"))
    f.dropped.astype("<f4").tofile(os.path.join(out_dir, "dropped.f32"))
    f.presence.astype("u1").tofile(os.path.join(out_dir, "presence.u8"))
    f.patches["area"].astype("<f8").tofile(os.path.join(out_dir, "area.f64"))
    with open(os.path.join(out_dir, "meta.json"), "w") as fh:
        json.dump(
            {
                "n": f.n,
                "layout": f.layout,
                "k": f.k,
                "scene_hash": f.scene_hash,
                "method": f.method,
                "params": f.params,
                "groups": f.groups,
                "chunks": f.chunks,
                "indexed": f.indexed,
                "warnings": f.warnings,
                "crc": CRC_IMPLEMENTATION,
            },
            fh,
        )


def main(argv) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    try:
        f = read(argv[0])
    except FfzError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    p = f.presence
    print(f"{f.path}: n = {f.n}, layout {f.layout} (k = {f.k}), method {f.method} [{f.params}]")
    print(f"rows: {int((p == PRESENT).sum())} present, {int((p == SKIPPED_STATE).sum())} skipped, {int((p == MISSING).sum())} missing; {f.matrix.nnz} stored entries in {f.chunks} chunks")
    for w in f.warnings:
        print(f"warning: {w}")
    if len(argv) >= 3 and argv[1] == "--dump":
        dump(f, argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
