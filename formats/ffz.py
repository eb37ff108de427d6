"""Reader for `.ffz` version 1 files (the spec is `ffz-v1.md` beside this file).

Package `ffstream-ffz` (`pip install ./formats`), module `ffz`. Needs numpy, scipy,
zstandard and crc32c.

    import ffz
    with ffz.open("out.ffz") as f:          # header, patch table and index only
        cols, vals, dropped = f.row(17)     # reads and checks only the chunk holding row 17
        m = f.to_csr()                      # scipy.sparse.csr_matrix, n x n, float32: F_ij
        area = f.patches["area"]            # the patch table (spec 4); f.groups, f.n, f.layout

    f = ffz.read("out.ffz")                 # the whole file at once: an FfzFile
    f.matrix, f.dropped, f.presence         # CSR matrix, dropped mass per row (spec 5.6), row state
    f.true_row_sums()                       # stored + dropped
    f.no_light_lost()                       # kept entries scaled by (stored + dropped) / stored

`open(path, verify=True, threads=None, cache_chunks=8)` returns an FfzReader (a context
manager; close() releases the memory map):
- At open it reads and checks the header, the meta block (patches, groups, method,
  params) and the footer and index (spec 3-7). Without a usable index it runs the
  recovery scan (spec 8), which decompresses every chunk once, and `warnings` says so.
- `row(i)`: None for a missing row. A top-k row gives (cols uint32 ascending, vals
  float32, dropped); a dense row gives (None, all n values float32, zeros included,
  dropped); a skipped row gives (empty uint32, empty float32, 0.0) and reads no chunk.
  Only the chunk holding row i is read and checked; the last `cache_chunks` decoded
  chunks are kept. The arrays are read-only.
- `chunks()`: the chunks in file order (Chunk objects: `index`, `offset`, `rows`,
  `state`, `nnz`, `dropped`, `row(i)`); iterating one yields RowRecord(row, state,
  cols, vals, dropped) in the chunk's order, with the conventions of `row(i)`. A few
  chunks (about 1 MiB raw each) are in memory at a time, never the whole file.
- `to_csr()`: the matrix, the same as `read().matrix` (dense rows keep their non-zero
  entries, top-k rows every stored entry).
- `routes`: how the pairs got their visibility (spec 6.1), a dict of `rows` (rows, or
  half rows with --symmetric, that the counts cover: those computed by runs that
  finished), `evaluated`, `unoccludable`, `exact`, `fallback`, `rays`,
  `exact_visible`, `exact_hidden`, `exact_points`, `exact_unmet` (0 when the record has no tenth count); None when the index has no such
  record or the file was recovered by a scan.
- `presence` (uint8 per row: 0 missing, 1 present, 2 skipped) comes from the index or
  the scan: no pass over the chunks. `dropped` (float32 per row) is stored in the
  chunks: its first use reads every chunk once (unless to_csr() already did), then it
  is kept.
- Every chunk read checks what spec 9.3 lists. A failure raises FfzError naming the
  file, the chunk and its byte offset; the other chunks still read.
- to_csr() and read() also check the numbers (spec 10): entries that are negative, not
  finite or above 1.5, and a dropped mass outside [0, 1.5], cannot be form factors.
  They are returned as stored, but each kind found adds a line to `warnings` (the count
  of rows and the first row and column) and raises a RuntimeWarning; `value_faults()`
  gives the same lines for any matrix and dropped mass, and the command line exits 3.
- Files with links to clusters (spec 4.3, 5.7): `cluster_order`; `links(i)` gives row
  i's (starts, lengths, values, slopes); `link_matrix()` expands every link into patch
  entries (n x n sparse: for small files, as entries it grows as n^2);
  `link_operator()` is the same as a scipy LinearOperator that sums through prefix
  sums, O(links) a product: `to_csr() @ b + link_operator() @ b` is F b for a solver
  (100k patches, 25.6M links: built in about 80 s, 7 s a product of three columns).
- verify=False skips the CRC-32C checks (not the structural ones). `threads`: chunks
  decoded in parallel by to_csr(), chunks() and dropped (default: the CPUs, at most 8).

Speed: `read()` with every checksum checked reads a 98 MB dense file at about
300 MB/s (file bytes per second) on 2 cores (bench/python_reader.py).

Command line: `python3 ffz.py FILE [--dump DIR]` prints a summary; `--dump` also writes
the arrays as raw little-endian files (used by the Rust test `tests/it/ffz_python.rs`).

CRC-32C: the `crc32c` package (installed with this package; hardware instructions
where the CPU has them). Only when the module is run from the source tree without that
package does it fall back to the pure-Python table-driven implementation below (about
1 MB/s: fine for tests and small files). `CRC_IMPLEMENTATION` says which is in use.
"""

from __future__ import annotations

import builtins
import collections
import json
import mmap
import os
import struct
import sys
import threading
import warnings as _warnings
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple, Optional

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
import zstandard

__version__ = "0.2.0"

FILE_MAGIC = b"\x89FFZ\r\n\x1a\n"  # spec 3.1
CHUNK_MAGIC = b"FFZC"  # spec 5.1
INDEX_MAGIC = b"FFZI"  # spec 6
INDEX_FLAG_ROUTES = 1  # spec 6: a route record (6.1) follows the row table
INDEX_FLAG_ROUTES_UNMET = 2  # spec 6.1: with ROUTES, the record has a tenth count
ROUTES_LEN = 72
# spec 6.1, in file order (nine u64, a tenth with INDEX_FLAG_ROUTES_UNMET; 0 without)
ROUTE_FIELDS = ("rows", "evaluated", "unoccludable", "exact", "fallback", "rays",
                "exact_visible", "exact_hidden", "exact_points", "exact_unmet")
FOOTER_MAGIC = b"FFZ-END\n"  # spec 7
HEADER_LEN, PATCH_LEN, CHUNK_HEADER_LEN, DIR_LEN, FOOTER_LEN = 64, 168, 40, 24, 32
SHUFFLED, SKIPPED, SPARSE = 1, 1, 2
LINKS = 4  # spec 5.7: row directory flag, the row's links follow its entries
SLOPES = 8  # spec 5.7: row directory flag, each link also has a slope (only with LINKS)
LINK_ERROR = 16  # spec 5.7: row directory flag, the links are followed by the writer's error estimate (only with LINKS)
FLAT_WEIGHT = 1e-6  # spec 5.7: a link whose weights sum to at most this times its range's area is spread by area
HEADER_FLAG_CLUSTERS = 1  # spec 3.1, 4.3: the meta block holds a cluster order
NO_CHUNK = 0xFFFFFFFF
MISSING, PRESENT, SKIPPED_STATE = 0, 1, 2

# Per-run slice copies beat per-element gathers when runs are at least this long on
# average (words of a sparse chunk's rows of one length; CSR entries of rows that follow
# each other in a chunk and in the matrix). Module constants so that tests reach both ways.
MIN_RUN_WORDS = 64
MIN_RUN_ENTRIES = 256

# Spec 10: no form factor and no row's total exceeds 1; a stored entry or dropped mass
# above this (or negative, or not finite) cannot be one. ffstream's `verify` fails such
# rows and its `solve` refuses them.
MAX_FORM_FACTOR = 1.5


def _rows(k) -> str:
    return f"{k} row" if k == 1 else f"{k} rows"


def value_faults(matrix, dropped) -> list:
    """Rows whose numbers cannot be form factors (spec 10), one message per kind of
    fault that occurs: entries not finite, negative or above MAX_FORM_FACTOR, and a
    dropped mass that is not a finite number in [0, MAX_FORM_FACTOR]. Each message
    gives the count of rows and names the first row (and column). Empty for a sound
    file. `matrix` is the CSR matrix of to_csr(), `dropped` the mass per row."""
    out = []
    data = matrix.data
    rows_of = lambda at: np.searchsorted(matrix.indptr, at, side="right") - 1  # noqa: E731
    kinds = [
        (~np.isfinite(data), "is not finite"),
        (np.isfinite(data) & (data < 0), "is negative"),
        (np.isfinite(data) & (data > MAX_FORM_FACTOR), f"is above {MAX_FORM_FACTOR}: not a form factor"),
    ]
    for bad, what in kinds:
        at = np.flatnonzero(bad)
        if len(at):
            r = rows_of(at)
            k = int(at[0])
            out.append(
                f"entries that cannot be form factors in {_rows(len(np.unique(r)))}; "
                f"first: row {int(r[0])}: value {float(data[k]):g} at column {int(matrix.indices[k])} {what}"
            )
    d = np.asarray(dropped)
    bad = ~(np.isfinite(d) & (d >= 0) & (d <= MAX_FORM_FACTOR))
    if bad.any():
        r = np.flatnonzero(bad)
        out.append(
            f"a dropped mass that is not a finite number in [0, {MAX_FORM_FACTOR}] in {_rows(len(r))}; "
            f"first: row {int(r[0])}: {float(d[r[0]]):g}"
        )
    return out

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


try:  # a dependency of the installed package; absent only when run from the source tree
    import crc32c as _crc32c_pkg
except ImportError:  # pragma: no cover - depends on the machine
    _crc32c_pkg = None

if _crc32c_pkg is not None:
    _crc32c_fn = _crc32c_pkg.crc32c

    def crc32c(data) -> int:
        """CRC-32C of any bytes-like object (bytes, memoryview, numpy array)."""
        return _crc32c_fn(data)

    CRC_IMPLEMENTATION = "crc32c package {} ({})".format(
        getattr(_crc32c_pkg, "__version__", "?"),
        "hardware" if getattr(_crc32c_pkg, "hardware_based", False) else "software",
    )
else:  # pragma: no cover - depends on the machine
    crc32c = crc32c_pure
    CRC_IMPLEMENTATION = "pure Python"


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
    routes: Optional[dict] = None  # spec 6.1; see FfzReader.routes

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


class RowData(NamedTuple):
    """One row: cols None for a dense row (vals then holds all n values)."""

    cols: Optional[np.ndarray]  # uint32, ascending
    vals: np.ndarray  # float32
    dropped: float


class RowRecord(NamedTuple):
    """One row of a chunk, as Chunk iteration yields it (conventions of RowData)."""

    row: int
    state: int  # PRESENT or SKIPPED_STATE
    cols: Optional[np.ndarray]
    vals: np.ndarray
    dropped: float


def _u32(b, o):
    return struct.unpack_from("<I", b, o)[0]


def _u64(b, o):
    return struct.unpack_from("<Q", b, o)[0]


def _meta_text(path, meta, at, length, end, what) -> str:
    """The UTF-8 string of `length` bytes at byte `at` of the meta block, which must
    end by `end` (spec 3.2, 4.2); FfzError naming the byte otherwise."""
    if at + length > end:
        raise FfzError(f"{path}: header at byte {at}: {what} string of {length} bytes cut short (the meta block's strings end at byte {end})")
    try:
        return bytes(meta[at : at + length]).decode("utf-8")
    except UnicodeDecodeError as e:
        raise FfzError(f"{path}: header at byte {at + e.start}: {what} string is not UTF-8") from None


def _excl_cumsum(a) -> np.ndarray:
    """[0, a0, a0 + a1, ...] without the total, int64."""
    out = np.zeros(len(a), dtype=np.int64)
    if len(a) > 1:
        np.cumsum(a[:-1], out=out[1:])
    return out


def _first_failure(checks):
    """checks: [(mask over entries, message(j))]; the message of the lowest failing
    entry (ties: the first check in the list), or None."""
    best = None
    for mask, msg in checks:
        if mask is None:
            continue
        hit = np.flatnonzero(mask)
        if len(hit) and (best is None or hit[0] < best[0]):
            best = (int(hit[0]), msg)
    return None if best is None else best[1](best[0])


def _unshuffle_uniform(u8, arrays, m) -> np.ndarray:
    """`arrays` byte-shuffled arrays of m words each, back to rows of words (spec 5.5)."""
    x = u8[: arrays * 4 * m].reshape(arrays, 4, m)
    out = np.empty((arrays, m, 4), dtype=np.uint8)
    for b in range(4):  # four plane copies: much faster than one transposing copy
        out[:, :, b] = x[:, b, :]
    return out.view("<u4").reshape(arrays, m)


def _sparse_words(u8, m, shuffled):
    """Column deltas and values (uint32 words, rows one after the other) of sparse rows
    with m[r] entries each, stored as in spec 5.4 (row r's 8 m[r] bytes start at byte
    8 first[r]: deltas, then values, each byte-shuffled on its own when `shuffled`)."""
    total = int(m.sum())
    first = _excl_cumsum(m)
    deltas = np.empty(total, dtype="<u4")
    vals = np.empty(total, dtype="<u4")
    runs = np.flatnonzero(np.diff(m)) + 1  # runs of rows of one length: 2-D copies each
    runs = np.concatenate(([0], runs, [len(m)])) if len(m) else np.zeros(1, np.int64)
    if total >= MIN_RUN_WORDS * (len(runs) - 1):  # long runs (top-k rows of k entries, long rows)
        for a, b in zip(runs[:-1].tolist(), runs[1:].tolist()):
            rows, w, s = b - a, int(m[a]), int(first[a])
            block = u8[8 * s : 8 * (s + rows * w)]
            if shuffled:
                x = block.reshape(rows, 2, 4, w)
                d = deltas[s : s + rows * w].view(np.uint8).reshape(rows, w, 4)
                v = vals[s : s + rows * w].view(np.uint8).reshape(rows, w, 4)
                for byte in range(4):  # plane copies: faster than a transposing copy
                    d[:, :, byte] = x[:, 0, byte, :]
                    v[:, :, byte] = x[:, 1, byte, :]
            else:
                x = block.view("<u4").reshape(rows, 2, w)
                deltas[s : s + rows * w].reshape(rows, w)[:] = x[:, 0, :]
                vals[s : s + rows * w].reshape(rows, w)[:] = x[:, 1, :]
    else:  # many short runs: gather every byte (word) with computed offsets
        # Output word g = first[r] + q of row r: its delta bytes start at byte 8 first[r],
        # its value bytes at 8 first[r] + 4 m[r]; shuffled, byte b of word q is at
        # start + b m[r] + q = g + (start - first[r]) + b m[r]; plain, at start + 4 q + b.
        g = np.arange(total, dtype=np.int64)
        for out, extra in ((deltas, 0), (vals, 4)):
            if shuffled:
                src = g + np.repeat(7 * first + extra * m, m)
                step = np.repeat(m, m)
                ob = out.view(np.uint8).reshape(total, 4)
                for byte in range(4):  # src is in range by construction: mode="clip" avoids buffering
                    np.take(u8, src, out=ob[:, byte], mode="clip")
                    src += step
            else:
                w32 = u8[: 8 * total].view("<u4")
                np.take(w32, g + np.repeat(first + extra // 4 * m, m), out=out, mode="clip")
    return deltas, vals.view("<f4")


def _words(b, shuffled) -> np.ndarray:
    """One array of 4-byte words (spec 5.5: byte planes when shuffled)."""
    m = len(b) // 4
    if not shuffled:
        return np.frombuffer(b, dtype="<u4", count=m).copy()
    return np.frombuffer(b, dtype=np.uint8).reshape(4, m).T.copy().view("<u4").ravel()


def _split_links(raw, d, n, shuffled):
    """Spec 5.7: the links of a chunk's LINKS rows taken out of its payload. Returns the
    payload and directory as they would be without links (offsets shifted, LINKS
    cleared), {row: (starts, lengths, values, slopes)} (slopes an (m, 3) float32
    array, zeros for a row without SLOPES) and {row: link error} for the rows with
    LINK_ERROR; ValueError on a bad link."""
    rows = len(d)
    d = d.copy()
    base = DIR_LEN * rows
    out = [bytes(raw[:base])]
    links, errors = {}, {}
    pos = base  # where the next row's data starts in the payload as stored
    new = base
    for j in range(rows):
        row, fl, nnz = int(d[j, 0]), int(d[j, 1]), int(d[j, 2])
        off = int(d[j, 4]) | (int(d[j, 5]) << 32)
        if off != pos:
            raise ValueError(f"row {row}: data offset {off}, expected {pos}")
        size = 0 if fl & SKIPPED else 8 * nnz
        if fl & LINKS and not (fl & SPARSE and not fl & SKIPPED):
            raise ValueError(f"row {row}: links on a row that is not sparse")
        if fl & SLOPES and not fl & LINKS:
            raise ValueError(f"row {row}: slopes on a row without links")
        if fl & LINK_ERROR and not fl & LINKS:
            raise ValueError(f"row {row}: a link error on a row without links")
        out.append(bytes(raw[pos : pos + size]))
        d[j, 4], d[j, 5] = new & 0xFFFFFFFF, new >> 32
        pos += size
        new += size
        if fl & LINKS:
            if pos + 4 > len(raw):
                raise ValueError(f"row {row}: link count beyond the payload")
            m = _u32(raw, pos)
            per = 24 if fl & SLOPES else 12
            if not 1 <= m <= n or pos + 4 + per * m > len(raw):
                raise ValueError(f"row {row}: {m} links impossible here")
            gaps = _words(raw[pos + 4 : pos + 4 + 4 * m], shuffled).astype(np.int64)
            lens = _words(raw[pos + 4 + 4 * m : pos + 4 + 8 * m], shuffled).astype(np.int64)
            vals = _words(raw[pos + 4 + 8 * m : pos + 4 + 12 * m], shuffled).view("<f4")
            ends = np.cumsum(gaps + lens)
            starts = ends - lens
            if np.any(lens < 1) or int(ends[-1]) > n:
                raise ValueError(f"row {row}: a link is empty or ends beyond n = {n}")
            dropped = float(np.frombuffer(raw, dtype="<f4", count=1, offset=DIR_LEN * j + 12)[0])
            total = float(vals.astype(np.float64).sum())
            if abs(total - dropped) > 1e-6 * max(abs(total), abs(dropped)) + 1e-30:
                raise ValueError(f"row {row}: dropped mass {dropped:e} is not the sum of its links {total:e}")
            if fl & SLOPES:
                at = pos + 4 + 12 * m
                slopes = np.stack([_words(raw[at + 4 * m * c : at + 4 * m * (c + 1)], shuffled).view("<f4") for c in range(3)], axis=1)
                if not np.all(np.isfinite(slopes)):
                    raise ValueError(f"row {row}: a link's slope is not finite")
            else:
                slopes = np.zeros((m, 3), np.float32)
            links[row] = (starts.astype(np.uint32), lens.astype(np.uint32), vals.copy(), slopes)
            pos += 4 + per * m
            if fl & LINK_ERROR:
                if pos + 4 > len(raw):
                    raise ValueError(f"row {row}: link error beyond the payload")
                e = float(np.frombuffer(raw, dtype="<f4", count=1, offset=pos)[0])
                if not (np.isfinite(e) and e >= 0):
                    raise ValueError(f"row {row}: link error {e} is not a finite number >= 0")
                errors[row] = e
                pos += 4
            d[j, 1] = fl & ~(LINKS | SLOPES | LINK_ERROR)
    if pos != len(raw):
        raise ValueError(f"row data ends at {pos}, payload is {len(raw)} bytes")
    return b"".join(out), d, links, errors


def _check_directory(d, rlen, n, sparse, k):
    """The row directory rules of spec 5.3 over the (rows, 6) u32 words of a directory;
    ValueError naming the first bad entry. Returns (row, skipped, nnz, dropped)."""
    rows = len(d)
    row, fl, nnz, dbits = d[:, 0], d[:, 1], d[:, 2], d[:, 3]
    off = d[:, 4].astype(np.uint64) | (d[:, 5].astype(np.uint64) << np.uint64(32))
    skipped = (fl & SKIPPED) != 0
    row_sparse = (fl & SPARSE) != 0
    size = np.where(skipped, 0, nnz.astype(np.int64) * (8 if sparse else 4))
    expected = DIR_LEN * rows + _excl_cumsum(size)
    repeated = np.zeros(rows, dtype=bool)
    if rows > 1:
        order = np.argsort(row, kind="stable")
        later = order[1:][row[order[1:]] == row[order[:-1]]]  # second and later copies
        repeated[later] = True
    msg = _first_failure(
        [
            ((row >= n) | repeated, lambda j: f"directory: row {int(row[j])} out of range or repeated"),
            ((fl & ~np.uint32(SKIPPED | SPARSE)) != 0, lambda j: f"row {int(row[j])}: unknown flags {int(fl[j]):#x}"),
            (skipped & ((nnz != 0) | row_sparse | (dbits != 0)), lambda j: f"row {int(row[j])}: skipped row with data"),
            (~skipped & (row_sparse != sparse), lambda j: f"row {int(row[j])}: row kind does not match the layout"),
            (None if sparse else ~skipped & (nnz != n), lambda j: f"row {int(row[j])}: dense row with {int(nnz[j])} values"),
            (nnz > min(k, n) if sparse else None, lambda j: f"row {int(row[j])}: {int(nnz[j])} entries > min(k, n)"),
            (off != expected.astype(np.uint64), lambda j: f"row {int(row[j])}: data offset {int(off[j])}, expected {int(expected[j])}"),
        ]
    )
    if msg:
        raise ValueError(msg)
    end = DIR_LEN * rows + int(size.sum())
    if end != rlen:
        raise ValueError(f"row data ends at {end}, payload is {rlen} bytes")
    return row, skipped, nnz, dbits.view("<f4")


_local = threading.local()


def _decompressor():
    """One zstd decompression context per thread (they are not thread-safe)."""
    d = getattr(_local, "zstd", None)
    if d is None:
        d = _local.zstd = zstandard.ZstdDecompressor()
    return d


def _col_type(n):
    """Index type of the CSR matrix (scipy's choice for these sizes)."""
    return np.int32 if n <= np.iinfo(np.int32).max else np.int64


def _default_threads() -> int:
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, 8))


def _ordered_map(fn, items, threads):
    """fn over items, results in order; with threads > 1 up to 2 x threads calls run
    ahead in a thread pool (zstd, CRC-32C and numpy release the GIL)."""
    if threads <= 1 or len(items) <= 1:
        for x in items:
            yield fn(x)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending = collections.deque()
        try:
            for x in items:
                pending.append(pool.submit(fn, x))
                if len(pending) > 2 * threads:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for fut in pending:
                fut.cancel()


class Chunk:
    """A checked, decoded chunk (spec 5). `rows`, `state` (PRESENT / SKIPPED_STATE),
    `nnz` (values stored: n for a dense row) and `dropped` are per entry, in the chunk's
    order. Iterating yields RowRecord per entry; `row(i)` gives row i's RowData or None.
    In a recovered file a row that an earlier chunk also holds is left out (spec 8, step 4)."""

    def __init__(self, index, offset, n, rows, state, nnz, dropped, start, vals, cols):
        self.index = index  # chunk number: position in the index, or in scan order
        self.offset = offset  # byte offset of the chunk in the file
        self.rows = rows
        self.state = state
        self.nnz = nnz
        self.dropped = dropped
        self._n = n
        self._start = start  # per entry: where its values start in _vals / _cols
        self._vals = vals  # float32, the entries' values one after the other
        self._cols = cols  # uint32 (top-k) or None (dense)
        self._where = None
        for a in (rows, state, nnz, dropped, vals, cols):
            if a is not None:
                a.flags.writeable = False

    def __len__(self):
        return len(self.rows)

    def __repr__(self):
        return f"<ffz.Chunk {self.index} at byte {self.offset}: {len(self.rows)} rows>"

    def _data(self, j) -> RowData:
        dropped = float(self.dropped[j])
        if self.state[j] != PRESENT:
            return RowData(np.zeros(0, np.uint32), np.zeros(0, np.float32), 0.0)
        a = int(self._start[j])
        b = a + int(self.nnz[j])
        return RowData(None if self._cols is None else self._cols[a:b], self._vals[a:b], dropped)

    def row(self, i) -> Optional[RowData]:
        if self._where is None:
            self._where = {int(r): j for j, r in enumerate(self.rows)}
        j = self._where.get(int(i))
        return None if j is None else self._data(j)

    def __iter__(self):
        for j in range(len(self.rows)):
            cols, vals, dropped = self._data(j)
            yield RowRecord(int(self.rows[j]), int(self.state[j]), cols, vals, dropped)

    def _csr_part(self):
        """(rows, counts, cols int32, vals float32, dropped) of the present rows, for
        to_csr(): a dense row keeps its non-zero values, a top-k row every stored one."""
        present = np.flatnonzero(self.state == PRESENT)
        rows = self.rows[present].astype(np.int64)
        if not len(present):
            return rows, np.zeros(0, np.int64), np.zeros(0, _col_type(self._n)), np.zeros(0, np.float32), self.dropped[present]
        if self._cols is None:  # dense: n values per present row
            n = self._n
            starts = self._start[present]
            if np.all(np.diff(starts) == n):  # one block (always, unless rows were left out)
                block = self._vals[int(starts[0]) : int(starts[0]) + len(present) * n].reshape(len(present), n)
            else:
                block = self._vals.reshape(-1, n)[starts // n]
            at = np.flatnonzero(block != 0)
            counts = np.diff(np.searchsorted(at, np.arange(len(present) + 1, dtype=np.int64) * n))
            vals = block.reshape(-1)[at]
            at -= np.repeat(np.arange(len(present), dtype=np.int64) * n, counts)
            cols = at.astype(_col_type(n))
        else:
            counts = self.nnz[present].astype(np.int64)
            starts = self._start[present]
            if (starts[0] != 0 or np.any(starts[1:] != starts[:-1] + counts[:-1]) or int(starts[-1] + counts[-1]) != len(self._vals)):
                take = np.repeat(starts - _excl_cumsum(counts), counts) + np.arange(int(counts.sum()))
                cols, vals = self._cols[take], self._vals[take]
            else:
                cols, vals = self._cols, self._vals
            cols = cols.astype(_col_type(self._n))
        return rows, counts, cols, vals, self.dropped[present]


class FfzReader:
    """An open `.ffz` file (see the module docstring); made by `ffz.open`."""

    def __init__(self, path, verify: bool = True, threads: Optional[int] = None, cache_chunks: int = 8):
        self.path = os.fspath(path)
        self.verify = verify
        self.threads = _default_threads() if threads is None else max(1, int(threads))
        self.warnings: list = []
        self.routes = None
        self._crc = crc32c if verify else None
        self._cache = collections.OrderedDict()
        self._cache_size = max(0, int(cache_chunks))
        self._dropped = None
        self._iters = weakref.WeakSet()
        self._mm = self._mv = None
        with builtins.open(self.path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size < HEADER_LEN:
                raise FfzError(f"{self.path}: header at byte {size}: file shorter than the 64-byte header")
            self._mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._mv = memoryview(self._mm)
        try:
            self._read_meta()
            self._read_index_or_scan()
        except BaseException:
            self.close()
            raise

    # --- open: header, meta block, index (spec 3, 4, 6, 7) or scan (spec 8) ----------

    def _crc_ok(self, data, stored) -> bool:
        return self._crc is None or self._crc(data) == stored

    def _read_meta(self):
        path, buf = self.path, self._mm
        h = buf[:HEADER_LEN]
        if h[:8] != FILE_MAGIC:
            raise FfzError(f"{path}: not an .ffz file (magic at byte 0 is {h[:8].hex()})")
        version = _u32(h, 8)
        if version != 1:
            raise FfzError(f"{path}: .ffz version {version} is not supported")
        flags, n, layout, k, level = struct.unpack_from("<IIIIi", h, 12)
        scene_hash, meta_len = struct.unpack_from("<QQ", h, 32)
        mlen, plen, clen, hcrc = struct.unpack_from("<IIII", h, 48)
        if not self._crc_ok(h[:60], hcrc):
            raise FfzError(f"{path}: header at byte 60: header checksum mismatch")
        if flags & ~HEADER_FLAG_CLUSTERS or (flags and layout != 1) or layout not in (0, 1) or (layout == 0) != (k == 0):
            raise FfzError(f"{path}: header at byte 12: bad flags/layout/k")
        if meta_len > len(buf) or meta_len < HEADER_LEN + mlen + plen + clen + n * PATCH_LEN + 8:
            raise FfzError(f"{path}: header at byte 40: meta_len {meta_len} impossible (file has {len(buf)} bytes)")
        meta = buf[:meta_len]
        if not self._crc_ok(memoryview(meta)[HEADER_LEN:-4], _u32(meta, meta_len - 4)):
            raise FfzError(f"{path}: header at byte {meta_len - 4}: meta block checksum mismatch")
        # Every length is checked against the body (which ends at the meta checksum)
        # before it is used, and every string is decoded as UTF-8 with an FfzError,
        # as the Rust reader does (issue 48, item 17: a group name's length running
        # past the block raised struct.error, a string not UTF-8 UnicodeDecodeError).
        end = meta_len - 4
        p = HEADER_LEN
        method = _meta_text(path, meta, p, mlen, end, "method")
        p += mlen
        params = _meta_text(path, meta, p, plen, end, "params")
        p += plen
        created = _meta_text(path, meta, p, clen, end, "created")
        p += clen
        rec = np.frombuffer(meta, dtype=PATCH_DTYPE, count=n, offset=p)
        p += n * PATCH_LEN
        ngroups = _u32(meta, p)  # inside the body: meta_len was checked above
        p += 4
        groups = []
        for g in range(ngroups):
            if p + 4 > end:
                raise FfzError(f"{path}: header at byte {p}: group {g} name cut short ({ngroups} groups)")
            ln = _u32(meta, p)
            groups.append(_meta_text(path, meta, p + 4, ln, end, "group name"))
            p += 4 + ln
        clusters = None
        if flags & HEADER_FLAG_CLUSTERS:  # spec 4.3: a permutation of the patches
            if p + 4 * n > meta_len - 4:
                raise FfzError(f"{path}: header at byte {p}: cluster order cut short")
            clusters = np.frombuffer(meta, dtype="<u4", count=n, offset=p).copy()
            if n and (int(clusters.max()) >= n or len(np.unique(clusters)) != n):
                raise FfzError(f"{path}: header at byte {p}: the cluster order is not a permutation of the patches")
            p += 4 * n
        if p != meta_len - 4:
            raise FfzError(f"{path}: header at byte {p}: meta block length mismatch")
        if n and (np.any((rec["n_corners"] != 3) & (rec["n_corners"] != 4)) or np.any(rec["group"] >= ngroups) or np.any(rec["reserved"] != 0)):
            raise FfzError(f"{path}: header: bad patch record")
        self.n, self.k, self.zstd_level, self.scene_hash = n, k, level, scene_hash
        self.layout = "topk" if layout == 1 else "dense"
        self.method, self.params, self.created = method, params, created
        self.patches = {name: rec[name].copy() for name in PATCH_DTYPE.names if name != "reserved"}
        self.groups = groups
        self._sparse = layout == 1
        self._meta_len = meta_len
        # spec 4.3: position -> patch; links (5.7) name ranges of positions. None when
        # the rows carry no links.
        self.cluster_order = clusters
        self._links = {}  # row -> (starts, lengths, values, slopes) of the rows read so far
        self._link_errors = {}  # row -> the writer's link error (spec 5.7, LINK_ERROR) of the rows read so far

    def _read_index(self):
        """Footer then index (spec 7, 6); raises ValueError with the offset."""
        buf, n, meta_len = self._mm, self.n, self._meta_len
        size = len(buf)
        if size < meta_len + FOOTER_LEN:
            raise ValueError(f"byte {size}: no room for a footer")
        f = size - FOOTER_LEN
        foot = buf[f:]
        if foot[24:] != FOOTER_MAGIC:
            raise ValueError(f"byte {f + 24}: no footer magic")
        ioff, ilen, icrc, fcrc = struct.unpack_from("<QQII", foot, 0)
        if not self._crc_ok(foot[:20], fcrc):
            raise ValueError(f"byte {f + 20}: footer checksum mismatch")
        if ioff < meta_len or ioff + ilen != f:
            raise ValueError(f"byte {f}: index placed outside the file")
        ix = buf[ioff:f]
        if not self._crc_ok(ix, icrc):
            raise ValueError(f"byte {f + 16}: index checksum mismatch")
        if ix[:4] != INDEX_MAGIC:
            raise ValueError(f"byte {ioff}: bad index magic")
        flags = _u32(ix, 4)
        if flags & ~(INDEX_FLAG_ROUTES | INDEX_FLAG_ROUTES_UNMET) or flags == INDEX_FLAG_ROUTES_UNMET:
            raise ValueError(f"byte {ioff + 4}: unknown index flags {flags:#x}")
        nch, nrows = _u64(ix, 8), _u64(ix, 16)
        unmet = bool(flags & INDEX_FLAG_ROUTES_UNMET)
        extra = (ROUTES_LEN + 8 * unmet) if flags & INDEX_FLAG_ROUTES else 0
        if nrows != n or ilen != 24 + 8 * nch + 8 * nrows + extra:
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
        routes = None
        if extra:
            at = 24 + 8 * nch + 8 * n
            counts = struct.unpack_from("<10Q" if unmet else "<9Q", ix, at)
            routes = dict(zip(ROUTE_FIELDS, counts + (0,) * (len(ROUTE_FIELDS) - len(counts))))
            r = routes
            partly = r["exact"] - r["exact_visible"] - r["exact_hidden"]
            if (r["rows"] > n or r["unoccludable"] + r["exact"] + r["rays"] > r["evaluated"]
                    or r["fallback"] > r["rays"] or partly < 0
                    or (unmet and not 0 < r["exact_unmet"] <= partly)):
                raise ValueError(f"byte {ioff + at}: route record counts that cannot hold together")
        self.routes = routes
        return offsets.tolist(), chunk.copy(), state.astype(np.uint8), ioff

    def _read_index_or_scan(self):
        n = self.n
        try:
            offsets, row_chunk, presence, area_end = self._read_index()
        except ValueError as why:
            self.indexed = False
            self.routes = None
            spans, bad, dirs = self._scan()
            self._spans = spans
            row_chunk = np.full(n, NO_CHUNK, dtype=np.uint32)
            presence = np.zeros(n, dtype=np.uint8)
            self.warnings.append(f"{self.path}: footer or index unusable ({why}); recovered {len(spans)} chunks by scanning")
            self.warnings += [f"{self.path}: bytes {a}..{b} skipped: {r}" for a, b, r in bad]
            for c, (row, skipped) in enumerate(dirs):  # spec 8, step 4: the first copy of a row wins
                taken = row_chunk[row] != NO_CHUNK
                for r in row[taken]:
                    self.warnings.append(f"{self.path}: row {int(r)} repeated in chunk {c}; first copy kept")
                fresh = ~taken
                row_chunk[row[fresh]] = c
                presence[row[fresh]] = np.where(skipped[fresh], SKIPPED_STATE, PRESENT)
            self._held = None
        else:
            self.indexed = True
            ends = offsets[1:] + [area_end]
            self._spans = list(zip(offsets, ends))
            self._held = np.bincount(row_chunk[presence != MISSING].astype(np.int64), minlength=len(offsets))
        self._row_chunk = row_chunk
        self.presence = presence
        self.presence.flags.writeable = False

    def _scan(self):
        """Recovery scan (spec 8): every good chunk, skipping unreadable regions.
        Returns the chunks' (start, end), the bad regions and each chunk's rows."""
        spans, bad, dirs = [], [], []
        pos, end = self._meta_len, len(self._mm)
        open_bad = None
        while pos < end:
            try:
                length, _, _, (row, skipped, _, _) = self._read_chunk(pos, end)
            except ValueError as e:
                if open_bad is None:
                    open_bad = [pos, end, f"{e} (at byte {pos})"]
                nxt = self._mm.find(CHUNK_MAGIC, pos + 1)
                if nxt < 0:
                    break
                pos = nxt
                continue
            if open_bad is not None:
                open_bad[1] = pos
                bad.append(tuple(open_bad))
                open_bad = None
            spans.append((pos, pos + length))
            dirs.append((row.copy(), skipped))
            pos += length
        if open_bad is not None:
            bad.append(tuple(open_bad))
        return spans, bad, dirs

    # --- chunks (spec 5) ---------------------------------------------------------------

    def _read_chunk(self, pos, end):
        """Header, checksums, decompression and directory of the chunk at pos (the
        checks of spec 5.1-5.3, in the spec's order); ValueError on the first failure.
        Returns (record length, shuffled, payload, directory)."""
        if end - pos < CHUNK_HEADER_LEN:
            raise ValueError(f"chunk header cut short ({end - pos} bytes)")
        mv = self._mv
        h = bytes(mv[pos : pos + CHUNK_HEADER_LEN])
        if h[:4] != CHUNK_MAGIC:
            raise ValueError(f"bad chunk magic {h[:4].hex()}")
        flags, clen, rlen, rows, crc_c, crc_r, crc_h = struct.unpack_from("<IQQIIII", h, 4)
        if not self._crc_ok(h[:36], crc_h):
            raise ValueError("chunk header checksum mismatch")
        if flags & ~SHUFFLED:
            raise ValueError(f"unknown chunk flags {flags:#x}")
        if pos + CHUNK_HEADER_LEN + clen > end:
            raise ValueError(f"chunk cut short: needs {CHUNK_HEADER_LEN + clen} bytes, {end - pos} remain")
        n = self.n
        with mv[pos + CHUNK_HEADER_LEN : pos + CHUNK_HEADER_LEN + clen] as payload:  # no copy
            if not self._crc_ok(payload, crc_c):
                raise ValueError("compressed payload checksum mismatch")
            if rlen < DIR_LEN * rows or rlen > rows * (DIR_LEN + 4 + 32 * n) or rows > n:
                raise ValueError(f"raw length {rlen} impossible for {rows} rows")
            try:
                said = zstandard.frame_content_size(payload)
                if said >= 0 and said != rlen:  # refused before a wrong-sized allocation
                    raise ValueError(f"zstd frame holds {said} bytes, header says {rlen}")
                raw = _decompressor().decompress(payload, max_output_size=rlen)
            except zstandard.ZstdError as e:
                raise ValueError(f"zstd payload does not decompress: {e}") from None
        if len(raw) != rlen:
            raise ValueError(f"payload decompresses to {len(raw)} bytes, header says {rlen}")
        if not self._crc_ok(raw, crc_r):
            raise ValueError("decompressed payload checksum mismatch")
        d = np.frombuffer(raw, dtype="<u4", count=6 * rows).reshape(rows, 6)
        if self.cluster_order is not None:
            raw, d, links, errors = _split_links(raw, d, n, bool(flags & SHUFFLED))
            rlen = len(raw)
            self._links.update(links)
            self._link_errors.update(errors)
        elif np.any(d[:, 1] & LINKS):
            j = int(np.flatnonzero(d[:, 1] & LINKS)[0])
            raise ValueError(f"row {int(d[j, 0])}: links in a file without a cluster order")
        return CHUNK_HEADER_LEN + clen, bool(flags & SHUFFLED), raw, _check_directory(d, rlen, self.n, self._sparse, self.k)

    def _decode(self, c) -> Chunk:
        """Chunk c read, decoded and checked against the index (spec 9.3)."""
        pos, end = self._spans[c]
        try:
            return self._decode_checked(c, pos, end)
        except ValueError as e:
            raise FfzError(f"{self.path}: chunk {c} at byte {pos}: {e}") from None

    def _decode_checked(self, c, pos, end) -> Chunk:
        n = self.n
        _, shuffled, raw, (row, skipped, nnz, dropped) = self._read_chunk(pos, end)
        entries = len(row)
        present = np.flatnonzero(~skipped)
        u8 = np.frombuffer(raw, dtype=np.uint8, offset=DIR_LEN * entries)
        start = np.zeros(entries, dtype=np.int64)
        bad_delta = bad_col = None
        cols = None
        if not self._sparse:  # spec 5.4: n f32 per present row
            start[present] = np.arange(len(present), dtype=np.int64) * n
            if shuffled:
                vals = _unshuffle_uniform(u8, len(present), n).view("<f4").reshape(-1)
            else:
                vals = u8[: 4 * n * len(present)].view("<f4")
        else:  # spec 5.4: per present row nnz column deltas then nnz values
            m = nnz[present].astype(np.int64)
            first = _excl_cumsum(m)
            start[present] = first
            bad_delta = np.zeros(entries, dtype=bool)
            bad_col = np.zeros(entries, dtype=bool)
            deltas, vals = _sparse_words(u8, m, shuffled)
            cs = np.cumsum(deltas, dtype=np.uint64)  # columns: per-row running sums of deltas
            has = m > 0
            base = np.zeros(len(m), dtype=np.uint64)
            later = has & (first > 0)
            base[later] = cs[first[later] - 1]
            colv = cs - np.repeat(base, m)
            zero = deltas == 0
            zero[first[has]] = False  # the first delta is the first column: 0 is fine
            hit = np.searchsorted(first, np.flatnonzero(zero), side="right") - 1
            bad_delta[present[hit]] = True
            bad_col[present[has]] = colv[first[has] + m[has] - 1] >= n
            cols = colv.astype(np.uint32)
        state = np.where(skipped, SKIPPED_STATE, PRESENT).astype(np.uint8)
        rc = self._row_chunk[row]
        checks = [
            (bad_delta, lambda j: f"row {int(row[j])}: column delta 0"),
            (bad_col, lambda j: f"row {int(row[j])}: column >= n"),
        ]
        if self.indexed:  # spec 9.3: the chunk holds the rows the index says it does
            checks += [
                (rc != c, lambda j: f"holds row {int(row[j])} which the index puts in chunk {int(rc[j])}"),
                (self.presence[row] != state, lambda j: f"row {int(row[j])}: skipped flag disagrees with the index"),
            ]
        msg = _first_failure(checks)
        if msg:
            raise ValueError(msg)
        if self.indexed:
            if entries != self._held[c]:
                mine = np.flatnonzero((self._row_chunk == c) & (self.presence != MISSING))
                i = int(mine[~np.isin(mine, row)][0])
                raise ValueError(f"the index puts row {i} here but the chunk does not hold it")
            keep = None
        else:
            keep = rc == c  # a later copy of a row (spec 8, step 4) is left out
            if keep.all():
                keep = None
        if keep is not None:
            row, state, nnz, dropped, start = row[keep], state[keep], nnz[keep], dropped[keep], start[keep]
        nnz = np.where(state == PRESENT, nnz, 0).astype(np.uint32)
        return Chunk(c, pos, n, row.copy(), state, nnz, dropped.copy(), start, vals, cols)

    def _chunk(self, c) -> Chunk:
        """Chunk c through the LRU cache."""
        ch = self._cache.get(c)
        if ch is not None:
            self._cache.move_to_end(c)
            return ch
        ch = self._decode(c)
        if self._cache_size:
            self._cache[c] = ch
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return ch

    # --- public --------------------------------------------------------------------------

    @property
    def n_chunks(self) -> int:
        return len(self._spans)

    @property
    def chunk_offsets(self) -> list:
        """Byte offset of each chunk, in chunk-number order."""
        return [a for a, _ in self._spans]

    def _check_open(self):
        if self._mv is None:
            raise ValueError(f"{self.path}: reader is closed")

    def row(self, i) -> Optional[RowData]:
        """Row i as RowData(cols, vals, dropped), or None when it is missing (see the
        module docstring for dense and skipped rows). Reads only row i's chunk."""
        self._check_open()
        i = int(i)
        if not 0 <= i < self.n:
            raise IndexError(f"row {i} out of range (n = {self.n})")
        state = self.presence[i]
        if state == MISSING:
            return None
        if state == SKIPPED_STATE:
            return RowData(np.zeros(0, np.uint32), np.zeros(0, np.float32), 0.0)
        return self._chunk(int(self._row_chunk[i])).row(i)

    def links(self, i):
        """Row i's links to clusters (spec 5.7) as (starts, lengths, values, slopes):
        starts and lengths over positions of `cluster_order`, slopes an (m, 3) array
        (zeros for a row written without SLOPES); empty arrays for a row without links
        (or a file without a cluster order). Reads row i's chunk if it was not read yet."""
        i = int(i)
        if self.cluster_order is not None and i not in self._links and self.presence[i] == PRESENT:
            self._decode(int(self._row_chunk[i]))
        empty = (np.zeros(0, np.uint32), np.zeros(0, np.uint32), np.zeros(0, np.float32), np.zeros((0, 3), np.float32))
        return self._links.get(i, empty)

    def link_error(self, i):
        """Row i's link error as the writer estimated it (spec 5.7, LINK_ERROR: the
        relative error its links may make in the radiosity the row gathers), or None
        for a row without one. Reads row i's chunk if it was not read yet."""
        self.links(i)
        return self._link_errors.get(int(i))

    def link_errors(self) -> np.ndarray:
        """Every row's link error (link_error), NaN for a row without one; reads every
        chunk."""
        out = np.full(self.n, np.nan)
        for i in range(self.n):
            e = self.link_error(i)
            if e is not None:
                out[i] = e
        return out

    def centroids(self) -> np.ndarray:
        """Patch centroids x_j as spec 5.7 defines them, (n, 3) float64: a triangle's
        corner mean; a quadrilateral's area-weighted mean of the centroids of its
        triangles 0-1-2 and 0-2-3."""
        c = self.patches["corners"].astype(np.float64)
        g1 = (c[:, 0] + c[:, 1] + c[:, 2]) / 3.0
        g2 = (c[:, 0] + c[:, 2] + c[:, 3]) / 3.0
        a1 = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
        a2 = np.linalg.norm(np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 0]), axis=1)
        tot = a1 + a2
        with np.errstate(invalid="ignore", divide="ignore"):
            quad = np.where((tot > 0)[:, None], (g1 * a1[:, None] + g2 * a2[:, None]) / tot[:, None], 0.5 * (g1 + g2))
        return np.where((self.patches["n_corners"] == 3)[:, None], g1, quad)

    def link_matrix(self) -> scipy.sparse.csr_matrix:
        """The links expanded into patch entries, n x n float64; add to_csr() for the
        whole matrix. Empty without links. Spec 5.7: over each link's patches j (those
        in its range that are not a kept column of row i and not i),
        F_ij = F_iL w_j / sum(w), w_j = A_j (1 + q_L . (x_j - mean_L)), mean_L the
        area-weighted mean centroid of the whole range, q_L the link's slope. Some
        entries may be negative where a slope takes weights below zero (spec 5.7: the
        weights are the rule a link gathers by, not single form factors); each link's
        entries still sum to F_iL."""
        n = self.n
        kept = self.to_csr()
        area = self.patches["area"].astype(np.float64)
        order = self.cluster_order
        rows, cols, vals = [], [], []
        if order is not None:
            x = self.centroids()
            for i in range(n):
                starts, lens, values, slopes = self.links(i)
                if not len(starts):
                    continue
                own = set(kept.indices[kept.indptr[i] : kept.indptr[i + 1]].tolist()) | {i}
                for a, ln, v, q in zip(starts.tolist(), lens.tolist(), values.tolist(), slopes.astype(np.float64)):
                    js = order[a : a + ln].astype(np.int64)
                    mean = area[js] @ x[js] / area[js].sum()
                    js = js[~np.isin(js, list(own))]
                    whole = area[order[a : a + ln]].sum()
                    w = area[js] * (1.0 + (x[js] - mean) @ q)
                    if not w.sum() > FLAT_WEIGHT * whole:  # kept columns hold (almost) all the weight: by area
                        w = area[js]
                    if w.sum() > 0:
                        rows.append(np.full(len(js), i))
                        cols.append(js)
                        vals.append(v * w / w.sum())
        if not rows:
            return scipy.sparse.csr_matrix((n, n), dtype=np.float64)
        r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        return scipy.sparse.csr_matrix((v, (r, c)), shape=(n, n))

    def link_operator(self) -> scipy.sparse.linalg.LinearOperator:
        """The links as an n x n scipy LinearOperator: `op @ b` (b of n values, or n x m)
        is link_matrix() @ b without expanding the links, in O(links + n) a product
        (spec 5.7's weights, summed through prefix sums over the cluster order, as
        ffstream's solver gathers). Add to_csr() @ b for the whole matrix; so a solve
        of a 10^5-patch linked file needs no n x n matrix. Zero without links."""
        n = self.n
        order = self.cluster_order
        parts = [self.links(i) for i in range(n)] if order is not None else []
        counts = np.array([len(p[0]) for p in parts], dtype=np.int64)
        if not counts.sum():
            return scipy.sparse.linalg.LinearOperator((n, n), matvec=lambda b: np.zeros(n), matmat=lambda b: np.zeros((n, b.shape[1])), dtype=np.float64)
        row = np.repeat(np.arange(n, dtype=np.int64), counts)
        start = np.concatenate([p[0] for p in parts]).astype(np.int64)
        end = start + np.concatenate([p[1] for p in parts]).astype(np.int64)
        value = np.concatenate([p[2] for p in parts]).astype(np.float64)
        slope = np.concatenate([p[3] for p in parts]).astype(np.float64)
        area = self.patches["area"].astype(np.float64)
        x = self.centroids()
        pos = np.empty(n, dtype=np.int64)
        pos[order] = np.arange(n)
        pa = np.concatenate([[0.0], np.cumsum(area[order])])
        px = np.vstack([np.zeros(3), np.cumsum(area[order, None] * x[order], axis=0)])
        a_range = pa[end] - pa[start]
        mean = (px[end] - px[start]) / a_range[:, None]
        # The patches in a link's range that are not its own: the row's kept columns
        # and the row patch, found by their position in the row's ascending links.
        kept = self.to_csr()
        pairs = np.unique(np.concatenate([np.repeat(np.arange(n, dtype=np.int64), np.diff(kept.indptr)) * n + kept.indices, np.arange(n, dtype=np.int64) * (n + 1)]))
        kr, kj = pairs // n, pairs % n
        key = row * n + start
        k = np.searchsorted(key, kr * n + pos[kj], side="right") - 1
        inside = (k >= 0) & (row[np.maximum(k, 0)] == kr) & (pos[kj] < end[np.maximum(k, 0)])
        out_link, out_patch = k[inside], kj[inside]

        def weights(q):
            w = a_range - np.bincount(out_link, weights=area[out_patch] * (1.0 + np.einsum("ij,ij->i", x[out_patch] - mean[out_link], q[out_link])), minlength=len(row))
            return w

        w = weights(slope)
        flat = ~(w > FLAT_WEIGHT * a_range) & np.any(slope != 0, axis=1)  # kept columns hold (almost) all the weight: by area
        q = np.where(flat[:, None], 0.0, slope)
        w = weights(q) if flat.any() else w
        use = w > 0
        scale = np.where(use, value / np.where(use, w, 1.0), 0.0)
        out_w = area[out_patch] * (1.0 + np.einsum("ij,ij->i", x[out_patch] - mean[out_link], q[out_link]))

        def matmat(b):
            b = np.asarray(b, dtype=np.float64).reshape(n, -1)
            ab = np.vstack([np.zeros((1, b.shape[1])), np.cumsum(area[order, None] * b[order], axis=0)])
            axb = np.concatenate([np.zeros((1, 3, b.shape[1])), np.cumsum(area[order, None, None] * x[order, :, None] * b[order, None, :], axis=0)])
            s_ab = ab[end] - ab[start]  # links x m
            total = s_ab.copy()
            for d in range(3):  # one coordinate at a time: no links x 3 x m temporary
                total += q[:, d, None] * (axb[end, d] - axb[start, d] - mean[:, d, None] * s_ab)
            m = b.shape[1]
            less = np.stack([np.bincount(out_link, weights=out_w * b[out_patch, c], minlength=len(row)) for c in range(m)], axis=1)
            gathered = scale[:, None] * (total - less)
            return np.stack([np.bincount(row, weights=gathered[:, c], minlength=n) for c in range(m)], axis=1)

        return scipy.sparse.linalg.LinearOperator((n, n), matvec=lambda b: matmat(b)[:, 0], matmat=matmat, dtype=np.float64)

    def chunk_of(self, i) -> Optional[int]:
        """Number of the chunk holding row i (present or skipped), or None (missing)."""
        i = int(i)
        if not 0 <= i < self.n:
            raise IndexError(f"row {i} out of range (n = {self.n})")
        return None if self.presence[i] == MISSING else int(self._row_chunk[i])

    def chunk(self, c) -> Chunk:
        """Chunk number c (cached like row())."""
        self._check_open()
        if not 0 <= c < len(self._spans):
            raise IndexError(f"chunk {c} out of range ({len(self._spans)} chunks)")
        return self._chunk(int(c))

    def chunks(self):
        """The chunks in file order, decoded and checked, a few at a time."""
        self._check_open()
        it = _ordered_map(self._decode, list(range(len(self._spans))), self.threads)
        gen = self._track(it)
        return gen

    def _track(self, it):
        def gen():
            try:
                yield from it
            finally:
                it.close()

        g = gen()
        self._iters.add(g)
        return g

    @property
    def dropped(self) -> np.ndarray:
        """Dropped mass per row (spec 5.6), float32; 0 for rows not present. The first
        use reads every chunk unless to_csr() has."""
        if self._dropped is None:
            self._check_open()
            dropped = np.zeros(self.n, dtype=np.float32)
            for ch in self.chunks():
                p = ch.state == PRESENT
                dropped[ch.rows[p]] = ch.dropped[p]
            dropped.flags.writeable = False
            self._dropped = dropped
        return self._dropped

    def to_csr(self) -> scipy.sparse.csr_matrix:
        """The matrix as scipy.sparse.csr_matrix (n x n, float32), rows in row order."""
        self._check_open()
        n = self.n
        parts = []
        counts = np.zeros(n, dtype=np.int64)
        dropped = np.zeros(n, dtype=np.float32)
        it = self._track(_ordered_map(lambda c: self._decode(c)._csr_part(), list(range(len(self._spans))), self.threads))
        for part in it:
            rows, cnt, _, _, dr = part
            counts[rows] = cnt
            dropped[rows] = dr
            parts.append(part)
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        nnz = int(indptr[-1])
        big = nnz > np.iinfo(np.int32).max or n > np.iinfo(np.int32).max
        itype = np.int64 if big else np.int32
        indices = np.empty(nnz, dtype=itype)
        data = np.empty(nnz, dtype=np.float32)
        for rows, cnt, cols, vals, _ in parts:  # each chunk's rows to their places
            if not len(cols):
                continue
            dest = indptr[rows]
            src = _excl_cumsum(cnt)
            # Runs of rows that follow each other in the matrix too (all of the chunk when
            # its rows ascend): one slice copy per run when runs are long, else a scatter.
            cut = np.flatnonzero(dest[1:] != dest[:-1] + cnt[:-1]) + 1
            if len(cols) >= MIN_RUN_ENTRIES * (len(cut) + 1):
                starts = np.concatenate(([0], cut)).tolist()
                ends = cut.tolist() + [len(rows)]
                for a, b in zip(starts, ends):
                    lo, hi = int(src[a]), int(src[b - 1] + cnt[b - 1])
                    d = int(dest[a])
                    indices[d : d + hi - lo] = cols[lo:hi]
                    data[d : d + hi - lo] = vals[lo:hi]
            else:
                at = np.repeat(dest - src, cnt) + np.arange(len(cols))
                indices[at] = cols
                data[at] = vals
        parts.clear()
        dropped.flags.writeable = False
        self._dropped = dropped
        m = scipy.sparse.csr_matrix((data, indices, indptr.astype(itype)), shape=(n, n), copy=False)
        self._note_faults(m, dropped)
        return m

    def _note_faults(self, matrix, dropped):
        """Spec 10's value checks on what to_csr() read: each fault becomes a warning in
        `warnings` (once) and a RuntimeWarning, so a NaN or negative entry is never
        handed over silently. The numbers themselves are returned as stored."""
        for msg in value_faults(matrix, dropped):
            msg = f"{self.path}: {msg}"
            if msg not in self.warnings:
                self.warnings.append(msg)
                _warnings.warn(msg, RuntimeWarning, stacklevel=3)

    def read(self) -> FfzFile:
        """The whole file as an FfzFile (what `ffz.read` returns)."""
        matrix = self.to_csr()
        return FfzFile(
            path=self.path,
            n=self.n,
            layout=self.layout,
            k=self.k,
            zstd_level=self.zstd_level,
            scene_hash=self.scene_hash,
            method=self.method,
            params=self.params,
            created=self.created,
            patches=self.patches,
            groups=self.groups,
            matrix=matrix,
            dropped=self.dropped.copy(),
            presence=self.presence.copy(),
            chunks=self.n_chunks,
            indexed=self.indexed,
            warnings=list(self.warnings),
            routes=None if self.routes is None else dict(self.routes),
        )

    def close(self):
        """Release the memory map (also at the end of a `with` block)."""
        for g in list(self._iters):
            g.close()
        self._cache.clear()
        mv, mm = self._mv, self._mm
        self._mv = self._mm = None
        try:
            if mv is not None:
                mv.release()
            if mm is not None:
                mm.close()
        except BufferError:  # a view still exported somewhere: the map goes with it
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __repr__(self):
        state = "closed" if self._mv is None else f"{self.n_chunks} chunks"
        return f"<ffz.FfzReader {self.path!r}: n = {self.n}, {self.layout}, {state}>"


def open(path, verify: bool = True, threads: Optional[int] = None, cache_chunks: int = 8) -> FfzReader:  # noqa: A001
    """Open an `.ffz` file for lazy reading: header, meta block and index are read and
    checked now (or the recovery scan runs), rows and chunks when asked for.

    verify=False skips the CRC-32C checks (not the structural ones). threads: chunk
    decoders used by to_csr(), chunks() and dropped (default: the CPUs, at most 8).
    cache_chunks: decoded chunks kept for row() and chunk()."""
    return FfzReader(path, verify=verify, threads=threads, cache_chunks=cache_chunks)


def read(path, verify: bool = True, threads: Optional[int] = None) -> FfzFile:
    """Read a whole `.ffz` file into memory as a CSR matrix plus metadata.

    verify=False skips the CRC-32C checks (not the structural ones): only when speed
    matters more than detecting damage (the checks cost little with the crc32c package).
    """
    with open(path, verify=verify, threads=threads, cache_chunks=0) as f:
        return f.read()


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
    with builtins.open(os.path.join(out_dir, "meta.json"), "w") as fh:
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
        # The command line prints every warning below, once: the RuntimeWarnings that
        # a library caller gets for the same faults would say each a second time.
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore", RuntimeWarning)
            f = read(argv[0])
    except (FfzError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    p = f.presence
    print(f"{f.path}: n = {f.n}, layout {f.layout} (k = {f.k}), method {f.method} [{f.params}]")
    print(f"rows: {int((p == PRESENT).sum())} present, {int((p == SKIPPED_STATE).sum())} skipped, {int((p == MISSING).sum())} missing; {f.matrix.nnz} stored entries in {f.chunks} chunks")
    for w in f.warnings:
        print(f"warning: {w}")
    if len(argv) >= 3 and argv[1] == "--dump":
        dump(f, argv[2])
    return 3 if value_faults(f.matrix, f.dropped) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
