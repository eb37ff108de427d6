#!/usr/bin/env python3
"""Plot of per-surface error against k and against the link budget and tolerance (issue 44).

Computes `builtin:room` (16 boxes, one ceiling light) at --patches N once with dense rows
(the reference; no --top-k) and then, one compute at a time:

  (a) for each --top-k K in --ks: pooled rows (`--links off`) and linked rows
      (`--links 256`, the default);
  (b) at --top-k 64, linked rows for each link budget `--links M` in --budgets
      (the default tolerance, --link-tol 1e-3);
  (c) at --top-k 64 and `--links 4096` (so that the tolerance binds rather than the
      budget), linked rows for each `--link-tol T` in --tols.

Each file is solved with `ffstream solve F -q -o F.csv` (the default solver) and compared
per group (area-weighted mean radiosity, as `links_room.py` does) with the dense solve.
"Worst surface" is max over groups and over R, G, B of |group B / dense B - 1|, in %.
The plot (bench/plots/links_error.png by default) shows that error on log axes and, on a
second axis of each panel, the file size as % of the dense file; the pool at k = 64 is a
horizontal line in (b) and (c). A markdown table of every run goes to stdout.

    python3 bench/links_plot.py [--exe target/release/ffstream] [--patches 3000]
                                [--label "abc1234 + uncommitted change"]
                                [--save-json R.json] [--load-json R.json]

--load-json re-draws the plot and table from a previous --save-json without computing.
Needs matplotlib. 18 computes after the dense one; at 3k patches 2-25 s each on 2 cores
(about 4 minutes in all, bench/LINKS.md).
"""
import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from links_room import groups  # noqa: E402  (per-group area-weighted radiosity of a solve CSV)

EXE = os.path.join(HERE, "..", "target", "release", "ffstream")
CH = "RGB"


def info(exe, path):
    """Patch count, link statistics and the link settings recorded in the header, from `ffstream info`."""
    out = subprocess.run([exe, "info", path], check=True, capture_output=True, text=True).stdout
    n = int(re.search(r"^n:\s+(\d+) patches", out, re.M).group(1))
    m = re.search(r"^links:.*?(\d+) links, ([\d.]+) a linked row, at most (\d+)", out, re.M)
    links = (int(m.group(1)), float(m.group(2)), int(m.group(3))) if m else None
    hdr = " ".join(re.findall(r"\b(links=\S+|link_tol=\S+|top_k=\S+)", out))
    return n, links, hdr


def run(exe, patches, work, name, extra):
    """compute + solve one variant; returns a dict of what was measured (or the error)."""
    out = os.path.join(work, name + ".ffz")
    csv_path = os.path.join(work, name + ".csv")
    rec = {"name": name, "args": extra}
    try:
        t = time.time()
        subprocess.run([exe, "compute", "builtin:room", "--patches", str(patches), "-q", "-o", out, *extra],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        rec["compute_s"] = time.time() - t
        t = time.time()
        subprocess.run([exe, "solve", out, "-q", "-o", csv_path],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        rec["solve_s"] = time.time() - t
    except subprocess.CalledProcessError as e:
        rec["error"] = f"exit {e.returncode}: {(e.stderr or b'').decode(errors='replace').strip()[-300:]}"
        print(f"  {name}: FAILED ({rec['error']})", file=sys.stderr)
        return rec
    rec["bytes"] = os.path.getsize(out)
    rec["n"], rec["links"], rec["header"] = info(exe, out)
    rec["groups"] = groups(csv_path)
    os.remove(out)  # keep the scratch small; the CSV is all that is compared
    return rec


def compare(rec, ref):
    """Worst surface (signed, %), where, and the total radiosity power against dense (%)."""
    g = rec["groups"]
    worst, k, c = max((abs(g[k][1][c] / ref[k][1][c] - 1), k, c) for k in ref for c in range(3))
    signed = 100 * (g[k][1][c] / ref[k][1][c] - 1)
    power = lambda gg: sum(a * sum(b) for a, b in gg.values())
    rec["worst_pct"] = 100 * worst
    rec["worst_signed_pct"] = signed
    rec["where"] = f"{k} {CH[c]}"
    rec["power_pct"] = 100 * (power(g) / power(ref) - 1)


def compute_all(args):
    res = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
           "load_start": os.getloadavg(), "exe": os.path.abspath(args.exe), "patches": args.patches,
           "label": args.label, "k_fixed": args.k_fixed, "tol_links": args.tol_links, "runs": []}
    with tempfile.TemporaryDirectory(prefix="links_plot.") as work:
        print(f"dense reference at --patches {args.patches} ...", file=sys.stderr)
        dense = run(args.exe, args.patches, work, "dense", [])
        if "error" in dense:
            sys.exit("the dense reference failed: " + dense["error"])
        ref = dense["groups"]
        res["dense"] = {k: v for k, v in dense.items() if k != "groups"}
        plan = []
        for k in args.ks:
            plan.append(("pool", k, None, None))
            plan.append(("links", k, args.default_links, None))
        for m in args.budgets:
            plan.append(("links", args.k_fixed, m, None))
        for tol in args.tols:
            plan.append(("tol", args.k_fixed, args.tol_links, tol))
        seen = set()
        for series, k, m, tol in plan:
            key = (series, k, m, tol)
            if key in seen:  # (a)'s linked run at k = --k-fixed is also (b)'s
                continue
            seen.add(key)
            extra = ["--top-k", str(k), "--links", "off" if series == "pool" else str(m)]
            if tol is not None:
                extra += ["--link-tol", f"{tol:g}"]
            name = "_".join(x.lstrip("-") for x in extra)
            print(f"{name} ...", file=sys.stderr)
            rec = run(args.exe, args.patches, work, name, extra)
            rec.update(series=series, k=k, budget=m, tol=tol)
            if "error" not in rec:
                compare(rec, ref)
                rec["file_pct"] = 100 * rec["bytes"] / dense["bytes"]
                del rec["groups"]
                print(f"  worst {rec['worst_signed_pct']:+.2f} % ({rec['where']}), file {rec['file_pct']:.1f} %, "
                      f"compute {rec['compute_s']:.1f} s", file=sys.stderr)
            res["runs"].append(rec)
    res["load_end"] = os.getloadavg()
    return res


def pick(res, series, **kw):
    """The successful runs of a series matching kw, sorted by their x value."""
    out = [r for r in res["runs"] if "error" not in r and r["series"] == series
           and all(r.get(a) == b for a, b in kw.items())]
    return out


def table(res):
    d = res["dense"]
    lines = [f"| rows | worst surface | total radiosity power | file (of dense) | links a linked row: mean, max | compute wall |",
             "|---|---|---|---|---|---|",
             f"| dense (reference) | – | – | {d['bytes'] / 1e6:.2f} MB | – | {d['compute_s']:.1f} s |"]
    for r in res["runs"]:
        if r["series"] == "pool":
            name = f"top-k {r['k']}, pool (`--links off`)"
        elif r["series"] == "links":
            name = f"top-k {r['k']}, `--links {r['budget']}`"
        else:
            name = f"top-k {r['k']}, `--links {r['budget']} --link-tol {r['tol']:g}`"
        if "error" in r:
            lines.append(f"| {name} | failed: {r['error']} | | | | |")
            continue
        ln = f"{r['links'][1]:.1f}, {r['links'][2]}" if r["links"] else "–"
        lines.append(f"| {name} | {r['worst_signed_pct']:+.2f} % ({r['where']}) | {r['power_pct']:+.2f} % | "
                     f"{r['bytes'] / 1e6:.2f} MB ({r['file_pct']:.1f} %) | {ln} | {r['compute_s']:.1f} s |")
    return "\n".join(lines).replace("| -", "| \u2212").replace("+-", "\u2212")  # minus signs as elsewhere in LINKS.md


def plot(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, NullFormatter

    plain = FuncFormatter(lambda v, _: f"{v:g}")

    kf = res["k_fixed"]
    pool_k = pick(res, "pool", k=kf)
    fig, axes = plt.subplots(1, 3, figsize=(17, 6.6), sharey=True)
    twins = []

    def err_and_file(ax, xs, rs, label, color, marker, annot=None):
        ax.plot(xs, [r["worst_pct"] for r in rs], marker + "-", color=color, label=f"{label}: worst surface")
        tw = ax._twin
        tw.plot(xs, [r["file_pct"] for r in rs], marker + "--", color=color, mfc="none", alpha=0.7,
                label=f"{label}: file (right axis)")
        if annot:
            for x, r in zip(xs, rs):
                if r["links"]:
                    ax.annotate(annot(r), (x, r["worst_pct"]), fontsize=6, xytext=(3, 4), textcoords="offset points")

    for ax in axes:
        ax._twin = ax.twinx()
        twins.append(ax._twin)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax._twin.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.axhline(1.0, color="k", ls=":", lw=1, label="1 % (issue target, at 10k)")
        ax._twin.axhline(20.0, color="0.4", ls="-.", lw=0.8, label="1/5 of dense (issue target, at 10k)")
        ax._twin.set_ylabel("file size [% of the dense file]  (dashed, hollow)")

    # (a) against k
    ax = axes[0]
    rs = sorted(pick(res, "pool"), key=lambda r: r["k"])
    err_and_file(ax, [r["k"] for r in rs], rs, "pool (--links off)", "C3", "s")
    rs = sorted(pick(res, "links", budget=res.get("default_links", 256)), key=lambda r: r["k"])
    err_and_file(ax, [r["k"] for r in rs], rs, "links 256 (default)", "C0", "o")
    ax.set_xscale("log", base=2)
    ax.set_xticks([r["k"] for r in rs])
    ax.set_xlabel("--top-k k [entries kept a row]")
    ax.set_ylabel("worst surface |B_group / B_dense - 1| [%]  (solid)")
    ax.set_title("(a) error against k", fontsize=10)

    # (b) against the link budget
    ax = axes[1]
    rs = sorted(pick(res, "links", k=kf), key=lambda r: r["budget"])
    err_and_file(ax, [r["budget"] for r in rs], rs, f"links, k={kf}, --link-tol 1e-3", "C0", "o",
                 annot=lambda r: f"{r['links'][1]:.0f}")
    ax.set_xscale("log", base=2)
    ax.set_xticks([r["budget"] for r in rs])
    ax.set_xlabel("--links M [most links a row]")
    ax.set_title(f"(b) error against the link budget --links, k = {kf}", fontsize=10)

    # (c) against the tolerance
    ax = axes[2]
    rs = sorted(pick(res, "tol", k=kf), key=lambda r: -r["tol"])
    if rs:
        err_and_file(ax, [r["tol"] for r in rs], rs, f"links, k={kf}, --links {res['tol_links']}", "C2", "^",
                     annot=lambda r: f"{r['links'][1]:.0f}")
        ax.set_xticks([r["tol"] for r in rs])
    ax.invert_xaxis()
    ax.set_xlabel("--link-tol [fraction of the row's total], finer to the right")
    ax.set_title(f"(c) error against the link tolerance --link-tol, k = {kf}, --links {res['tol_links']}", fontsize=10)

    for ax in axes[1:]:
        if pool_k:
            ax.axhline(pool_k[0]["worst_pct"], color="C3", lw=1.2, label=f"pool at k = {kf}: worst surface")
            ax._twin.axhline(pool_k[0]["file_pct"], color="C3", lw=1, ls="--", alpha=0.7,
                             label=f"pool at k = {kf}: file (right axis)")
    # one scale for all the error axes and one for all the file axes
    fl = [r["file_pct"] for r in res["runs"] if "error" not in r] + [20.0]
    for tw in twins:
        tw.set_ylim(min(fl) / 1.5, max(fl) * 1.5)
    el = [r["worst_pct"] for r in res["runs"] if "error" not in r]
    axes[0].set_ylim(min(0.1, min(el) / 1.5), max(el) * 1.5)  # shared; down to 0.1 % so that tick is labelled
    for ax in axes:
        ax.xaxis.set_major_formatter(plain)
        ax.xaxis.set_minor_formatter(NullFormatter())
        for a in (ax.yaxis, ax._twin.yaxis):
            a.set_major_formatter(plain)
            a.set_minor_formatter(plain if a is ax._twin.yaxis else NullFormatter())
        ax._twin.tick_params(axis="y", which="minor", labelsize=6)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax._twin.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    d = res["dense"]
    fig.suptitle(f"builtin:room, {d['n']:,} patches (--patches {res['patches']}), worst surface against dense rows "
                 f"({d['bytes'] / 1e6:.1f} MB) and file size; numbers at points: mean links a linked row\n"
                 f"ffstream {res['label']}, {res['date']}", fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def git_label():
    try:
        h = subprocess.run(["git", "-C", HERE, "log", "-1", "--format=%h"], capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", HERE, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        return h + (" + uncommitted changes" if dirty else "")
    except OSError:
        return "unknown commit"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--exe", default=EXE, help="ffstream binary used for compute, info and solve (default: %(default)s)")
    ap.add_argument("--patches", type=int, default=3000)
    ap.add_argument("--ks", type=int, nargs="+", default=[16, 64, 256, 1024], help="--top-k values of panel (a)")
    ap.add_argument("--default-links", type=int, default=256, help="--links of the linked series of panel (a)")
    ap.add_argument("--k-fixed", type=int, default=64, help="--top-k of panels (b) and (c)")
    ap.add_argument("--budgets", type=int, nargs="+", default=[32, 64, 128, 256, 512, 1024], help="--links of panel (b)")
    ap.add_argument("--tols", type=float, nargs="*", default=[1e-2, 3e-3, 1e-3, 3e-4, 1e-4], help="--link-tol of panel (c)")
    ap.add_argument("--tol-links", type=int, default=4096, help="--links of panel (c), large so the tolerance binds")
    ap.add_argument("--label", default=None, help="build named in the title (default: git hash of this tree, + a note if modified)")
    ap.add_argument("-o", "--output", default=os.path.join(HERE, "plots", "links_error.png"))
    ap.add_argument("--save-json", metavar="PATH", help="write the measurements here")
    ap.add_argument("--load-json", metavar="PATH", help="plot and tabulate these measurements instead of computing")
    args = ap.parse_args()
    if args.load_json:
        with open(args.load_json) as fh:
            res = json.load(fh)
    else:
        args.label = args.label or git_label()
        res = compute_all(args)
        res["default_links"] = args.default_links
        if args.save_json:
            with open(args.save_json, "w") as fh:
                json.dump(res, fh, indent=1)
    plot(res, args.output)
    la, lb = res["load_start"], res.get("load_end", res["load_start"])
    print(f"builtin:room, {res['dense']['n']:,} patches, ffstream {res['label']}, {res['date']}, "
          f"load average {la[0]:.1f} at the start, {lb[0]:.1f} at the end\n")
    print(table(res))
    print(f"\nplot: {os.path.relpath(args.output)}")


if __name__ == "__main__":
    sys.exit(main())
