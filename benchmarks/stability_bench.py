# SPDX-License-Identifier: LGPL-2.1-or-later
"""How much the fit stage's result moves when its input moves by rounding.

Usage::

    .venv/bin/python benchmarks/stability_bench.py [--only NAME ...] [--copies 8]
                                                   [--seeds 1] [--noise 1e-12]
                                                   [--cache DIR] [--out benchmarks]

For every dev mesh that reaches the fit (``fit_speed_bench.CASES``), the cage of
``reconstruct(path, stop_after="basemesh")`` is fitted by the fit stage at default parameters
(``core.stages.fit.run_fit``: the inside fit with its outside refinement, what a user gets)
``--copies`` times: once as it is and on copies whose vertices carry normal noise of
``--noise`` (default ``fit_speed_bench.PERTURBATION``, 1e-12, the size of the rounding of
another machine) of the largest coordinate; with ``--seeds S`` the cage as it is is also fitted
with the target-sample seeds 1 .. S-1 (the fit's ``seed``: other samples of the same surface).
Per mesh it records the mean and maximum distance of the limit surface to the target
(fractions of the diagonal), the volume outside (fraction of the target's) and the crossing
triangle pairs, and the spread of each: (largest - smallest) / median.

Writes ``STABILITY_RESULTS.md`` (a generated table) and ``stability_results.json`` into
``--out``.
"""
import argparse
import json
import os
import sys
import time
from dataclasses import replace
from functools import partial

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)

from fit_speed_bench import CASES, PERTURBATION, perturbed  # noqa: E402

FIGURES = ("mean_distance", "max_distance", "outside_volume_fraction")
SPREAD_RULE = 0.10
"""Largest relative spread of each figure that counts as stable."""


def fit_copies(name, folder, copies, seeds=1, noise=PERTURBATION):
    """Records of the fit stage on the cached cage of ``name``, ``copies - 1`` copies
    perturbed by ``noise`` and the cage with the sample seeds ``1 .. seeds - 1``: one dict
    per fit with its copy, seed, noise, figures, crossings, faces and CPU seconds."""
    import pickle

    import core.fitting
    from core.params import ReconstructionParams
    from core.progress import NO_PROGRESS
    from core.stages.fit import run_fit
    from core.threads import single_threaded

    with open(os.path.join(folder, name + ".state.pkl"), "rb") as handle:
        intake, basemesh = pickle.load(handle)
    fit = core.fitting.fit_base_mesh
    records = []
    for k, seed in [(k, 0) for k in range(copies)] + [(0, s) for s in range(1, seeds)]:
        started = time.process_time()
        # the stage looks the fit up in core.fitting when it runs
        core.fitting.fit_base_mesh = partial(fit, seed=seed)
        try:
            with single_threaded():
                result = run_fit(intake, replace(basemesh, cage=perturbed(basemesh.cage, k,
                                                                          noise)),
                                 ReconstructionParams(), NO_PROGRESS)
        finally:
            core.fitting.fit_base_mesh = fit
        report = result.report
        records.append({"copy": k, "seed": seed, "noise": noise if k else 0.0,
                        "cpu": time.process_time() - started,
                        "faces": int(result.cage.n_faces),
                        "crossings": report.get("self_intersections"),
                        **{key: float(report[key]) for key in FIGURES}})
    return records


def cache_states(names, folder):
    """Pickle ``(intake, basemesh)`` of each mesh into ``folder`` unless already there."""
    import pickle

    from core.pipeline import reconstruct

    os.makedirs(folder, exist_ok=True)
    for name in names:
        path = os.path.join(folder, name + ".state.pkl")
        if not os.path.exists(path):
            state = reconstruct(CASES[name], stop_after="basemesh").state
            with open(path, "wb") as handle:
                pickle.dump((state.intake, state.basemesh), handle)


def spread(values):
    """(largest - smallest) / median of ``values``; 0 where all are 0."""
    import numpy as np

    values = np.asarray(values, dtype=float)
    median = float(np.median(values))
    width = float(values.max() - values.min())
    return 0.0 if width == 0.0 else width / median if median > 0 else float("inf")


def fits(records):
    """What the fits of a row were: the cage, its noisy copies (with the noise's size) and
    its other sample seeds (records of runs before seeds were recorded had noise
    ``PERTURBATION`` and seed 0)."""
    noisy = [r.get("noise", PERTURBATION) for r in records if r["copy"]]
    seeds = sum(1 for r in records if r.get("seed", 0))
    cells = ["1"]
    if noisy:
        cells.append(f"{len(noisy)} noisy ({max(noisy):g})")
    if seeds:
        cells.append(f"{seeds} seeds")
    return " + ".join(cells)


def markdown(results):
    """The generated table: per mesh the fits made and the median and spread of each figure."""
    import numpy as np

    lines = [
        "# Stability of the fit stage under rounding and other target samples",
        "",
        "Generated by `benchmarks/stability_bench.py`; do not edit. Each mesh's cage is fitted "
        "by the fit stage at default parameters (`fits`): as it is, on copies whose vertices "
        "are moved by normal noise of the given size times their largest coordinate (noisy), "
        "and as it is with other seeds of the fit's target samples (seeds). Distances are "
        "fractions of the diagonal, the volume outside a fraction of the target's; spread is "
        "(largest - smallest) / median, stable where every spread is at most "
        f"{SPREAD_RULE:.0%}.",
        "",
        "| mesh | fits | faces | mean (median) | spread | max (median) | spread "
        "| outside (median) | spread | crossings | CPU s (median) | stable |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, records in results.items():
        cells = [name, fits(records), "/".join(sorted({str(r["faces"]) for r in records}))]
        stable = True
        for key in FIGURES:
            values = [r[key] for r in records]
            width = spread(values)
            stable &= width <= SPREAD_RULE
            cells += [f"{np.median(values):.2e}", f"{width:.1%}"]
        cells += [str(max(r["crossings"] or 0 for r in records)),
                  f"{np.median([r['cpu'] for r in records]):.1f}", "yes" if stable else "no"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="*", default=list(CASES))
    parser.add_argument("--copies", type=int, default=8)
    parser.add_argument("--seeds", type=int, default=1,
                        help="also fit the cage with the sample seeds 1 .. SEEDS-1")
    parser.add_argument("--noise", type=float, default=PERTURBATION,
                        help="relative size of the noise of the perturbed copies")
    parser.add_argument("--cache", default=os.path.join("/tmp", "polycube_stability_cages"))
    parser.add_argument("--out", default=HERE)
    args = parser.parse_args()
    cache_states(args.only, args.cache)
    os.makedirs(args.out, exist_ok=True)
    saved = os.path.join(args.out, "stability_results.json")
    results = {}
    if os.path.exists(saved):  # rows of meshes not re-run stay as they were measured
        with open(saved) as handle:
            results = {name: records for name, records in json.load(handle).items()
                       if name in CASES}
    for name in args.only:
        results[name] = fit_copies(name, args.cache, args.copies, args.seeds, args.noise)
        print(name, json.dumps(results[name][-1]), flush=True)
    with open(saved, "w") as handle:
        json.dump(results, handle, indent=1)
    with open(os.path.join(args.out, "STABILITY_RESULTS.md"), "w") as handle:
        handle.write(markdown(results))


if __name__ == "__main__":
    main()
