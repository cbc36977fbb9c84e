# SPDX-License-Identifier: LGPL-2.1-or-later
"""Layout peer: our base mesh's extraordinary vertices against QuadriFlow's at the same face count.

Usage::

    .venv/bin/python benchmarks/layout_peer_bench.py [--meshes DIR ...] [--only NAME ...]
                                                     [--timeout SECONDS] [--refresh]

Reads the case rows of ``benchmarks/basemesh_results.json`` (written by
``benchmarks/basemesh_bench.py``: per mesh and parts mode our route, faces, extraordinary
vertices and genus) and, for each, asks QuadriFlow (PyPI ``pyquadriflow``, a benchmark-only
dependency) for a quad mesh of our face count on the same target (the intake stage's
validated triangle mesh). Each QuadriFlow run is its own process with a timeout, since it can
crash or hang. Of its quad mesh: faces, extraordinary vertices (interior vertices of valence
other than 4), holes (QuadriFlow can leave small boundary loops), genus from the Euler
characteristic where the mesh is a closed 2-manifold, else once each hole is closed by one
face, else what it has instead of a 2-manifold; components and seconds. The summary per parts
mode: the median and worst ratio of our extraordinary vertices per face to QuadriFlow's over
the meshes where QuadriFlow keeps the genus, and how many of ours take the polycube route.

QuadriFlow's results are cached in ``benchmarks/layout_peer_cache.json`` by the SHA-256 of the
mesh file and the face count asked, so a run after our base mesh changes runs QuadriFlow only
for the face counts not asked before (and for the runs that timed out; ``--refresh`` runs every
case again). Writes ``benchmarks/LAYOUT_PEER_RESULTS.md`` and
``benchmarks/images/layout_peer_evs.png``.
"""
import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
DEFAULT_MESHES = (os.path.join(REPO, "..", "shared", "data", "meshes"),
                  os.path.join(HERE, "simp_unseen"))
BASEMESH_JSON = os.path.join(HERE, "basemesh_results.json")
CACHE_JSON = os.path.join(HERE, "layout_peer_cache.json")
RESULTS_MD = os.path.join(HERE, "LAYOUT_PEER_RESULTS.md")
IMAGE = os.path.join(HERE, "images", "layout_peer_evs.png")
MODES = ("single", "auto")
SEED = 0
"""QuadriFlow's random seed (fixed, so a cached result is the one a re-run would give)."""
FLAGS = {"preserve_sharp": False, "preserve_boundary": False, "adaptive_scale": False,
         "aggressive_sat": False, "minimum_cost_flow": False}
"""QuadriFlow's options, its defaults (as ``benchmarks/fit_bench.py`` calls it)."""
FACE_TOLERANCE = 0.1
"""QuadriFlow's face count is taken as ours within this fraction of ours."""
ATTEMPTS = 3
"""QuadriFlow runs per case at most, each asking for the count scaled by the last miss."""
EV_RATIO_MEDIAN = 1.0
EV_RATIO_WORST = 1.5
"""The rule: where QuadriFlow keeps the genus, our extraordinary vertices per face at most
QuadriFlow's on the median mesh and at most 1.5 times on every mesh."""


def quad_mesh_figures(faces):
    """Topology of a polygon mesh of equal-size faces, as QuadriFlow returns it.

    Parameters
    ----------
    faces : (m, k) int64 corners of each face (vertex indices; unreferenced vertices are
        not counted).

    Returns
    -------
    dict: ``faces``, ``vertices`` (referenced ones), ``degenerate_faces`` (a corner repeated),
    ``boundary_edges`` (one face), ``non_manifold_edges`` (more than two faces),
    ``non_manifold_vertices`` (faces around the vertex in more than one fan),
    ``misoriented_edges`` (an edge walked the same way by two faces), ``components`` (through
    shared vertices), ``euler`` (V - E + F), ``closed_manifold`` (bool), ``genus`` (from the
    Euler characteristic, None unless a closed 2-manifold), ``holes`` (boundary loops of a
    2-manifold with boundary), ``genus_holes_filled`` (the genus once each hole is closed by
    one face, None unless a 2-manifold), ``extraordinary_vertices`` (vertices on no boundary
    edge whose valence is not 4), ``rim_vertices`` and ``rim_extraordinary_vertices`` (the
    vertices on boundary edges, and those of valence other than 4), ``min_valence``,
    ``max_valence``.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64)
    m, k = faces.shape
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    faces = inverse.reshape(m, k)
    n = np.int64(len(used))
    repeated = np.zeros(m, dtype=bool)
    for i in range(k):
        for j in range(i + 1, k):
            repeated |= faces[:, i] == faces[:, j]
    degenerate = int(repeated.sum())
    a, b = faces.reshape(-1), np.roll(faces, -1, axis=1).reshape(-1)
    undirected = np.minimum(a, b) * n + np.maximum(a, b)
    edges, uses = np.unique(undirected, return_counts=True)
    _, directed_uses = np.unique(a * n + b, return_counts=True)
    valence = np.bincount(np.concatenate([edges // n, edges % n]), minlength=n)
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[np.concatenate([edges[uses == 1] // n, edges[uses == 1] % n])] = True
    # Fans: corners at the same vertex are linked when they share an edge at that vertex.
    corner = np.arange(m * k)
    prev = np.roll(faces, 1, axis=1).reshape(-1)
    keys = np.concatenate([a * n + b, a * n + prev])
    owners = np.concatenate([corner, corner])
    order = np.argsort(keys, kind="stable")
    same = keys[order][1:] == keys[order][:-1]
    links = sp.coo_matrix((np.ones(int(same.sum())), (owners[order][1:][same],
                                                      owners[order][:-1][same])),
                          shape=(m * k, m * k))
    _, fan = connected_components(links, directed=False)
    fans_per_vertex = np.bincount(np.unique(a * (m * k) + fan) // (m * k), minlength=n)
    incidence = sp.csr_matrix((np.ones(m * k), (a, np.repeat(np.arange(m), k))), shape=(n, m))
    components, _ = connected_components(incidence @ incidence.T, directed=False)
    euler = int(n) - len(edges) + m
    manifold = bool(degenerate == 0 and (uses <= 2).all() and (fans_per_vertex == 1).all())
    closed_manifold = manifold and bool((uses == 2).all())
    rim = edges[uses == 1]
    holes = 0
    if manifold and len(rim):
        loops = sp.coo_matrix((np.ones(len(rim)), (rim // n, rim % n)), shape=(n, n))
        _, label = connected_components(loops, directed=False)
        holes = len(np.unique(label[on_boundary]))
    interior = valence[~on_boundary]
    return {"faces": int(m), "vertices": int(n), "degenerate_faces": degenerate,
            "boundary_edges": int((uses == 1).sum()),
            "non_manifold_edges": int((uses > 2).sum()),
            "non_manifold_vertices": int((fans_per_vertex > 1).sum()),
            "misoriented_edges": int((directed_uses > 1).sum()),
            "components": int(components), "euler": euler, "closed_manifold": closed_manifold,
            "genus": (2 * int(components) - euler) // 2 if closed_manifold else None,
            "holes": holes,
            "genus_holes_filled": ((2 * int(components) - euler - holes) // 2 if manifold
                                   else None),
            "extraordinary_vertices": int((interior != 4).sum()),
            "rim_vertices": int(on_boundary.sum()),
            "rim_extraordinary_vertices": int((valence[on_boundary] != 4).sum()),
            "min_valence": int(valence.min()) if n else None,
            "max_valence": int(valence.max()) if n else None}


def run_peer(path, faces, out_json):
    """QuadriFlow on the intake target of ``path`` at about ``faces`` quads; writes a JSON dict.

    Run in a process of its own (``--case``): the target is the intake stage's validated
    triangle mesh, the one our base mesh is built on. QuadriFlow's face count can miss the one
    asked by a third; while it misses by more than ``FACE_TOLERANCE``, it is asked again for
    the count scaled by the miss (at most ``ATTEMPTS`` runs), and the run nearest ``faces``
    is kept.
    """
    from pyQuadriFlow.pyQuadriFlow import pyquadriflow

    from core.pipeline import reconstruct

    result = reconstruct(path, {}, stop_after="intake")
    target = result.state.intake.target
    summary = result.report["input"]
    vertices, triangles = target.vertices.tolist(), target.faces.tolist()
    row = {"target_triangles": int(len(target.faces)), "target_genus": int(summary["genus"]),
           "target_components": int(summary.get("components", 1)), "asked": [], "got": []}
    best, ask, total = None, int(faces), 0.0
    for _ in range(ATTEMPTS):
        started = time.perf_counter()
        out = pyquadriflow(ask, SEED, vertices, triangles, *FLAGS.values())
        seconds = time.perf_counter() - started
        total += seconds
        quads = np.asarray(out["faces"], dtype=np.int64)
        row["asked"].append(ask)
        row["got"].append(int(len(quads)))
        if len(quads) == 0:
            break
        if best is None or abs(len(quads) - faces) < abs(len(best[0]) - faces):
            best = (quads.reshape(len(quads), -1), seconds)
        if abs(len(quads) - faces) <= FACE_TOLERANCE * faces:
            break
        ask = max(1, int(round(ask * faces / len(quads))))
    row["total_seconds"] = round(total, 2)
    if best is None:
        row["error"] = "QuadriFlow returned no faces"
    else:
        row.update(quad_mesh_figures(best[0]), seconds=round(best[1], 2))
    with open(out_json, "w", encoding="utf-8") as handle:
        json.dump(row, handle)


def peer_result(path, faces, timeout):
    """QuadriFlow's figures for ``path`` at ``faces`` (dict), from a child process that is
    stopped after ``timeout`` seconds; a crash or a timeout is recorded as ``error``."""
    with tempfile.TemporaryDirectory(prefix="layout-peer-") as tmp:
        out = os.path.join(tmp, "peer.json")
        started = time.perf_counter()
        try:
            done = subprocess.run([sys.executable, os.path.abspath(__file__), "--case", path,
                                   str(faces), out], capture_output=True, text=True,
                                  timeout=timeout, cwd=REPO)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout:g} s", "timed_out": True}
        if os.path.exists(out):
            with open(out, encoding="utf-8") as handle:
                row = json.load(handle)
        else:
            lines = [line for line in done.stderr.strip().splitlines() if line.strip()]
            row = {"error": (lines[-1] if lines else f"exit code {done.returncode}")[:300]}
        row["process_seconds"] = round(time.perf_counter() - started, 2)
        return row


def file_sha256(path):
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def find_meshes(folders):
    """``{stem: path}`` of the mesh files in ``folders`` (the first folder wins a stem)."""
    found = {}
    for folder in folders:
        for name in sorted(os.listdir(folder)):
            stem, ext = os.path.splitext(name)
            if ext.lower() in (".stl", ".obj", ".ply", ".off"):
                found.setdefault(stem, os.path.abspath(os.path.join(folder, name)))
    return found


def per_100(evs, faces):
    return None if evs is None or not faces else 100.0 * evs / faces


def ev_ratio(ours, peer):
    """Our extraordinary vertices per face over QuadriFlow's (inf where only QuadriFlow has
    none, 1 where neither has any)."""
    if ours is None or peer is None:
        return None
    if peer == 0:
        return 1.0 if ours == 0 else float("inf")
    return ours / peer


KEPT, KEPT_FILLED, NOT_KEPT = "yes", "with holes filled", "no"
"""Whether QuadriFlow keeps the genus: as a closed 2-manifold, once each hole of its quad mesh
is closed by one face, or neither."""


def peer_topology(peer):
    """QuadriFlow's mesh in words: its genus, or what keeps it from having one (str)."""
    extra = "" if peer["components"] == peer["target_components"] else \
        f" ({peer['components']} components)"
    if peer["closed_manifold"]:
        return f"{peer['genus']}{extra}"
    if peer["genus_holes_filled"] is not None:
        return f"{peer['genus_holes_filled']} with holes filled{extra}"
    flaws = [f"{peer[key]} {label}" for key, label in (
        ("non_manifold_edges", "non-manifold edges"),
        ("non_manifold_vertices", "non-manifold vertices"),
        ("degenerate_faces", "degenerate faces")) if peer[key]]
    return "none: " + ", ".join(flaws)


def peer_holes(peer):
    """QuadriFlow's holes in words: how many, the vertices on their rims and how many of those
    are extraordinary (str)."""
    if peer["genus_holes_filled"] is None:
        return f"– ({peer['boundary_edges']} open edges)"
    if not peer["holes"]:
        return "0"
    return (f"{peer['holes']} ({peer['rim_vertices']} rim vertices, "
            f"{peer['rim_extraordinary_vertices']} of valence ≠ 4)")


def peer_keeps_genus(peer, genus):
    """``KEPT`` where QuadriFlow's mesh is a closed 2-manifold of the target's components and
    ``genus``; ``KEPT_FILLED`` where it is once each hole is closed by one face; else
    ``NOT_KEPT``."""
    if peer["components"] != peer["target_components"]:
        return NOT_KEPT
    if peer["closed_manifold"]:
        return KEPT if peer["genus"] == genus else NOT_KEPT
    return KEPT_FILLED if peer["genus_holes_filled"] == genus else NOT_KEPT


def compare(rows, cache, meshes):
    """One comparison per case row of ``basemesh_results.json`` (list of dict)."""
    table = []
    for r in rows:
        base = r.get("base_mesh")
        entry = {"mesh": r["mesh"], "mode": r["mode"], "method": r.get("method", "auto"),
                 "genus": r.get("input_genus")}
        if base:
            entry.update(route=base.get("method") or "polycube", faces=base["faces"],
                         evs=base["extraordinary_vertices"],
                         genus_kept=base["genus"] == r["input_genus"])
            key = cache_key(meshes.get(r["mesh"]), base["faces"])
            peer = cache.get(key) if key else {"error": "mesh file not found"}
            entry["peer"] = peer if peer is not None else {"error": "not run"}
            if "error" not in entry["peer"]:
                entry["peer_genus_kept"] = peer_keeps_genus(peer, r["input_genus"])
                entry["ratio"] = ev_ratio(per_100(entry["evs"], entry["faces"]),
                                          per_100(peer["extraordinary_vertices"], peer["faces"]))
        table.append(entry)
    return table


def cache_key(path, faces):
    """``"<sha256>:<faces>"`` of a mesh file and a face count (None without a file)."""
    return None if path is None else f"{_hashes.setdefault(path, file_sha256(path))}:{faces}"


_hashes = {}
"""SHA-256 of each mesh file read in this run, by path."""


def summary(table, mode, accepted):
    """The rule's figures over the rows of parts mode ``mode`` with the default route where
    QuadriFlow's genus is one of ``accepted`` (dict)."""
    rows = [t for t in table if t["mode"] == mode and t["method"] == "auto" and "faces" in t]
    kept = [t for t in rows if t.get("peer_genus_kept") in accepted and t.get("ratio") is not None]
    ratios = [t["ratio"] for t in kept]
    median = statistics.median(ratios) if ratios else None
    worst = max(kept, key=lambda t: t["ratio"]) if kept else None
    return {"mode": mode, "rows": len(rows), "peer_kept": len(kept), "median": median,
            "worst": worst["ratio"] if worst else None,
            "worst_mesh": worst["mesh"] if worst else None,
            "polycube": sum(t["route"] == "polycube" for t in rows),
            "median_ok": median is not None and median <= EV_RATIO_MEDIAN,
            "worst_ok": worst is not None and worst["ratio"] <= EV_RATIO_WORST}


def _fmt(value, digits=2):
    if value is None:
        return "–"
    if value == float("inf"):
        return "∞"
    return f"{value:.{digits}f}"


def _run_days(table):
    """The days QuadriFlow's results in ``table`` were computed (sorted list of str)."""
    return sorted({t["peer"]["date"][:10] for t in table if "date" in t.get("peer", {})})


def markdown(table, meta):
    lines = ["# Layout peer: extraordinary vertices against QuadriFlow", "",
             "Written by `benchmarks/layout_peer_bench.py`; do not edit by hand.", "",
             f"- Date: {meta['date']}; commit {meta['commit']}; load (1 min) at start "
             f"{meta['load']}; QuadriFlow: PyPI `pyquadriflow` {meta['quadriflow']}, seed {SEED}, "
             "default options, each run in its own process (timeout "
             f"{meta['timeout']:g} s); {meta['ran']} cases run by QuadriFlow in this run, the "
             "others from `layout_peer_cache.json` (by mesh file SHA-256 and faces asked; "
             f"QuadriFlow run on {', '.join(_run_days(table))}).",
             f"- Ours: `basemesh_results.json` of {meta['basemesh']['date']}, commit "
             f"{meta['basemesh']['commit']} (`benchmarks/basemesh_bench.py`, default "
             "parameters, `--target-faces 300`).",
             "- QuadriFlow is asked for our face count on the same target (the intake stage's "
             "validated mesh). Its face count can miss the one asked by a third: while it "
             f"misses ours by more than {FACE_TOLERANCE:.0%}, it is asked again for the count "
             f"scaled by the miss (at most {ATTEMPTS} runs), and the run nearest ours is kept. "
             "QF s: seconds of that run's remesh alone (wall).",
             "- EVs: extraordinary vertices; ours: valence other than 4 on our closed cage; "
             "QuadriFlow's: interior vertices (on no open edge) of valence other than 4. QF "
             "holes: boundary loops of QuadriFlow's quad mesh, the vertices on their rims "
             "(not counted in its EVs) and how many of those have a valence other than 4. "
             "Genus: from the Euler characteristic; QuadriFlow's as returned where it is a "
             "closed 2-manifold, else once each hole is closed by one face (`with holes "
             "filled`), else `none` with what it has instead of a 2-manifold. Ratio: our EVs "
             "per face over QuadriFlow's.",
             f"- Rule: where QuadriFlow keeps the genus, the ratio at most {EV_RATIO_MEDIAN:g} on "
             f"the median mesh and at most {EV_RATIO_WORST:g} on every mesh (default route "
             "rows only; QuadriFlow's meshes whose holes, each closed by one face, give the "
             "genus get a line of their own where there are any).", ""]
    for mode in MODES:
        for accepted, how in (((KEPT,), "keeps the genus as a closed mesh"),
                              ((KEPT, KEPT_FILLED), "keeps the genus, counting a mesh whose "
                               "holes, each closed by one face, give the genus")):
            s = summary(table, mode, accepted)
            if not s["rows"] or (len(accepted) > 1
                                 and s["peer_kept"] == summary(table, mode, (KEPT,))["peer_kept"]):
                continue
            lines.append(
                f"- **{mode}**: polycube route on {s['polycube']} of {s['rows']} meshes; "
                f"QuadriFlow {how} on {s['peer_kept']}; over those, median ratio "
                f"{_fmt(s['median'])} (at most {EV_RATIO_MEDIAN:g}: "
                f"{'yes' if s['median_ok'] else 'no'}), worst {_fmt(s['worst'])} on "
                f"`{s['worst_mesh']}` (at most {EV_RATIO_WORST:g}: "
                f"{'yes' if s['worst_ok'] else 'no'}).")
    lines.append("")
    forced = any(t["method"] != "auto" for t in table)
    header = ["mesh", "parts"] + (["asked route"] if forced else []) + [
        "genus", "our route", "our faces", "our EVs", "our EVs / 100 faces", "our genus kept",
        "QF faces", "QF holes", "QF EVs", "QF EVs / 100 faces", "QF genus", "QF genus kept",
        "QF s",
        "ratio ours / QF"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for t in table:
        cells = [f"`{t['mesh']}`", t["mode"]] + ([t["method"]] if forced else []) + \
            [str(t["genus"])]
        if "faces" not in t:
            lines.append("| " + " | ".join(cells + ["not reached"] + ["–"] * 12) + " |")
            continue
        peer = t["peer"]
        cells += [t["route"], str(t["faces"]), str(t["evs"]),
                  _fmt(per_100(t["evs"], t["faces"]), 1),
                  "yes" if t["genus_kept"] else "**no**"]
        if "error" in peer:
            cells += [peer["error"] if peer["error"] in ("not run", "mesh file not found")
                      else "failed: " + peer["error"][:80]] + ["–"] * 7
        else:
            cells += [str(peer["faces"]), peer_holes(peer), str(peer["extraordinary_vertices"]),
                      _fmt(per_100(peer["extraordinary_vertices"], peer["faces"]), 1),
                      peer_topology(peer), t["peer_genus_kept"],
                      _fmt(peer["seconds"], 1), _fmt(t["ratio"])]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "![EVs per 100 faces, ours and QuadriFlow's](images/layout_peer_evs.png)"]
    return "\n".join(lines) + "\n"


PEER_COLOUR = "#3d8a3d"
PEER_BARS = {KEPT: (PEER_COLOUR, None), KEPT_FILLED: ("#a6d5a6", ".."),
             NOT_KEPT: ("white", "///")}
"""Fill and hatch of QuadriFlow's bars by whether it keeps the genus."""


def plot(table, path):
    """Bar chart of extraordinary vertices per 100 faces, ours (by route) and QuadriFlow's
    (filled by whether it keeps the genus, ``PEER_BARS``), per mesh, one panel per parts
    mode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    modes = [m for m in MODES if any(t["mode"] == m and t["method"] == "auto" and "faces" in t
                                     for t in table)]
    fig, axes = plt.subplots(len(modes), 1, figsize=(14, 4.5 * len(modes)), squeeze=False)
    colours = {"polycube": "#2f6fbf", "paired decimation": "#d98c2b"}
    for ax, mode in zip(axes[:, 0], modes):
        rows = [t for t in table if t["mode"] == mode and t["method"] == "auto" and "faces" in t]
        x = np.arange(len(rows))
        ours = [per_100(t["evs"], t["faces"]) for t in rows]
        ax.bar(x - 0.2, ours, 0.4, color=[colours.get(t["route"], "grey") for t in rows])
        for k, t in enumerate(rows):
            peer = t["peer"]
            if "error" in peer:
                ax.text(x[k] + 0.2, 0.5, peer["error"][:20], rotation=90, ha="center", va="bottom",
                        fontsize=7)
                continue
            fill, hatch = PEER_BARS[t["peer_genus_kept"]]
            ax.bar(x[k] + 0.2, per_100(peer["extraordinary_vertices"], peer["faces"]), 0.4,
                   color=fill, edgecolor=PEER_COLOUR, hatch=hatch)
        ax.set_xticks(x)
        ax.set_xticklabels([f"{t['mesh']} (g{t['genus']})" for t in rows], rotation=60,
                           ha="right", fontsize=8)
        ax.set_ylabel("EVs per 100 faces")
        ax.set_title(f"--parts {mode}")
        ax.grid(axis="y", alpha=0.3)
    fig.legend(handles=[Patch(color=colours["polycube"], label="ours, polycube layout"),
                        Patch(color=colours["paired decimation"], label="ours, paired decimation"),
                        *[Patch(facecolor=fill, edgecolor=PEER_COLOUR, hatch=hatch,
                                label=f"QuadriFlow, genus kept: {kept}")
                          for kept, (fill, hatch) in PEER_BARS.items()]],
               loc="upper center", ncol=5, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="*", default=list(DEFAULT_MESHES),
                        help="folders of the meshes named in basemesh_results.json")
    parser.add_argument("--only", nargs="*", help="run QuadriFlow only for these meshes")
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--refresh", action="store_true",
                        help="run QuadriFlow again where the cache has a result")
    parser.add_argument("--case", nargs=3, metavar=("PATH", "FACES", "JSON"))
    args = parser.parse_args(argv)
    if args.case:
        run_peer(args.case[0], int(args.case[1]), args.case[2])
        return 0
    from importlib.metadata import version

    with open(BASEMESH_JSON, encoding="utf-8") as handle:
        ours = json.load(handle)
    meshes = find_meshes(args.meshes)
    cache = {}
    if os.path.exists(CACHE_JSON):
        with open(CACHE_JSON, encoding="utf-8") as handle:
            cache = json.load(handle)
    meta = {"date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "load": round(os.getloadavg()[0], 2),
            "timeout": args.timeout, "quadriflow": version("pyQuadriFlow"),
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                     capture_output=True, text=True).stdout.strip(),
            "basemesh": {k: ours["meta"][k] for k in ("date", "commit")}, "ran": 0}
    ran = set()
    for r in ours["rows"]:
        base, path = r.get("base_mesh"), meshes.get(r["mesh"])
        if not base or path is None or (args.only and r["mesh"] not in args.only):
            continue
        key = cache_key(path, base["faces"])
        known = cache.get(key)
        if key in ran or (known is not None and not known.get("timed_out")
                          and not args.refresh):
            continue
        peer = peer_result(path, base["faces"], args.timeout)
        peer.update(mesh=r["mesh"], asked_faces=base["faces"], date=meta["date"])
        cache[key] = peer
        ran.add(key)
        meta["ran"] = len(ran)
        print(r["mesh"], base["faces"], peer.get("faces"), peer.get("extraordinary_vertices"),
              peer.get("genus"), peer.get("error", ""), flush=True)
        with open(CACHE_JSON, "w", encoding="utf-8") as handle:
            json.dump(cache, handle, indent=1, sort_keys=True)
    table = compare(ours["rows"], cache, meshes)
    os.makedirs(os.path.dirname(IMAGE), exist_ok=True)
    plot(table, IMAGE)
    with open(RESULTS_MD, "w", encoding="utf-8") as handle:
        handle.write(markdown(table, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
