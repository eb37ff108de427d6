"""Check ffstream's .vtu grids with meshio, as a ParaView user's script would read them.

Usage: vtu_meshio.py solve GRID.vtu radiosity.csv patches.csv
       vtu_meshio.py export GRID.vtu patches.csv

Every cell array must equal the table's columns (solve's grid: radiosity.csv's, and
the row sums and sky view factors of the file's patch table, `export --patches-csv`) (the CSV prints each value in the
shortest form that reads back to the same float, so f64 arrays match exactly and f32
ones within f32 rounding); cell k must be patch k, with 3 or 4 points. Prints one line
per array checked; exits 1 naming the first difference.
"""
import csv
import sys

import meshio
import numpy as np

# cell array -> CSV columns, per kind of table
COLUMNS = {
    "solve": {
        "patch": ["patch"],
        "area": ["area"],
        "radiosity": ["B_r", "B_g", "B_b"],
        "irradiance": ["H_r", "H_g", "H_b"],
        "emitted_exitance": ["E_r", "E_g", "E_b"],
        "reflectance": ["rho_r", "rho_g", "rho_b"],
    },
    "export": {
        "patch": ["patch"],
        "area": ["area"],
        "reflectance": ["rho_r", "rho_g", "rho_b"],
        "emitted_exitance": ["e_r", "e_g", "e_b"],
        "row_sum": ["row_sum"],
        "sky_view": ["sky_view"],
    },
    "sums": {
        "patch": ["patch"],
        "row_sum": ["row_sum"],
        "sky_view": ["sky_view"],
    },
}
# Arrays each grid holds: its columns above, group, and dropped mass (no table column).
GRIDS = {
    "solve": set(COLUMNS["solve"]) | set(COLUMNS["sums"]) | {"group", "dropped_mass"},
    "export": set(COLUMNS["export"]) | {"group", "dropped_mass"},
}


def fail(what):
    print(f"vtu_meshio: {what}", file=sys.stderr)
    sys.exit(1)


def main():
    kind, grid, table = sys.argv[1:4]
    mesh = meshio.read(grid)
    if kind == "solve":
        check(mesh, "solve", grid, table)
        check(mesh, "sums", grid, sys.argv[4])
    else:
        check(mesh, "export", grid, table)


def check(mesh, kind, grid, table):
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    n = len(rows)
    cells = sum(len(block.data) for block in mesh.cells)
    if cells != n:
        fail(f"{grid}: {cells} cells, {table}: {n} patches")
    for block in mesh.cells:
        if block.type not in ("triangle", "quad"):
            fail(f"{grid}: cells of type {block.type}")
    expected_arrays = GRIDS["solve" if kind == "sums" else kind]
    got_arrays = set(mesh.cell_data)
    if got_arrays != expected_arrays:
        fail(f"{grid}: cell arrays {sorted(got_arrays)}, expected {sorted(expected_arrays)}")
    # Cells are in blocks by type; the patch array says which patch each cell is.
    patch = np.concatenate([np.asarray(a).reshape(-1) for a in mesh.cell_data["patch"]])
    for name, cols in COLUMNS[kind].items():
        got = np.concatenate([np.asarray(a).reshape(len(a), -1) for a in mesh.cell_data[name]])
        want = np.array(
            [[float(r[c]) if r[c] != "" else np.nan for c in cols] for r in rows]
        )[patch.astype(int)]
        if got.shape != want.shape:
            fail(f"{grid}: {name} has shape {got.shape}, {table} {want.shape}")
        if got.dtype == np.float32:
            tol = np.abs(want) * 2.0**-23
        else:
            tol = np.zeros_like(want)
        bad = ~((np.abs(got - want) <= tol) | (np.isnan(got) & np.isnan(want)))
        if bad.any():
            k = np.argwhere(bad)[0]
            fail(f"{grid}: {name}[{k[0]}] = {got[tuple(k)]!r}, {table} says {want[tuple(k)]!r}")
        print(f"{name}: {got.shape[0]} cells x {got.shape[1]} ({got.dtype}) equal {table}")
    # The group array indexes the file's group names: one index per name and back.
    groups = np.concatenate([np.asarray(a).reshape(-1) for a in mesh.cell_data["group"]])
    pairs = {(int(g), rows[int(p)]["group"]) for g, p in zip(groups, patch)}
    if len({g for g, _ in pairs}) != len(pairs) or len({s for _, s in pairs}) != len(pairs):
        fail(f"{grid}: group indices and {table}'s group names do not match one to one: {sorted(pairs)}")
    print(f"group: {len(groups)} cells in {len(pairs)} groups match {table}")

if __name__ == "__main__":
    main()
