#!/usr/bin/env python3
"""Speed of the Python .ffz reader (formats/ffz.py, package ffstream-ffz).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install ./formats
    /tmp/v/bin/python bench/python_reader.py [--bin target/release/ffstream] [--file X.ffz]

Makes a dense file of about --target-mb MB (default 100) with `ffstream compute
builtin:room:20` (the patch count is adjusted once if the first file misses the size by
more than 10 %), or uses --file. Then times, best and median of --repeat runs:

- ffz.read(path): the whole file into a CSR matrix, every checksum checked (the figure
  quoted in the docs), also with threads=1 and with verify=False;
- ffz.open(path).to_csr();
- ffz.open(path): header, patch table and index only;
- row(i) of --rows random present rows on a freshly opened file (each decodes its
  chunk), then the same rows again (from the chunk cache).

MB/s = file bytes / wall seconds (1 MB = 10^6 bytes). The file is read from the page
cache (it was just written or read), so this is the reader's speed, not the disk's.
Imports the installed `ffz` when there is one, else formats/ffz.py of this tree.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import statistics
import struct
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

try:
    import ffz
except ImportError:
    sys.path.insert(0, os.path.join(ROOT, "formats"))
    import ffz

import numpy as np
import scipy
import zstandard


def version_of(dist: str) -> str:
    try:
        from importlib.metadata import PackageNotFoundError, version
    except ImportError:  # pragma: no cover - Python < 3.8
        return "?"
    try:
        return version(dist)
    except PackageNotFoundError:
        return "not installed"


def loadavg() -> str:
    try:
        with open("/proc/loadavg") as fh:
            return fh.read().strip()
    except OSError:
        return "n/a"


def git_head() -> str:
    try:
        head = subprocess.run(["git", "-C", ROOT, "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True).stdout.strip()
        return head + (" (modified)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "n/a"


def make_file(binary: str, path: str, target_mb: float, patches: int) -> None:
    for attempt in range(2):
        cmd = [binary, "compute", "builtin:room:20", "--patches", str(patches), "-o", path, "--quiet", "--force"]
        print("$ " + " ".join(cmd), flush=True)
        t = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        mb = os.path.getsize(path) / 1e6
        print(f"  {mb:.1f} MB in {time.perf_counter() - t:.1f} s", flush=True)
        if attempt or abs(mb / target_mb - 1) <= 0.10:
            return
        patches = int(patches * (target_mb / mb) ** 0.5)  # dense: size grows as n^2


def timed(fn, repeat: int):
    times, result = [], None
    for _ in range(repeat):
        result = None  # the previous result freed before the next run
        t = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times), result


def raw_bytes(path: str) -> int:
    """Sum of the chunks' raw_len (spec 5.1)."""
    total = 0
    with ffz.open(path, verify=False) as f, open(path, "rb") as fh:
        for off in f.chunk_offsets:
            fh.seek(off + 16)
            total += struct.unpack("<Q", fh.read(8))[0]
    return total


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "ffstream"), help="ffstream binary (to make the file)")
    ap.add_argument("--file", help="time this .ffz file instead of making one")
    ap.add_argument("--target-mb", type=float, default=100.0, help="size of the file to make, MB (default 100)")
    ap.add_argument("--patches", type=int, default=9000, help="first patch count tried (default 9000: ~98 MB)")
    ap.add_argument("--repeat", type=int, default=5, help="runs per measurement (default 5)")
    ap.add_argument("--rows", type=int, default=20, help="random rows for the row(i) timing (default 20)")
    ap.add_argument("--work", help="directory for the made file (default: a temporary one, removed)")
    args = ap.parse_args()

    tmp = None
    if args.file:
        path = args.file
    else:
        work = args.work or (tmp := tempfile.mkdtemp(prefix="ffz-bench-"))
        path = os.path.join(work, "room.ffz")
        make_file(args.bin, path, args.target_mb, args.patches)
    try:
        return run(path, args)
    finally:
        if tmp:
            os.remove(path)
            os.rmdir(tmp)


def run(path: str, args) -> int:
    size = os.path.getsize(path)
    mb = size / 1e6
    load_start = loadavg()
    with ffz.open(path) as f:
        n, layout, chunks, threads = f.n, f.layout, f.n_chunks, f.threads
        present = np.flatnonzero(f.presence == ffz.PRESENT)
        rng = random.Random(1)
        one_per_chunk = {}  # random present rows, each from another chunk
        for i in rng.sample(list(present), len(present)):
            one_per_chunk.setdefault(f.chunk_of(i), int(i))
            if len(one_per_chunk) == args.rows:
                break
        pick = sorted(one_per_chunk.values())
    raw = raw_bytes(path)

    print(f"file: {path}: {size} bytes ({mb:.1f} MB), n = {n}, {layout}, {chunks} chunks, raw {raw / 1e6:.1f} MB (ratio {raw / size:.2f})")
    print(f"python {platform.python_version()} ({platform.python_implementation()}), {platform.machine()}, {os.cpu_count()} CPUs; ffz {ffz.__version__} from {ffz.__file__}")
    print(f"ffstream-ffz {version_of('ffstream-ffz')}, numpy {np.__version__}, scipy {scipy.__version__}, zstandard {zstandard.__version__} (libzstd {zstandard.ZSTD_VERSION[0]}.{zstandard.ZSTD_VERSION[1]}.{zstandard.ZSTD_VERSION[2]}), crc32c {version_of('crc32c')}")
    print(f"CRC-32C: {ffz.CRC_IMPLEMENTATION}; decoding threads: {threads}")
    print(f"git HEAD {git_head()}; load average at start: {load_start}")
    print()

    ffz.read(path)  # warm-up: page cache, imports, allocator
    rows = []

    def line(what, best, median):
        rows.append((what, best, median))
        print(f"{what:44s} best {best:7.3f} s  {mb / best:7.1f} MB/s   median {median:7.3f} s  {mb / median:7.1f} MB/s", flush=True)

    best, med, full = timed(lambda: ffz.read(path), args.repeat)
    line("ffz.read(path)  [verify]", best, med)
    def open_to_csr():
        with ffz.open(path) as f:
            return f.to_csr()

    best, med, m = timed(open_to_csr, args.repeat)
    line("ffz.open(path).to_csr()  [verify]", best, med)
    same = (m != full.matrix).nnz == 0 and m.dtype == full.matrix.dtype and m.nnz == full.matrix.nnz
    del m
    best, med, _ = timed(lambda: ffz.read(path, threads=1), args.repeat)
    line("ffz.read(path, threads=1)  [verify]", best, med)
    best, med, _ = timed(lambda: ffz.read(path, verify=False), args.repeat)
    line("ffz.read(path, verify=False)", best, med)
    nnz = full.matrix.nnz
    del full

    best, med, _ = timed(lambda: ffz.open(path).close(), args.repeat)
    print(f"{'ffz.open(path) (header, patches, index)':44s} best {best * 1e3:7.2f} ms   median {med * 1e3:7.2f} ms")
    cold, warm = [], []
    for _ in range(args.repeat):
        with ffz.open(path, cache_chunks=len(pick)) as f:
            for i in pick:
                t = time.perf_counter()
                f.row(i)
                cold.append(time.perf_counter() - t)
            for i in pick:
                t = time.perf_counter()
                f.row(i)
                warm.append(time.perf_counter() - t)
    print(f"{'row(i), first in its chunk (decodes it)':44s} median {statistics.median(cold) * 1e3:7.2f} ms   max {max(cold) * 1e3:7.2f} ms   ({len(pick)} random rows of different chunks, x {args.repeat})")
    print(f"{'row(i), chunk cached':44s} median {statistics.median(warm) * 1e6:7.1f} us")
    print()
    print(f"stored entries {nnz}; open().to_csr() == read().matrix: {same}; load average at end: {loadavg()}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
