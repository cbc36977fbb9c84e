# SPDX-License-Identifier: LGPL-2.1-or-later
"""The fit stage's refinement where an inside fit leaves volume outside, over perturbed cages.

Usage::

    .venv/bin/python benchmarks/outside_refinement_bench.py [--only NAME ...]
                                                            [--perturbations K] [--cache DIR]
                                                            [--json PATH]

For each mesh (default ``gripper_domain``, the dev mesh whose inside fit leaves most outside)
the cage is built and cached as ``fit_speed_bench.py`` does; then the fit stage
(``core.stages.fit.run_fit``, default parameters) runs on seed 0 of the cage and on ``K - 1``
copies moved by ``fit_speed_bench.PERTURBATION`` of the largest coordinate (the fit is
chaotic, so one fit says little). Printed per fit: the first fit's volume outside (what the
stage gave before the refinement: the first fit is the same), the kept fit's volume outside,
faces, mean and largest distance of its fine limit points (fractions of the diagonal) and the
stage's CPU seconds; then the medians and extremes. ``--json`` writes the records, one a line.
"""
import argparse
import json
import os
import pickle
import statistics
import sys
import time
from types import SimpleNamespace

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

from fit_speed_bench import CASES, cache_cages, perturbed  # noqa: E402


def measure(name, k, folder):
    """One run of the fit stage on perturbation ``k`` of the cached cage of ``name``."""
    from core.params import ReconstructionParams
    from core.progress import NO_PROGRESS
    from core.stages.fit import run_fit
    from core.types import BaseMeshResult

    with open(os.path.join(folder, name + ".pkl"), "rb") as handle:
        cage, target = pickle.load(handle)
    started = time.process_time()
    result = run_fit(SimpleNamespace(target=target), BaseMeshResult(perturbed(cage, k)),
                     ReconstructionParams(), NO_PROGRESS)
    seconds = time.process_time() - started
    report = result.report
    rounds = report.get("outside_refinement", {}).get("rounds")
    first = rounds[0]["outside_volume_fraction"] if rounds else report["outside_volume_fraction"]
    return {"mesh": name, "k": k, "first_outside": first,
            "outside": report["outside_volume_fraction"], "faces": int(result.cage.n_faces),
            "base_faces": int(cage.n_faces), "mean": report["mean_distance"],
            "max": report["max_distance"], "cpu": seconds,
            "fits": [r["faces"] for r in rounds] if rounds else [int(cage.n_faces)]}


def markdown(records):
    lines = ["| mesh | k | first fit outside % | kept outside % | faces (fits) | mean / max "
             "(1e-3 of diagonal) | stage CPU s |", "|---|---|---|---|---|---|---|"]
    for r in records:
        fits = " -> ".join(map(str, r["fits"]))
        lines.append(f"| `{r['mesh']}` | {r['k']} | {100 * r['first_outside']:.3f} | "
                     f"{100 * r['outside']:.3f} | {r['faces']} ({fits}) | "
                     f"{1e3 * r['mean']:.2f} / {1e3 * r['max']:.1f} | {r['cpu']:.1f} |")
    for name in sorted({r["mesh"] for r in records}):
        mine = [r for r in records if r["mesh"] == name]
        for key, label in (("first_outside", "first fit outside %"),
                           ("outside", "kept outside %")):
            values = [100 * r[key] for r in mine]
            lines.append(f"\n`{name}` {label}: median {statistics.median(values):.3f}, "
                         f"{min(values):.3f}-{max(values):.3f} over {len(values)} fits")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="*", default=["gripper_domain"], choices=list(CASES))
    parser.add_argument("--perturbations", type=int, default=8)
    parser.add_argument("--cache", default=os.path.join("/tmp", "fit_speed_cages"))
    parser.add_argument("--json", help="also write every record here, one a line")
    args = parser.parse_args(argv)
    cache_cages(args.only, args.cache)
    records = []
    for name in args.only:
        for k in range(args.perturbations):
            records.append(measure(name, k, args.cache))
            print(json.dumps(records[-1]), file=sys.stderr, flush=True)
            if args.json:
                with open(args.json, "a") as handle:
                    handle.write(json.dumps(records[-1]) + "\n")
    print(markdown(records))


if __name__ == "__main__":
    main()
