# SPDX-License-Identifier: LGPL-2.1-or-later
"""CPU seconds of the default inside fit on every dev mesh that reaches the fit, before and after.

Usage::

    .venv/bin/python benchmarks/fit_speed_bench.py --baseline OLD_TREE [--only NAME ...]
                                                   [--seeds 0 1 2] [--perturbations K]
                                                   [--cache DIR] [--json PATH]

Each dev mesh's cage is built once by ``reconstruct(path, stop_after="basemesh")`` with this
tree and pickled (cage and target) into ``--cache``, so both trees fit the same cage. For every
mesh, a subprocess of the baseline tree (``--baseline``, for example ``git archive f8909fc core |
tar -x -C OLD_TREE``) and one of this tree run ``fit_base_mesh(cage, target, levels=2,
mode="inside", seed=k)`` for each seed, taking turns fit by fit (so a slow spell of this
machine, which comes and goes within minutes, falls on both alike). Each fit is timed by ``time.process_time`` around the call (CPU seconds of
the process, report figures included) and hashed (its vertices' bytes), so identical results
show as identical hashes. Prints a markdown table: CPU seconds per seed, the fit figures
(volume outside, mean and max distance of the fine limit points over the diagonal, crossing
triangle pairs of the fitted limit surface), whether the vertices are bit-identical, and the
load average when each run started; ``--json`` writes the records too, one a line.

The fit is chaotic: its hold-backs and nudges make discrete choices, so a change of the last
bit of one coordinate can give a different fit of different quality (featuretype's largest
distance is 2.2 % or 4.7 % of the diagonal depending on the machine's BLAS build). A change
that does not keep every fit bit for bit is therefore judged over many fits of each cage:
``--perturbations K`` fits seed 0 of the cage and of ``K - 1`` copies whose vertices are
moved by ``PERTURBATION`` of the largest coordinate (normal noise, generator seeded by the
copy's number ``k``), and prints per mesh and tree the median and largest CPU seconds and
figures over the ``K`` fits.
"""
import argparse
import hashlib
import json
import os
import pickle
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
CASES = {"to_simp_cantilever": os.path.join(REPO, "examples", "to_simp_cantilever.stl"),
         **{name: os.path.join(MESHES, name + ext) for name, ext in (
             ("polycube_bone", ".obj"), ("polycube_mambo_b0", ".obj"),
             ("to_levelset_cantilever_tiny", ".stl"), ("idler_riser", ".stl"),
             ("to_simp_mbb", ".stl"), ("to_simp_lbracket", ".stl"), ("to_simp_pylon", ".stl"),
             ("to_simp_torsion_arm", ".stl"), ("tray_bottom", ".stl"), ("fandisk", ".obj"),
             ("gripper_domain", ".stl"), ("ge_bracket_domain", ".stl"),
             ("to_simp_torsion_arm_fine3", ".stl"), ("featuretype", ".stl"),
             ("octagonal_pocket", ".stl"), ("simjeb76_ge_bracket_to", ".stl"),
             ("toplib_michell3d_density_mc", ".stl"))}}
"""The dev meshes that reach the fit."""
PERTURBATION = 1e-12
"""Relative size of the noise added to a cage's vertices by ``--perturbations`` (about the
rounding of coordinates computed another way)."""


def cache_cages(names, folder):
    """Pickle ``(cage, target)`` of each mesh into ``folder`` unless already there."""
    sys.path.insert(0, REPO)
    from core.pipeline import reconstruct

    os.makedirs(folder, exist_ok=True)
    for name in names:
        path = os.path.join(folder, name + ".pkl")
        if not os.path.exists(path):
            state = reconstruct(CASES[name], stop_after="basemesh").state
            with open(path, "wb") as handle:
                pickle.dump((state.basemesh.cage, state.intake.target), handle)


def perturbed(cage, k, size=PERTURBATION):
    """``cage`` for ``k = 0``, else a copy whose vertices carry noise of ``size`` (default
    ``PERTURBATION``) of the largest coordinate (numpy's normal generator seeded with ``k``)."""
    if not k:
        return cage
    import numpy as np
    from dataclasses import replace

    noise = np.random.default_rng(k).standard_normal(cage.vertices.shape)
    return replace(cage, vertices=cage.vertices
                   + size * float(np.abs(cage.vertices).max()) * noise)


def worker(tree, path):
    """Serve fits of one cached cage with ``tree``'s core: for each line ``SEED K`` read from
    stdin, fit seed ``SEED`` of the cage (``K > 0``: of its perturbed copy ``K``,
    :func:`perturbed`) and write one JSON line. One fit of the cage runs first, untimed, so
    that no timed fit pays for the modules the fit imports on first use."""
    sys.path.insert(0, tree)
    from core.fitting import fit_base_mesh

    with open(path, "rb") as handle:
        cage, target = pickle.load(handle)
    fit_base_mesh(cage, target, levels=2, mode="inside")
    for line in sys.stdin:
        seed, k = map(int, line.split())
        load = os.getloadavg()[0]
        started = time.process_time()
        fitted, info = fit_base_mesh(perturbed(cage, k), target, levels=2, mode="inside",
                                     seed=seed)
        cpu = time.process_time() - started
        if not isinstance(info, dict):  # a tree whose fit returns its phase records
            from core.stages.fit import fit_section
            info = {**fit_section(info), "self_intersections": info.self_intersections}
        print(json.dumps({
            "seed": seed, "perturbation": k, "cpu": cpu, "load": load,
            "triangles": len(target.faces),
            "faces": int(cage.n_faces), "outside": info["outside_volume_fraction"],
            "mean": info["mean_distance"], "max": info["max_distance"],
            "crossings": info.get("self_intersections"),
            "hash": hashlib.sha1(fitted.vertices.tobytes()).hexdigest()}), flush=True)


def run(trees, path, runs):
    """Records of both trees' fits of ``runs`` ((seed, k) pairs), fit by fit in turn.

    One worker process per tree (:func:`worker`) is kept alive, and the two fit each run one
    after the other, the baseline first on even runs and last on odd ones, so a slow or quiet
    spell of the machine falls on both alike.

    Returns
    -------
    (before, after) : lists of records, one per run each.
    """
    workers = [subprocess.Popen([sys.executable, __file__, "--worker", tree, path],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
               for tree in trees]
    records = ([], [])
    try:
        for number, (seed, k) in enumerate(runs):
            for side in ((0, 1) if number % 2 == 0 else (1, 0)):
                workers[side].stdin.write(f"{seed} {k}\n")
                workers[side].stdin.flush()
                line = workers[side].stdout.readline()
                if not line:
                    raise RuntimeError(f"the worker of {trees[side]} stopped on {path}")
                records[side].append(json.loads(line))
    finally:
        for process in workers:
            process.stdin.close()
            process.wait()
    return records


def markdown(results):
    """Table rows: mesh, seed, CPU s before / after, figures, identical, load."""
    lines = ["| mesh | triangles | cage faces | seed | CPU s before | CPU s after | outside % "
             "before / after | mean before / after | max before / after | crossings before / "
             "after | identical | load |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, (before, after) in results.items():
        for b, a in zip(before, after):
            lines.append(
                f"| {name} | {a['triangles']} | {a['faces']} | {a['seed']} | {b['cpu']:.2f} | "
                f"{a['cpu']:.2f} | {100 * b['outside']:.3f} / {100 * a['outside']:.3f} | "
                f"{b['mean']:.5f} / {a['mean']:.5f} | {b['max']:.4f} / {a['max']:.4f} | "
                f"{b.get('crossings')} / {a.get('crossings')} | "
                f"{'yes' if a['hash'] == b['hash'] else 'no'} | {b['load']:.1f}-{a['load']:.1f} |")
    return "\n".join(lines)


def spread_markdown(results):
    """Table rows over perturbed fits: per mesh and tree the median and largest of each."""
    import numpy as np

    lines = ["| mesh | fits | CPU s median / max, before -> after | CPU after / before, "
             "median of pairs | outside % median / max | mean (1e-3) median / max | "
             "max (1e-3) median / max | distinct fits |",
             "|---|---|---|---|---|---|---|---|"]

    def spread(records, key, scale, digits):
        values = np.array([r[key] for r in records], dtype=float) * scale
        return f"{np.median(values):.{digits}f} / {values.max():.{digits}f}"

    for name, (before, after) in results.items():
        cells = [" -> ".join(spread(records, key, scale, digits) for records in (before, after))
                 for key, scale, digits in (("cpu", 1, 2), ("outside", 100, 3),
                                            ("mean", 1e3, 2), ("max", 1e3, 1))]
        distinct = " -> ".join(str(len({r["hash"] for r in records})) for records in (before, after))
        ratio = np.median([a["cpu"] / b["cpu"] for b, a in zip(before, after)])
        cells.insert(1, f"{ratio:.2f}")
        lines.append(f"| {name} | {len(after)} | " + " | ".join(cells) + f" | {distinct} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", required=True, help="folder holding an older core/")
    parser.add_argument("--only", nargs="*", default=list(CASES))
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--perturbations", type=int, default=0,
                        help="fit seed 0 of the cage and K - 1 perturbed copies instead")
    parser.add_argument("--cache", default=os.path.join("/tmp", "fit_speed_cages"))
    parser.add_argument("--json", help="also write every record here, one a line")
    args = parser.parse_args(argv)
    cache_cages(args.only, args.cache)
    results = {}
    for name in args.only:
        path = os.path.join(args.cache, name + ".pkl")
        runs = ([(0, k) for k in range(args.perturbations)] if args.perturbations
                else [(seed, 0) for seed in args.seeds])
        results[name] = run((os.path.abspath(args.baseline), REPO), path, runs)
        print(f"{name} done", file=sys.stderr, flush=True)
    print(spread_markdown(results) if args.perturbations else markdown(results))
    if args.json:
        with open(args.json, "w") as handle:
            for name, (before, after) in results.items():
                for tree, records in (("before", before), ("after", after)):
                    for record in records:
                        handle.write(json.dumps({"tree": tree, "name": name, **record}) + "\n")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        worker(sys.argv[2], sys.argv[3])
    else:
        main()
