# SPDX-License-Identifier: LGPL-2.1-or-later
"""Export benchmark: sample cages to STEP, this tree against a baseline commit.

Usage::

    .venv/bin/python benchmarks/export_bench.py [--baseline COMMIT] [--repeats N]

For this tree and for ``COMMIT`` (default: the commit this branch started from,
exported with ``git archive`` into a temporary folder), every case runs in a fresh
process: the sample cage is written as OBJ and turned into a STEP file by
``polycube_wb.api.subd_to_solid`` (with and without measurement), then the STEP file
is read back with ``Part.read``. Recorded per case: patches (B-rep faces) per base
face, validity, the stage times (wall clock) and the process CPU time of the whole
call; the median over ``--repeats`` runs. The machine is shared, so the load average
is recorded with every run and CPU time is given next to wall time.

Writes ``benchmarks/EXPORT_RESULTS.md`` and ``benchmarks/export_results.json``.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEFAULT_BASELINE = "9ea2d9c"
CAGES = ("mixed_prism", "pentagonal_prism", "genus3_block", "grid_sphere_7", "grid_sphere_18")

_CASE = r'''
import json, os, sys, time
repo, cage, measure, folder = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4]
sys.path.insert(0, repo)
import FreeCAD, Part
from core.polymesh_io import write_polymesh
from core.subdivision import sample_cages
from polycube_wb.api import subd_to_solid
if cage.startswith("grid_sphere_"):
    mesh = sample_cages.grid_sphere(int(cage.rsplit("_", 1)[1]))
else:
    mesh = getattr(sample_cages, cage)()
obj = os.path.join(folder, cage + ".obj")
step = os.path.join(folder, cage + ".step")
write_polymesh(obj, mesh)
import core.export.bspline, polycube_wb.brep, polycube_wb.step_io  # loaded before timing
load = os.getloadavg()[0]
wall, cpu = time.perf_counter(), time.process_time()
solid, report = subd_to_solid(obj, step, measure=measure)
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
clock = time.perf_counter()
read = Part.read(step)
read_seconds = time.perf_counter() - clock
sizes = mesh.face_sizes
print(json.dumps({"wall": wall, "cpu": cpu, "load": load, "stages": report["stages"],
                  "faces": len(solid.Faces), "valid": bool(solid.isValid()),
                  "base_faces": int(mesh.n_faces), "quads": int((sizes == 4).sum()),
                  "others": int((sizes != 4).sum()),
                  "construction": report["brep"].get("construction", "sewn (Part.Shell)"),
                  "max_ev_error_rel": report["patches"].get("max_ev_error_rel"),
                  "normal_jump_max_deg": report["patches"].get("normal_jump_max_deg"),
                  "read_valid": bool(read.isValid()), "read_faces": len(read.Faces),
                  "read_seconds": read_seconds, "step_bytes": os.path.getsize(step)}))
'''


def run_case(repo, cage, measure):
    """One case in a fresh process; returns its figures (dict)."""
    with tempfile.TemporaryDirectory(prefix="export-bench-") as folder:
        done = subprocess.run([sys.executable, "-c", _CASE, repo, cage, "1" if measure else "0",
                               folder], capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr else "failed"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def median_case(repo, cage, measure, repeats):
    runs = [run_case(repo, cage, measure) for _ in range(repeats)]
    good = [r for r in runs if "error" not in r]
    if not good:
        return runs[0]
    good.sort(key=lambda r: r["wall"])
    best = dict(good[len(good) // 2])
    best["wall_all"] = [round(r["wall"], 3) for r in good]
    best["cpu_all"] = [round(r["cpu"], 3) for r in good]
    best["load_all"] = [round(r["load"], 2) for r in good]
    return best


def baseline_tree(commit, folder):
    """Export ``commit`` of this repository into ``folder``; returns the folder."""
    archive = subprocess.run(["git", "-C", REPO, "archive", commit], capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
    return folder


def _stage_text(stages):
    return ", ".join(f"{k} {v['seconds']:.2f}" for k, v in stages.items())


def markdown(results, baseline, repeats):
    lines = ["# Export benchmark: sample cages to STEP", "",
             f"Written by `benchmarks/export_bench.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
             f"this tree against the baseline commit `{baseline}`. Each figure is "
             f"the median of {repeats} runs, each in a fresh process. The machine (2 cores) was shared "
             "with other jobs: the 1-minute load average at the start of each run is given, and "
             "the process CPU time next to the wall time.", "",
             "## Patches per base face (mixed cages)", "",
             "| cage | base faces (quads / other) | B-rep faces before | B-rep faces now | "
             "expected (quads + n per n-gon) | valid now | construction now |", "|---|---|---|---|---|---|---|"]
    expected = {"mixed_prism": 7 + 3 * 10, "pentagonal_prism": 5 + 2 * 5}
    for cage in ("mixed_prism", "pentagonal_prism", "genus3_block"):
        old, new = results["baseline"][cage]["measure"], results["now"][cage]["measure"]
        lines.append(f"| `{cage}` | {new['base_faces']} ({new['quads']} / {new['others']}) | "
                     f"{old.get('faces')} | {new.get('faces')} | {expected.get(cage, new['base_faces'])} | "
                     f"{new.get('valid')} | {new.get('construction')} |")
    lines += ["", "## Accuracy (unchanged by the new layout)", "",
              "| cage | max EV error before (fraction of diagonal) | now | normal jump max ° before | now |",
              "|---|---|---|---|---|"]
    for cage in ("mixed_prism", "pentagonal_prism", "genus3_block"):
        old, new = results["baseline"][cage]["measure"], results["now"][cage]["measure"]
        lines.append(f"| `{cage}` | {old.get('max_ev_error_rel', 0):.3g} | {new.get('max_ev_error_rel', 0):.3g} | "
                     f"{old.get('normal_jump_max_deg', 0):.3g} | {new.get('normal_jump_max_deg', 0):.3g} |")
    lines += ["", "## Time to a valid STEP file", "",
              "`subd_to_solid(cage.obj, cage.step)`: with measurement (the CLI default) and without "
              "(`--no-measure`). Wall and CPU seconds of the call; stage times are wall seconds.", "",
              "| cage | measure | before wall s (CPU s) | now wall s (CPU s) | load before / now | "
              "stages now | STEP read back (Part.read) valid, faces, s |",
              "|---|---|---|---|---|---|---|"]
    for cage in CAGES:
        for key in ("measure", "no_measure"):
            old, new = results["baseline"][cage][key], results["now"][cage][key]
            if "error" in new or "error" in old:
                lines.append(f"| `{cage}` | {key} | {old.get('error', '')} | {new.get('error', '')} | | | |")
                continue
            lines.append(f"| `{cage}` ({new['base_faces']} faces) | {'yes' if key == 'measure' else 'no'} | "
                         f"{old['wall']:.2f} ({old['cpu']:.2f}) | {new['wall']:.2f} ({new['cpu']:.2f}) | "
                         f"{old['load']:.1f} / {new['load']:.1f} | {_stage_text(new['stages'])} | "
                         f"{new['read_valid']}, {new['read_faces']}, {new['read_seconds']:.2f} |")
    lines += ["", "## Speed bars", "",
              "| bar | case | limit s | wall s | CPU s | load | verdict on wall / on CPU |",
              "|---|---|---|---|---|---|---|"]
    for cage, limit in (("grid_sphere_18", 3.0), ("grid_sphere_7", 1.0)):
        for key in ("no_measure", "measure"):
            new = results["now"][cage][key]
            if "error" in new:
                continue
            verdict = " / ".join("PASS" if x <= limit else "FAIL" for x in (new["wall"], new["cpu"]))
            lines.append(f"| {new['base_faces']}-face cage to a valid STEP | `{cage}`, "
                         f"{'with' if key == 'measure' else 'without'} measurement | {limit:g} | "
                         f"{new['wall']:.2f} | {new['cpu']:.2f} | {new['load']:.1f} | {verdict} |")
    lines.append("")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=DEFAULT_BASELINE)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    results = {"baseline": {}, "now": {}}
    with tempfile.TemporaryDirectory(prefix="export-baseline-") as folder:
        trees = {"baseline": baseline_tree(args.baseline, folder), "now": REPO}
        for cage in CAGES:
            for which, tree in trees.items():
                results[which][cage] = {
                    key: median_case(tree, cage, key == "measure", args.repeats)
                    for key in ("measure", "no_measure")}
                print(which, cage, {k: v.get("wall") for k, v in results[which][cage].items()},
                      flush=True)
    with open(os.path.join(HERE, "export_results.json"), "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1)
    with open(os.path.join(HERE, "EXPORT_RESULTS.md"), "w", encoding="utf-8") as fh:
        fh.write(markdown(results, args.baseline, args.repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
