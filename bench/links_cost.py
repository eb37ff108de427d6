#!/usr/bin/env python3
"""The CPU of links against the pool, in one run (issue 44's cost target, bench/LINKS.md).

    python3 bench/links_cost.py [--patches N] [--rounds R] [--bin FFSTREAM]
                                [--other-bin FFSTREAM2] [--lanes] [--out DIR]

Computes `builtin:room --patches N --top-k 64` with `--links off` (the pool) and with
`--links 256` (the default), interleaved (pool, links, links, pool, ... so that a drift
of the machine's speed falls on both), and prints each run's CPU (user + sys of the
process and its threads, from os.wait4: the set-up pass that estimates the first bounce
counts, as the issue asks) and the ratio of the medians. With --other-bin, the links of
a second build run beside the first's (an A/B of two builds; the pool is the first
build's). With --lanes, two runs go at once on one thread each (links on one lane, the
pool twice on the other; with --other-bin, one build's links on each lane), so that both
see the same load on a shared machine.

The files go to DIR (default: a temporary directory, removed afterwards).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time


def start(binary, links, patches, out, threads):
    cmd = [binary, "compute", "builtin:room", "--patches", str(patches), "--top-k", "64",
           "--links", links, "-q", "--force", "-o", out]
    if threads:
        cmd += ["--threads", str(threads)]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def finish(p, name):
    _, status, ru = os.wait4(p.pid, 0)
    err = p.stderr.read().decode(errors="replace")
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"links_cost.py: {name} failed:\n{err}")
    return ru.ru_utime + ru.ru_stime


def load():
    try:
        return open("/proc/loadavg").read().split()[0]
    except OSError:
        return "?"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--patches", type=int, default=100000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--bin", default="target/release/ffstream")
    ap.add_argument("--other-bin")
    ap.add_argument("--lanes", action="store_true")
    ap.add_argument("--out")
    a = ap.parse_args()
    out = a.out or tempfile.mkdtemp(prefix="links_cost.")
    os.makedirs(out, exist_ok=True)
    runs = {"pool": [], "links": [], "links (other)": []}

    def f(name, k):
        return os.path.join(out, f"{name.split()[0]}{k}.ffz")

    def say(name, cpu):
        runs[name].append(cpu)
        print(f"{time.strftime('%H:%M:%S')} {name:14} CPU {cpu:8.2f} s  load {load()}", flush=True)

    for k in range(a.rounds):
        if a.lanes:
            # Lane one: links; lane two: the other build's links, or the pool twice.
            p1 = start(a.bin, "256", a.patches, f("links", k), 1)
            if a.other_bin:
                p2 = start(a.other_bin, "256", a.patches, f("other", k), 1)
                say("links", finish(p1, "links"))
                say("links (other)", finish(p2, "other"))
            else:
                for j in range(2):
                    say("pool", finish(start(a.bin, "off", a.patches, f("pool", 2 * k + j), 1), "pool"))
                say("links", finish(p1, "links"))
            continue
        order = ["pool", "links"] if k % 2 == 0 else ["links", "pool"]
        if a.other_bin:
            order.insert(1 if k % 2 == 0 else 0, "links (other)")
        for name in order:
            binary = a.other_bin if name == "links (other)" else a.bin
            links = "off" if name == "pool" else "256"
            say(name, finish(start(binary, links, a.patches, f(name, k), None), name))
    med = {n: statistics.median(v) for n, v in runs.items() if v}
    if "pool" in med:
        for n in ("links", "links (other)"):
            if n in med:
                print(f"{n}: median {med[n]:.2f} s, {med[n] / med['pool']:.2f}x the pool's {med['pool']:.2f} s")
    if "links (other)" in med:
        print(f"links against the other build's: {med['links'] / med['links (other)']:.3f}x")
    if not a.out:
        shutil.rmtree(out)


if __name__ == "__main__":
    main()
