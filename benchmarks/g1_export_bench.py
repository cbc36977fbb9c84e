# SPDX-License-Identifier: LGPL-2.1-or-later
"""Exact (graded) against G1 export: STEP size, FreeCAD read time, normal jumps, deviation.

Usage::

    .venv/bin/python benchmarks/g1_export_bench.py [CAGE.obj[=TARGET] ...]

Cages: ``examples/genus3_cage.obj``, sample cages of ``core.subdivision.sample_cages`` and
any OBJ cages given, each optionally with the target mesh it was fitted to (for example the
fitted cage ``reconstruct TARGET --stop-after fit --base-mesh cage.obj`` writes; the G1 form
refuses creased cages, recorded as such). For each cage and export form, in one process,
side by side: ``subd_to_solid`` writes the STEP file, ``Part.Shape().read`` reads it back
(best of 3), and the patches are measured: the largest normal jump across edges (degrees),
the largest distance from patch points (17 x 17 per patch) to a level-5 mesh (level 4 from
1,000 faces) of exact limit points (fraction of the bounding-box diagonal). With a target,
``polycube_wb.api.check`` measures the STEP against it: the mean of both one-sided mean
distances, the Hausdorff distance (fractions of the target's diagonal) and the volume
outside the target (fraction of its volume).

Writes ``benchmarks/G1_EXPORT_RESULTS.md`` and ``benchmarks/g1_export_results.json``.
"""
import json
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)

import FreeCAD  # noqa: E402,F401  (FreeCAD before numpy-using modules, as the workbench loads)
import Part  # noqa: E402
import numpy as np  # noqa: E402

SAMPLE_CAGES = ("cube", "mixed_prism", "genus3_block", "grid_sphere")


def _cages(paths):
    from core.polymesh_io import read_polymesh
    from core.subdivision import sample_cages

    out = [("genus3_cage", read_polymesh(os.path.join(REPO, "examples", "genus3_cage.obj")))]
    out += [(name, getattr(sample_cages, name)()) for name in SAMPLE_CAGES]
    out = [(name, cage, None) for name, cage in out]
    for arg in paths:
        path, _, target = arg.partition("=")
        out.append((os.path.splitext(os.path.basename(path))[0], read_polymesh(path),
                    target or None))
    return out


def _distance_to_limit(cage, patchset):
    from core.export.bspline_basis import evaluate_patch_points
    from core.geometry import triangulate
    from core.subdivision.catmull_clark import build_hierarchy
    from core.subdivision.limit import limit_matrices
    from core.target_surface import TargetSurface

    fine = build_hierarchy(cage, 5 if cage.n_faces < 1000 else 4).meshes[-1]
    surface = TargetSurface(limit_matrices(fine)[0] @ fine.vertices,
                            triangulate(fine.face_vertices, fine.face_offsets))
    s = np.linspace(0.0, 1.0, 17)
    u, v = (a.reshape(-1) for a in np.meshgrid(s, s, indexing="ij"))
    k = len(patchset.patches)
    points = evaluate_patch_points(patchset.patches, np.repeat(np.arange(k), len(u)),
                                   np.tile(u, k), np.tile(v, k))
    return float(surface.nearest(points).distance.max() / patchset.info["bbox_diagonal"])


def run_case(name, cage, target, export, folder):
    from core.export.bspline import limit_surface_patches
    from core.export.g1_patches import g1_surface_patches
    from core.polymesh_io import write_polymesh
    from polycube_wb.api import check, subd_to_solid

    obj = os.path.join(folder, name + ".obj")
    step = os.path.join(folder, f"{name}_{export}.step")
    write_polymesh(obj, cage)
    row = {"cage": name, "export": export, "base_faces": int(cage.n_faces)}
    try:
        clock = time.perf_counter()
        solid, report = subd_to_solid(obj, step, export=export)
        row["export_seconds"] = time.perf_counter() - clock
    except Exception as exc:  # recorded, e.g. the G1 form refusing creases
        row["error"] = str(exc)
        return row
    reads = []
    for _ in range(3):
        shape = Part.Shape()
        clock = time.perf_counter()
        shape.read(step)
        reads.append(time.perf_counter() - clock)
    patchset = (g1_surface_patches(cage, measure=False) if export == "g1"
                else limit_surface_patches(cage, measure=False))
    row.update({
        "faces": len(solid.Faces), "valid": bool(solid.isValid()),
        "closed": bool(report["brep"]["closed"]), "step_bytes": os.path.getsize(step),
        "read_seconds": min(reads), "read_valid": bool(shape.isValid()),
        "poles": int(report["patches"]["n_poles"]),
        "normal_jump_max_deg": report["patches"]["normal_jump_max_deg"],
        "distance_to_limit_rel": _distance_to_limit(cage, patchset),
        "volume_error_rel": report["brep"]["volume_error_rel"],
    })
    if target is not None:
        checked = check(target, step)
        d = checked["distances"]
        row.update({"target_mean_distance": 0.5 * (d["result_to_target_mean"]
                                                    + d["target_to_result_mean"]),
                    "target_max_distance": d["hausdorff"],
                    "target_outside_volume": checked["outside_volume_fraction"],
                    "target_watertight": checked["watertight"]})
    return row


def _target_cells(row):
    if "target_mean_distance" not in row:
        return " | "
    return (f"{row['target_mean_distance']:.2g} / {row['target_max_distance']:.2g} | "
            f"{row['target_outside_volume']:.2g}")


def main(paths):
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name, cage, target in _cages(paths):
            for export in ("exact", "g1"):
                rows.append(run_case(name, cage, target, export, folder))
                print(json.dumps(rows[-1]), flush=True)
    with open(os.path.join(HERE, "g1_export_results.json"), "w") as f:
        json.dump({"load": os.getloadavg()[0], "rows": rows}, f, indent=1)
    write_table(rows)


def write_table(rows):
    """Write ``G1_EXPORT_RESULTS.md`` from the result rows."""
    lines = ["# Exact (graded) against G1 export", "",
             "Generated by `benchmarks/g1_export_bench.py`; both forms of each cage in one process "
             "(the machine is shared: times are noisy, compare within a row pair). Rows after "
             "`grid_sphere` are the fitted cages `reconstruct TARGET --stop-after fit --base-mesh "
             "CAGE.obj` writes at default parameters; their target columns are `check`'s "
             "(fractions of the target's diagonal and volume).", "",
             "| cage | base faces | export | faces | poles | STEP KB | read s | valid | "
             "max normal jump deg | max distance to limit / diag | volume error | "
             "target mean / max distance | outside target |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['cage']} | {r['base_faces']} | {r['export']} | refused: "
                         f"{r['error']} | | | | | | | | | |")
            continue
        lines.append(f"| {r['cage']} | {r['base_faces']} | {r['export']} | {r['faces']} | "
                     f"{r['poles']} | {r['step_bytes'] / 1024:.0f} | {r['read_seconds']:.3f} | "
                     f"{r['valid'] and r['closed'] and r['read_valid']} | "
                     f"{r['normal_jump_max_deg']:.2g} | {r['distance_to_limit_rel']:.2g} | "
                     f"{r['volume_error_rel']:.2g} | {_target_cells(r)} |")
    with open(os.path.join(HERE, "G1_EXPORT_RESULTS.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
