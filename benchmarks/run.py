# SPDX-License-Identifier: LGPL-2.1-or-later
"""Run the benchmarks and write ``RESULTS.md``, ``results.json`` and ``images/``.

Usage::

    .venv/bin/python benchmarks/run.py [--meshes DIR ...] [--only NAME ...] [--quick]
                                       [--out DIR] [--timeout SECONDS] [--no-images]

A full run (no ``--only``, no ``--quick``) writes into ``benchmarks/``; partial runs write into
``out/benchmarks/`` unless ``--out`` says otherwise, so the committed figures always come from a
full run. Every case runs in its own process (``benchmarks/cases.py``) with a timeout; a case that
fails, crashes or times out is recorded and the run goes on.
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

from report import markdown, summarise  # noqa: E402

MESH_EXTENSIONS = (".stl", ".obj", ".ply", ".off")
DEFAULT_MESH_DIR = os.path.join(REPO, "..", "shared", "data", "meshes")
CAGES = ("cube", "torus", "mixed_prism", "genus3_block")
QUICK_MESHES = ("to_levelset_cantilever_tiny", "idler_riser", "polycube_bone")
QUICK_CAGES = ("cube", "torus")
LABELING_SPEED_SOURCE = "to_simp_mbb"
RECONSTRUCTION_TIMEOUT = 300.0


def machine_info():
    """Machine and library versions for the report header (dict of str/int)."""
    import manifold3d
    import matplotlib
    import numpy
    import scipy
    import trimesh

    info = {"date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "cpu_count": os.cpu_count(), "cpu_model": _cpu_model(),
            "memory_gb": _memory_gb(), "platform": platform.platform(),
            "python": platform.python_version(), "numpy": numpy.__version__,
            "scipy": scipy.__version__, "trimesh": trimesh.__version__,
            "manifold3d": getattr(manifold3d, "__version__", "installed"),
            "matplotlib": matplotlib.__version__, "freecad": _freecad_version(),
            "commit": _commit(), "load_start": round(os.getloadavg()[0], 2)}
    return info


def _cpu_model():
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _memory_gb():
    try:
        return round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError):
        return "?"


def _freecad_version():
    code = "import FreeCAD; print('.'.join(FreeCAD.Version()[:3]))"
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return "not importable"
    return out.stdout.strip().splitlines()[-1] if out.returncode == 0 and out.stdout.strip() \
        else "not importable"


def _commit():
    try:
        out = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=30)
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    if out.returncode != 0:
        return "unknown"
    return out.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")


def find_meshes(folders):
    """``{name: path}`` of the mesh files in ``folders`` (sorted; name = file stem)."""
    meshes = {}
    for folder in folders:
        if not os.path.isdir(folder):
            raise SystemExit(f"error: mesh folder {folder} does not exist")
        for file in sorted(os.listdir(folder)):
            if not file.lower().endswith(MESH_EXTENSIONS):
                continue
            stem = os.path.splitext(file)[0]
            name = stem if stem not in meshes else f"{os.path.basename(folder)}/{stem}"
            meshes[name] = os.path.abspath(os.path.join(folder, file))
    return meshes


def plan(args, meshes):
    """List of ``(section, key, sub, spec)`` cases to run."""
    selected = set(args.only or ())

    def wanted(name):
        return not selected or name in selected

    if args.quick:
        meshes = {k: v for k, v in meshes.items() if k in QUICK_MESHES}
    images = None if args.no_images else os.path.join(args.out, "images")
    cases = []
    for name, path in meshes.items():
        if not wanted(name):
            continue
        for mode in ("single", "auto"):
            cases.append(("meshes", name, mode, {"kind": "mesh", "path": path, "mode": mode,
                                                  "stem": name.replace("/", "_"),
                                                  "images": images}))
    for name, path in meshes.items():
        if wanted(name):
            cases.append(("reconstruction", name, None, {"kind": "reconstruction", "path": path,
                                                         "timeout": RECONSTRUCTION_TIMEOUT}))
    for cage in (QUICK_CAGES if args.quick else CAGES):
        if wanted(cage):
            cases.append(("cages", cage, None, {"kind": "cage", "cage": cage}))
    speed = [("subdivision_10k", {"kind": "subdivision_speed", "n": 41, "levels": 3,
                                  "repeats": 3})]
    if not args.quick:
        speed += [("step_2k", {"kind": "step_speed", "cage": "grid_sphere_18", "measure": True}),
                  ("step_2k_no_measure", {"kind": "step_speed", "cage": "grid_sphere_18",
                                          "measure": False})]
        source = meshes.get(LABELING_SPEED_SOURCE)
        if source:
            speed.append(("labeling_100k", {"kind": "labeling_speed", "path": source,
                                            "triangles": 100_000}))
    for key, spec in speed:
        if wanted(key):
            cases.append(("speed", key, None, spec))
    return cases


def run_case(spec, timeout, tmp):
    """Run one case in a child process; returns its result dict (never raises)."""
    spec_path = os.path.join(tmp, "spec.json")
    result_path = os.path.join(tmp, "result.json")
    if os.path.exists(result_path):
        os.remove(result_path)
    with open(spec_path, "w", encoding="utf-8") as fh:
        json.dump(spec, fh)
    started = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, os.path.join(HERE, "cases.py"), spec_path,
                               result_path], capture_output=True, text=True, timeout=timeout,
                              cwd=REPO)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "error": f"timed out after {timeout} s",
                "process_wall_seconds": round(time.perf_counter() - started, 1)}
    wall = round(time.perf_counter() - started, 3)
    if proc.returncode != 0 or not os.path.exists(result_path):
        lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
        return {"status": "crashed", "returncode": proc.returncode,
                "error": lines[-1] if lines else f"exit code {proc.returncode}",
                "process_wall_seconds": wall}
    with open(result_path, encoding="utf-8") as fh:
        result = json.load(fh)
    result["process_wall_seconds"] = wall
    return result


def _status_line(section, key, sub, result):
    what = f"{section}/{key}" + (f"/{sub}" if sub else "")
    note = result.get("error", "")
    lab = result.get("labels_file")
    if lab is not None:
        note = f"labels file valid={lab['valid']} charts={lab['charts']}"
    return f"{what:55s} {result.get('status', '?'):8s} {result['process_wall_seconds']:7.1f} s  {note}"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", nargs="+", metavar="DIR",
                        help="mesh folders (default ../shared/data/meshes beside the repository)")
    parser.add_argument("--only", nargs="+", metavar="NAME",
                        help="run only these cases (mesh file stems, cage names, speed keys)")
    parser.add_argument("--quick", action="store_true",
                        help=f"a few small cases: meshes {', '.join(QUICK_MESHES)}, cages "
                             f"{', '.join(QUICK_CAGES)}, the subdivision speed case")
    parser.add_argument("--out", metavar="DIR",
                        help="output folder (default benchmarks/ for a full run, else out/benchmarks/)")
    parser.add_argument("--timeout", type=float, default=900.0,
                        help="seconds per case before it is stopped and recorded (default 900)")
    parser.add_argument("--no-images", action="store_true", help="skip the PNG renderings")
    parser.add_argument("--render", action="store_true",
                        help="only write RESULTS.md again from the results.json in --out (the "
                             "topic index and the current pipeline table follow their files)")
    args = parser.parse_args(argv)
    if args.render:
        out = os.path.abspath(args.out or HERE)
        with open(os.path.join(out, "results.json"), encoding="utf-8") as fh:
            results = json.load(fh)
        with open(os.path.join(out, "RESULTS.md"), "w", encoding="utf-8") as fh:
            fh.write(markdown(results))
        return 0
    full = not args.quick and not args.only
    args.out = os.path.abspath(args.out or (HERE if full else os.path.join(REPO, "out", "benchmarks")))
    folders = [os.path.abspath(d) for d in (args.meshes or [DEFAULT_MESH_DIR])]
    meshes = find_meshes(folders)
    os.makedirs(args.out, exist_ok=True)
    images = os.path.join(args.out, "images")
    if full and not args.no_images and os.path.isdir(images):
        for file in os.listdir(images):
            if file.endswith(".png"):
                os.remove(os.path.join(images, file))
    started = time.perf_counter()
    results = {"machine": machine_info(), "quick": bool(args.quick), "only": args.only,
               "mesh_dirs": [os.path.relpath(d, REPO) for d in folders],
               "timeout": args.timeout, "meshes": {}, "reconstruction": {}, "cages": {},
               "speed": {}}
    cases = plan(args, meshes)
    print(f"{len(cases)} cases; output in {args.out}", flush=True)
    with tempfile.TemporaryDirectory(prefix="polycube-bench-") as tmp:
        for section, key, sub, spec in cases:
            single = results[section].get(key, {}).get("single") if sub == "auto" else None
            if single is not None and single.get("status") == "rejected":
                result = {**single, "process_wall_seconds": 0.0}
            else:
                result = run_case(spec, min(args.timeout, spec.get("timeout", args.timeout)), tmp)
            if sub is None:
                results[section][key] = result
            else:
                results[section].setdefault(key, {"file": spec["path"]})[sub] = result
            print(_status_line(section, key, sub, result), flush=True)
    results["total_seconds"] = round(time.perf_counter() - started, 1)
    results["machine"]["load_end"] = round(os.getloadavg()[0], 2)
    results["summary"] = summarise(results)
    with open(os.path.join(args.out, "results.json"), "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1)
        fh.write("\n")
    with open(os.path.join(args.out, "RESULTS.md"), "w", encoding="utf-8") as fh:
        fh.write(markdown(results))
    print(f"done in {results['total_seconds']:.0f} s: {os.path.join(args.out, 'RESULTS.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
