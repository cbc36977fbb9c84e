# SPDX-License-Identifier: LGPL-2.1-or-later
"""The pipeline on SIMP results that are not in ../shared/ (the development meshes).

Usage::

    .venv/bin/python benchmarks/unseen_bench.py [--only NAME ...] [--modes single auto]
                                                [--timeout SECONDS]

The designs come from ``benchmarks/simp_designs.py`` (``benchmarks/simp_unseen/*.stl``, listed
with their SHA-256 in ``benchmarks/simp_unseen/MANIFEST.json``); a missing or changed STL is
regenerated with ``benchmarks/.simp-venv/bin/python benchmarks/simp_designs.py NAME``. Each
design runs exactly as a user would, in its own process with a timeout::

    .venv/bin/python -m polycube_wb reconstruct MESH -o OUT.step --report OUT.json
        --labels OUT.ply --base-mesh OUT.obj [--parts auto]

(default parameters otherwise). The STEP file is judged by the independent
``../shared/tools/evaluate.py`` (B-rep validity, two-sided distances as fractions of the
target's bounding-box diagonal, containment), the labels by ``../shared/tools/labelcheck.py``.
Writes ``benchmarks/UNSEEN_RESULTS.md``, ``benchmarks/unseen_results.json`` (rows kept per
design and parts mode, so ``--only`` updates a few) and per case a PNG of the base cage over
its target (``benchmarks/images/unseen_NAME_MODE.png``, the helper of basemesh_bench.py) and
of the target alone (``unseen_NAME_target.png``, ``benchmarks/render.py``).

Large targets: ``--large`` adds, for each design of :data:`LARGE_DESIGNS`, the same design
Loop-subdivided twice (``NAME_loop2``, 16 times the triangles, 100k-170k; a finer and smoother
surface of the same result, as a TO exporter's fine output is), written once into
``benchmarks/tmp/unseen_large/`` (deterministic; the start of its SHA-256 is in the designs
table).
"""
import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)
SHARED_TOOLS = os.path.join(REPO, "..", "shared", "tools")
DESIGNS = os.path.join(HERE, "simp_unseen")
MANIFEST = os.path.join(DESIGNS, "MANIFEST.json")
SIMP_PYTHON = os.path.join(HERE, ".simp-venv", "bin", "python")
WORK = os.path.join(HERE, "tmp", "unseen")
IMAGES = os.path.join(HERE, "images")
RESULTS_JSON = os.path.join(HERE, "unseen_results.json")
RESULTS_MD = os.path.join(HERE, "UNSEEN_RESULTS.md")
LARGE = os.path.join(HERE, "tmp", "unseen_large")
LARGE_DESIGNS = ("simp_crank_arm", "simp_gripper_jaw", "simp_two_load_bracket")
LARGE_SUFFIX = "_loop2"
MODES = ("single", "auto")
STAGES = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches", "solid")


def sha256(path):
    with open(path, "rb") as handle:
        return hashlib.sha256(handle.read()).hexdigest()


def ensure_designs(names):
    """Manifest entries (dict name -> dict) of the wanted designs, regenerating missing STLs.

    Raises
    ------
    SystemExit when a design must be generated and the benchmark venv is missing.
    """
    manifest = _load(MANIFEST) or {}
    stale = [n for n in (names or sorted(manifest))
             if n not in manifest or not os.path.exists(os.path.join(DESIGNS, n + ".stl"))
             or sha256(os.path.join(DESIGNS, n + ".stl")) != manifest[n]["sha256"]]
    if stale:
        if not os.path.exists(SIMP_PYTHON):
            raise SystemExit(f"{', '.join(stale)}: STL missing or changed and {SIMP_PYTHON} "
                             "does not exist; create it as requirements-dev.txt says")
        subprocess.run([SIMP_PYTHON, "-W", "ignore", os.path.join(HERE, "simp_designs.py")]
                       + stale, check=True)
        manifest = _load(MANIFEST)
    return {n: manifest[n] for n in (names or sorted(manifest))}


def ensure_large(names):
    """Manifest-like entries (dict name -> dict) of the Loop-subdivided large designs.

    names : the wanted ``NAME_loop2`` names (empty: all of :data:`LARGE_DESIGNS`). Each is made
    from its design's STL (regenerated as :func:`ensure_designs` does) when it is missing, or
    when it or its source changed since it was made (``LARGE/MANIFEST.json`` records both
    hashes and the figures of the table).
    """
    import trimesh

    bases = [n[:-len(LARGE_SUFFIX)] for n in names if n.endswith(LARGE_SUFFIX)] \
        if names else list(LARGE_DESIGNS)
    os.makedirs(LARGE, exist_ok=True)
    manifest_path = os.path.join(LARGE, "MANIFEST.json")
    made = _load(manifest_path) or {}
    entries = {}
    for base, entry in ensure_designs(bases).items():
        name = base + LARGE_SUFFIX
        path = os.path.join(LARGE, name + ".stl")
        known = made.get(name, {})
        if not (os.path.exists(path) and known.get("source_sha256") == entry["sha256"]
                and known.get("sha256") == sha256(path)):
            source = trimesh.load(os.path.join(DESIGNS, entry["file"]), process=True)
            vertices, faces = trimesh.remesh.subdivide_loop(source.vertices, source.faces,
                                                            iterations=2)
            mesh = trimesh.Trimesh(vertices, faces, process=False)
            tmp = path + ".tmp.stl"
            mesh.export(tmp)
            os.replace(tmp, path)
            made[name] = {"source_sha256": entry["sha256"], "sha256": sha256(path),
                          "triangles": len(mesh.faces),
                          "genus": int(round((2 - mesh.euler_number) / 2))}
            tmp = manifest_path + ".tmp"
            with open(tmp, "w", encoding="utf-8") as handle:
                json.dump(made, handle, indent=1, sort_keys=True)
            os.replace(tmp, manifest_path)
        entries[name] = {**entry, "file": path,
                         "what": f"{base}, Loop-subdivided twice (SHA-256 "
                                 f"{made[name]['sha256'][:12]})",
                         **{k: made[name][k] for k in ("sha256", "triangles", "genus")}}
    return entries


def _load(path):
    if not os.path.exists(path):
        return None
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)


def _json_tool(argv, timeout):
    """Run a ../shared/tools script that prints JSON; (dict or None, error text)."""
    try:
        done = subprocess.run([sys.executable] + argv, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout} s"
    text = done.stdout
    try:
        return json.loads(text[text.index("{"):]), ""
    except ValueError:
        return None, (done.stderr or text).strip()[-300:]


def run_case(name, mesh, mode, timeout):
    """One design in one parts mode: CLI run, independent checks, PNG (dict row)."""
    out = os.path.join(WORK, f"{name}_{mode}")
    os.makedirs(out, exist_ok=True)
    paths = {k: os.path.join(out, f"result.{k}") for k in ("step", "json", "ply", "obj")}
    for path in paths.values():
        if os.path.exists(path):
            os.remove(path)
    cmd = [sys.executable, "-m", "polycube_wb", "reconstruct", mesh, "-o", paths["step"],
           "--report", paths["json"], "--labels", paths["ply"], "--base-mesh", paths["obj"]]
    if mode == "auto":
        cmd += ["--parts", "auto"]
    started = time.perf_counter()
    row = {"design": name, "mode": mode}
    try:
        done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=timeout)
        row["exit_code"] = done.returncode
        row["stderr"] = done.stderr.strip()[-400:]
    except subprocess.TimeoutExpired:
        row["exit_code"] = None
        row["stderr"] = f"timed out after {timeout} s"
    row["seconds"] = round(time.perf_counter() - started, 1)
    report = _load(paths["json"])
    row.update(_from_report(report))
    if os.path.exists(paths["ply"]):
        row["labelcheck"], err = _json_tool([os.path.join(SHARED_TOOLS, "labelcheck.py"),
                                             paths["ply"]], timeout)
        if err:
            row["labelcheck_error"] = err
    if os.path.exists(paths["step"]):
        row["evaluation"], err = _json_tool([os.path.join(SHARED_TOOLS, "evaluate.py"),
                                             "--target", mesh, "--result", paths["step"]],
                                            timeout)
        if err:
            row["evaluation_error"] = err
    row["images"] = render(name, mode, mesh, paths["obj"])
    return row


def _from_report(report):
    """Stage reached, failure, base-mesh and fit figures of a pipeline report (dict)."""
    if report is None:
        return {"report": False}
    stages = report.get("stages", {})
    reached = [s for s in STAGES if stages.get(s, {}).get("status") == "ok"]
    failed = [(s, stages[s]) for s in STAGES if s in stages and stages[s]["status"] != "ok"]
    base = report.get("base_mesh") or {}
    fit = report.get("fit") or {}
    brep = report.get("brep") or {}
    return {
        "report": True,
        "triangles": report.get("input", {}).get("triangles"),
        "genus": report.get("input", {}).get("genus"),
        "reached": reached[-1] if reached else None,
        "failed_stage": failed[0][0] if failed else None,
        "failed_status": failed[0][1]["status"] if failed else None,
        "failed_message": failed[0][1].get("message", "")[:400] if failed else "",
        "stage_seconds": {s: stages[s].get("seconds") for s in STAGES if s in stages},
        "stage_messages": {s: stages[s]["message"] for s in STAGES
                           if s in stages and stages[s].get("message")},
        "parts": report.get("parts", {}).get("parts"),
        "labeling_valid": report.get("labeling", {}).get("valid"),
        "base_mesh": {k: base.get(k) for k in (
            "method", "fallback_reason", "faces", "quads", "extraordinary_vertices", "genus",
            "within_budget", "minimum_reason", "inverted_faces")} if base else None,
        "fit_self_intersections": fit.get("self_intersections"),
        "brep": {k: brep.get(k) for k in ("faces", "valid", "closed")} if brep else None,
        "total_seconds": report.get("total_seconds"),
    }


def render(name, mode, mesh, base_obj):
    """PNGs of the target (shaded grey) and, when one was written, the base cage over it.

    Returns the image paths relative to benchmarks/ (list of str).
    """
    import numpy as np

    from basemesh_bench import render_cage
    from core.mesh_io import read_triangle_soup
    from core.polymesh_io import read_polymesh
    from render import render_faces

    os.makedirs(IMAGES, exist_ok=True)
    V, F = read_triangle_soup(mesh)
    images = [os.path.join(IMAGES, f"unseen_{name}_target.png")]
    render_faces(images[0], V, F, np.full((len(F), 3), 0.75), f"{name}: target, {len(F)} triangles")
    if os.path.exists(base_obj):
        cage = read_polymesh(base_obj)
        images.append(os.path.join(IMAGES, f"unseen_{name}_{mode}.png"))
        render_cage(images[1], V, F, cage, f"{name} ({mode}): {cage.n_faces} base faces")
    return [os.path.relpath(path, HERE) for path in images]


def _fmt(value, digits=4):
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def _evaluation_cells(row):
    ev = row.get("evaluation") or {}
    brep = ev.get("brep") or {}
    dist = (ev.get("distance") or {}).get("symmetric") or {}
    cont = ev.get("containment") or {}
    valid = "-" if not ev else ("yes" if brep.get("is_valid") and brep.get("all_shells_closed")
                                and brep.get("solids") == 1 else "NO")
    return [valid, _fmt(dist.get("mean_frac")), _fmt(dist.get("max_frac")),
            _fmt(cont.get("outside_fraction"))]


def _summary(rows):
    """Bullet lines counting the cases per outcome."""
    out = []
    for mode in MODES:
        mine = [r for r in rows if r["mode"] == mode]
        if not mine:
            continue
        base = [r.get("base_mesh") or {} for r in mine]
        valid = sum(_evaluation_cells(r)[0] == "yes" for r in mine)
        out.append(
            f"- {mode}: {len(mine)} cases; STEP written {sum(r.get('exit_code') == 0 for r in mine)}, "
            f"valid closed single solid (evaluate.py) {valid}; labeling valid (labelcheck) "
            f"{sum(bool((r.get('labelcheck') or {}).get('valid')) for r in mine)}; polycube base "
            f"mesh {sum(b.get('method') == 'polycube' for b in base)}, paired decimation "
            f"{sum(b.get('method') == 'paired decimation' for b in base)}; with inverted base "
            f"faces {sum((b.get('inverted_faces') or 0) > 0 for b in base)}; with fitted "
            f"self-intersections {sum((r.get('fit_self_intersections') or 0) > 0 for r in mine)}.")
    return out


def _earlier_rows(rows, meta):
    """A line naming the cases kept from runs at other commits, if any (``--only`` runs)."""
    earlier = {}
    for row in rows:
        commit = row.get("commit", "unknown")
        if commit != meta["commit"]:
            earlier.setdefault(commit, []).append(f"{row['design']} ({row['mode']})")
    return [f"- Kept from the run at commit {commit}: {', '.join(cases)}."
            for commit, cases in sorted(earlier.items())]


def markdown(rows, manifest, meta):
    lines = ["# The pipeline on unseen SIMP results", "",
             "Written by `benchmarks/unseen_bench.py`; do not edit by hand.", "",
             f"- Date: {meta['date']}; commit {meta['commit']}; load (1 min) at start "
             f"{meta['load']}; timeout per case {meta['timeout']} s.",
             *_earlier_rows(rows, meta),
             "- Designs: `benchmarks/simp_designs.py` (pymoto 2.0.1, density filter, OC, marching "
             "cubes at 0.5, 8 Taubin iterations, mm), none of them a dev-mesh load case; "
             "hashes in `benchmarks/simp_unseen/MANIFEST.json`.",
             "- Each case: `python -m polycube_wb reconstruct MESH -o OUT.step --report "
             "OUT.json --labels OUT.ply --base-mesh OUT.obj` (+ `--parts auto`), default "
             "parameters; STEP judged by `../shared/tools/evaluate.py`, labels by "
             "`../shared/tools/labelcheck.py`. Distances are symmetric, as fractions of the "
             "target's bounding-box diagonal; outside = volume of result minus target over "
             "target volume.", "",
             "## Designs", "",
             "| design | load case | grid | volfrac | triangles | genus | dropped comps |",
             "|---|---|---|---|---|---|---|"]
    for name, m in manifest.items():
        lines.append(f"| {name} | {m['what']} | {'x'.join(map(str, m['grid']))} | "
                     f"{m['volfrac']} | {m['triangles']} | {m['genus']} | "
                     f"{m['dropped_components']} |")
    lines += ["", "## Summary", ""] + _summary(rows) + ["", "## Results", "",
              "| design | mode | parts | exit | reached | failed at | labeling valid (ours / labelcheck) "
              "| base route | base faces | quads | inverted | fit crossings | STEP valid "
              "| mean dist | max dist | outside | seconds |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        base = row.get("base_mesh") or {}
        lc = row.get("labelcheck") or {}
        lines.append("| " + " | ".join(str(c) for c in [
            row["design"], row["mode"], _fmt(row.get("parts")), _fmt(row.get("exit_code")), _fmt(row.get("reached")),
            _fmt(row.get("failed_stage")),
            f"{_fmt(row.get('labeling_valid'))} / {_fmt(lc.get('valid'))}",
            _fmt(base.get("method")), _fmt(base.get("faces")), _fmt(base.get("quads")),
            _fmt(base.get("inverted_faces")), _fmt(row.get("fit_self_intersections"))]
            + _evaluation_cells(row) + [_fmt(row.get("seconds"))]) + " |")
    lines += ["", "## Seconds per stage", "",
              "| design | mode | " + " | ".join(STAGES) + " |",
              "|---|---|" + "---|" * len(STAGES)]
    for row in rows:
        sec = row.get("stage_seconds") or {}
        lines.append(f"| {row['design']} | {row['mode']} | "
                     + " | ".join(_fmt(sec.get(s), 3) for s in STAGES) + " |")
    lines += ["", "## Failed runs (exit code not 0; messages as printed)", ""]
    if all(row.get("exit_code") == 0 and not row.get("evaluation_error") for row in rows):
        lines.append("None: every run wrote its STEP file and was evaluated.")
    for row in rows:
        if row.get("exit_code") == 0 and not row.get("evaluation_error"):
            continue
        what = row.get("failed_message") or row.get("stderr") or ""
        lines.append(f"- **{row['design']} ({row['mode']})**, stage "
                     f"{_fmt(row.get('failed_stage'))} ({_fmt(row.get('failed_status'))}), exit "
                     f"{_fmt(row.get('exit_code'))}: {what.strip()}")
        if row.get("evaluation_error"):
            lines.append(f"  - evaluate.py: {row['evaluation_error']}")
    lines += ["", "## Stage messages (warnings and fallbacks of the runs)", ""]
    for row in rows:
        for stage, message in (row.get("stage_messages") or {}).items():
            lines.append(f"- {row['design']} ({row['mode']}), {stage}: {message.strip()}")
    lines += ["", "## Pictures (target; base cage over the target where one was built)", ""]
    shown = set()
    for row in rows:
        for image in row["images"]:
            if image not in shown:
                shown.add(image)
                lines.append(f"![{row['design']} {row['mode']}]({image})")
    return "\n".join(lines) + "\n"


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=[])
    parser.add_argument("--modes", nargs="*", default=list(MODES), choices=MODES)
    parser.add_argument("--timeout", type=float, default=900.0)
    parser.add_argument("--large", action="store_true",
                        help="run the Loop-subdivided large designs (LARGE_DESIGNS) too, or "
                             "with --only NAME_loop2 only them")
    parser.add_argument("--markdown-only", action="store_true",
                        help="rewrite UNSEEN_RESULTS.md from unseen_results.json, run nothing")
    args = parser.parse_args(argv)
    stored = _load(RESULTS_JSON) or {}
    previous = {(r["design"], r["mode"]): r for r in stored.get("rows", [])}
    if args.markdown_only:
        _write(previous, stored["meta"])
        return 0
    small = [n for n in args.only if not n.endswith(LARGE_SUFFIX)]
    large = [n for n in args.only if n.endswith(LARGE_SUFFIX)]
    manifest = ensure_designs(small) if small or not large else {}
    if args.large or large:
        manifest.update(ensure_large(large))
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                     capture_output=True, text=True).stdout.strip(),
            "load": round(os.getloadavg()[0], 1), "timeout": args.timeout}
    for name, entry in manifest.items():
        mesh = os.path.join(DESIGNS, entry["file"])  # an absolute file stays as it is
        for mode in args.modes:
            row = dict(run_case(name, mesh, mode, args.timeout), commit=meta["commit"])
            # re-read: another run of this script may have added rows meanwhile
            previous = {(r["design"], r["mode"]): r
                        for r in (_load(RESULTS_JSON) or {}).get("rows", [])}
            previous[(name, mode)] = row
            print(f"{name} {mode}: exit {row.get('exit_code')}, reached {row.get('reached')}, "
                  f"{row['seconds']} s", flush=True)
            _write(previous, meta)
    return 0


def _write(rows_by_key, meta):
    manifest = _load(MANIFEST) or {}
    if any(design.endswith(LARGE_SUFFIX) for design, _ in rows_by_key):
        manifest.update(ensure_large([]))
    rows = [rows_by_key[k] for k in sorted(rows_by_key, key=lambda k: (k[0], MODES.index(k[1])))]
    for path, text in ((RESULTS_JSON, json.dumps({"meta": meta, "rows": rows}, indent=1)),
                       (RESULTS_MD, markdown(rows, {n: manifest[n] for n in sorted(manifest)},
                                             meta))):
        tmp = path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
