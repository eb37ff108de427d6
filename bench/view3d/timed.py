#!/usr/bin/env python3
"""Run one command and record its CPU time (user + system of the process and its threads).

    python3 timed.py TIMES.json NAME [--cwd DIR] [--log FILE] [--rows-computed K --rows-total N] -- CMD ARGS...

The CPU time comes from os.wait4() on the child, i.e. that child alone (the same as a
getrusage(RUSAGE_CHILDREN) delta, but right even when other jobs run at the same time).
The entry NAME of TIMES.json (created if missing) gets cpu_s, user_s, sys_s, wall_s,
max_rss_mb, rc, cmd, cwd, loadavg before/after; with --rows-computed / --rows-total
(a run of sampled rows) also the CPU extrapolated to all rows. Exits with the command's
status. stdout and stderr of the command go to --log (default: NAME.log beside TIMES.json).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time


def loadavg():
    try:
        return open("/proc/loadavg").read().split()[:3]
    except OSError:
        return None


def main(argv):
    if "--" not in argv:
        sys.exit(__doc__)
    k = argv.index("--")
    opts, cmd = argv[:k], argv[k + 1:]
    if len(opts) < 2 or not cmd:
        sys.exit(__doc__)
    times, name = opts[0], opts[1]
    rest = opts[2:]
    cwd = None
    log = None
    rows_c = rows_t = None
    while rest:
        o = rest.pop(0)
        if o == "--cwd":
            cwd = rest.pop(0)
        elif o == "--log":
            log = rest.pop(0)
        elif o == "--rows-computed":
            rows_c = int(rest.pop(0))
        elif o == "--rows-total":
            rows_t = int(rest.pop(0))
        else:
            sys.exit(f"timed.py: unknown option {o}")
    log = log or os.path.join(os.path.dirname(os.path.abspath(times)), f"{name}.log")
    la0 = loadavg()
    t0 = time.time()
    with open(log, "w") as lf:
        p = subprocess.Popen(cmd, cwd=cwd, stdout=lf, stderr=subprocess.STDOUT)
        _, status, ru = os.wait4(p.pid, 0)
    wall = time.time() - t0
    rc = os.waitstatus_to_exitcode(status)
    rec = {
        "cpu_s": ru.ru_utime + ru.ru_stime, "user_s": ru.ru_utime, "sys_s": ru.ru_stime,
        "wall_s": wall, "max_rss_mb": ru.ru_maxrss / 1024.0, "rc": rc,
        "cmd": cmd, "cwd": cwd or os.getcwd(), "loadavg_before": la0, "loadavg_after": loadavg(),
    }
    if rows_c and rows_t:
        rec["rows_computed"] = rows_c
        rec["rows_total"] = rows_t
        rec["cpu_all_rows_s"] = rec["cpu_s"] * rows_t / rows_c
    # merge into TIMES.json (a lock file keeps concurrent writers apart)
    lock = times + ".lock"
    for _ in range(600):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL)
            break
        except FileExistsError:
            time.sleep(0.1)
    else:
        fd = None
    try:
        data = json.load(open(times)) if os.path.exists(times) else {}
        data[name] = rec
        with open(times + ".tmp", "w") as fh:
            json.dump(data, fh, indent=1)
        os.replace(times + ".tmp", times)
    finally:
        if fd is not None:
            os.close(fd)
            os.unlink(lock)
    print(f"  {name}: cpu {rec['cpu_s']:.2f} s, wall {wall:.2f} s, rc {rc}"
          + (f" ({rows_c} of {rows_t} rows; all rows ~{rec['cpu_all_rows_s']:.0f} CPU-s)"
             if rows_c and rows_t else ""), flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
