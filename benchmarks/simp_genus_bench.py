# SPDX-License-Identifier: LGPL-2.1-or-later
"""SIMP designs of genus 0 to 60: does each become a valid closed STEP solid with defaults?

Usage::

    .venv/bin/python benchmarks/simp_genus_bench.py [--meshes DIR] [--only NAME ...]

Every ``*.stl`` of ``--meshes`` (default ``benchmarks/simp_unseen``, designs made by
``benchmarks/simp_designs.py``; their ``MANIFEST.json`` gives the genus) is reconstructed by
the command a user runs, ``python -m polycube_wb reconstruct MESH -o OUT.step --report
OUT.json`` with default parameters, one process per mesh
(:func:`to_results_bench.run_mesh`), and the STEP written is checked by
``../shared/tools/evaluate.py``. Rows go to ``benchmarks/simp_genus_results.json`` after every
mesh and ``benchmarks/SIMP_GENUS_RESULTS.md`` is written from them.
"""
import argparse
import json
import os
import platform
import sys

from to_results_bench import run_mesh

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEFAULT_MESHES = os.path.join(HERE, "simp_unseen")
RESULTS_JSON = os.path.join(HERE, "simp_genus_results.json")
RESULTS_MD = os.path.join(HERE, "SIMP_GENUS_RESULTS.md")


def manifest_genus(directory):
    """Genus of every design named in ``directory/MANIFEST.json`` (a dict, empty without it)."""
    path = os.path.join(directory, "MANIFEST.json")
    if not os.path.exists(path):
        return {}
    with open(path) as handle:
        return {entry["file"]: entry["genus"] for entry in json.load(handle).values()}


def write_markdown(rows):
    """``RESULTS_MD`` from the rows."""
    lines = ["# SIMP designs of genus 0 to 60 with default parameters", "",
             "Written by `benchmarks/simp_genus_bench.py`: one CLI process per design "
             "(`reconstruct MESH -o OUT.step --report OUT.json`, defaults), the STEP checked by "
             "`../shared/tools/evaluate.py`. `route` and `faces` are the base mesh kept, "
             "`outside` the share of the target's volume outside the fitted limit surface, "
             "`cpu` the CPU seconds of the whole process (user and system; the machine's 2 "
             "cores are shared with other jobs, so `wall` seconds vary more), `exit` the CLI's "
             f"exit code. Python {platform.python_version()}, {platform.machine()}.", ""]
    header = ["mesh", "genus", "route", "faces", "valid / closed", "outside", "cpu s", "wall s",
              "exit", "error"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        base, fit = row.get("base_mesh") or {}, row.get("fit") or {}
        outside = fit.get("outside_volume_fraction")
        cells = [row["mesh"], str(row.get("genus", "-")), str(base.get("method") or "-"),
                 str(base.get("faces") or "-"), row.get("evaluate") or "-",
                 "-" if outside is None else f"{outside:.2%}",
                 "-" if row.get("cpu") is None else f"{row['cpu']:.1f}", f"{row['wall']:.1f}",
                 str(row["exit"]),
                 row["error"].replace("|", "/")[:200]]
        lines.append("| " + " | ".join(cells) + " |")
    with open(RESULTS_MD, "w") as handle:
        handle.write("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    names = args.only or sorted(name for name in os.listdir(args.meshes)
                                if name.endswith(".stl"))
    genus = manifest_genus(args.meshes)
    kept = {}
    if args.only and os.path.exists(RESULTS_JSON):  # rows of meshes not re-run stay
        with open(RESULTS_JSON) as handle:
            kept = {row["mesh"]: row for row in json.load(handle)}
    for name in names:
        row = run_mesh(REPO, os.path.abspath(os.path.join(args.meshes, name)), evaluate=True)
        row["genus"] = genus.get(name, (row.get("base_mesh") or {}).get("genus"))
        print(json.dumps(row), flush=True)
        kept[row["mesh"]] = row
        rows = [kept[key] for key in sorted(kept)]
        with open(RESULTS_JSON, "w") as handle:
            json.dump(rows, handle, indent=1)
        write_markdown(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
