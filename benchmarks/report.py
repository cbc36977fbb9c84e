# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summary figures and the Markdown page (``RESULTS.md``) of a benchmark run."""
import json

TARGETS = {
    "step_2k": ("~2,000-face base mesh (grid_sphere(18)) to a valid STEP file, default settings "
                "(with measurement)", 10.0),
    "subdivision_10k": ("Catmull-Clark matrices for a ~10,000-face base mesh (grid_sphere(41)) "
                        "to level 3, build_hierarchy + composite, median of 3", 2.0),
    "labeling_100k": ("labeling stage (HBECVT + repair + validity) of a ~100,000-triangle mesh, "
                      "single part", 5.0),
}
TALLY_KEYS = ("invalid_charts", "invalid_boundaries", "invalid_corners", "turning_points")


def _fmt(value, digits=3):
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "**no**"
    if isinstance(value, float):
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
            return f"{value:.2e}"
        return f"{value:.{digits}g}" if abs(value) < 1 else f"{value:.{digits}f}".rstrip("0").rstrip(".")
    return str(value)


def _tally(counts):
    """``charts/boundaries/corners/turning points`` invalid counts as one cell."""
    if not counts:
        return "–"
    return "/".join(str(counts.get(k, "?")) for k in TALLY_KEYS)


def _row(cells):
    return "| " + " | ".join(_fmt(c) if not isinstance(c, str) else c for c in cells) + " |"


def _table(header, rows):
    lines = [_row(header), "|" + "---|" * len(header)]
    lines += [_row(r) for r in rows]
    return lines


def _ok(case):
    return case is not None and case.get("status") == "ok"


def summarise(results):
    """Headline counts and target verdicts; returns a dict stored as ``results['summary']``."""
    meshes = results["meshes"]
    accepted = {k: v for k, v in meshes.items() if _ok(v.get("single")) and "labeling" in v["single"]}
    summary = {"meshes": len(meshes), "accepted": len(accepted),
               "rejected": sorted(k for k, v in meshes.items()
                                  if (v.get("single") or {}).get("status") == "rejected")}
    for mode in ("single", "auto"):
        ran = {k: v[mode] for k, v in meshes.items()
               if _ok(v.get(mode)) and "labeling" in v[mode]}
        summary[mode] = {
            "labeled": len(ran),
            "valid_labels_file": sum(bool(c["labels_file"]["valid"]) for c in ran.values()),
            "valid_pipeline": sum(bool(c["labeling"]["valid"]) for c in ran.values()),
            "valid_before_repair": sum(bool(c["before_repair"]["valid"]) for c in ran.values()),
            "valid_nearest_same_frames": sum(bool(c["nearest_same_frames"]["valid"])
                                             for c in ran.values()),
            "invalid_meshes": sorted(k for k, c in ran.items() if not c["labels_file"]["valid"]),
            "failed": sorted(k for k, v in meshes.items()
                             if v.get(mode) is not None and not _ok(v[mode])
                             and v[mode].get("status") != "rejected"),
            "max_angle_excess_deg": max(
                (c["labeling"]["mean_angle_deg"] - c["labeling"]["nearest_direction_mean_angle_deg"]
                 for c in ran.values()), default=None),
        }
    baseline = [v["single"]["nearest_identity"]["valid"] for v in accepted.values()
                if "nearest_identity" in v["single"]]
    summary["nearest_identity_valid"] = sum(bool(b) for b in baseline)
    summary["nearest_identity_labeled"] = len(baseline)
    speed = results.get("speed", {})
    verdicts = {}
    figures = {"step_2k": ("api_wall_seconds", speed.get("step_2k")),
               "subdivision_10k": ("seconds_median", speed.get("subdivision_10k")),
               "labeling_100k": ("labeling_seconds", speed.get("labeling_100k"))}
    for key, (field, case) in figures.items():
        if case is None:
            continue
        limit = TARGETS[key][1]
        seconds = case.get(field) if _ok(case) else None
        extra_ok = True
        if key == "step_2k" and _ok(case):
            extra_ok = bool(case["brep"]["valid"] and case["brep"]["closed"]
                            and case["round_trip"]["ok"])
        verdicts[key] = {"seconds": seconds, "limit": limit,
                         "pass": bool(seconds is not None and seconds <= limit and extra_ok)}
    summary["targets"] = verdicts
    return summary


TOPIC_RESULTS = (
    ("Base mesh: quantized layouts and the paired-decimation fallback on every dev mesh, cages "
     "over targets, whole pipeline to STEP",
     "BASEMESH_RESULTS.md", "benchmarks/basemesh_bench.py"),
    ("Base-mesh stage speed and determinism: CPU seconds, MILP counts, the same cage twice",
     "BASEMESH_SPEED_RESULTS.md", "benchmarks/basemesh_speed_bench.py"),
    ("Labeling: validity by the independent check, frames chosen, angles, turning points",
     "LABELING_RESULTS.md", "benchmarks/labeling_bench.py"),
    ("Fit: compiled queries, modes, the QuadriFlow peer", "FIT_RESULTS.md",
     "benchmarks/fit_bench.py"),
    ("Layout peer: extraordinary vertices of our base mesh against QuadriFlow's at the same "
     "face count, genus kept", "LAYOUT_PEER_RESULTS.md", "benchmarks/layout_peer_bench.py"),
    ("Export: shared-edge solids, mixed cages, STEP speed", "EXPORT_RESULTS.md",
     "benchmarks/export_bench.py"),
    ("Workbench: recompute, cancel, reopen", "workbench_RESULTS.md",
     "benchmarks/workbench_bench.py"),
    ("Batch: all dev meshes with --jobs 1 and --jobs 2", "BATCH_RESULTS.md",
     "benchmarks/batch_bench.py"),
    ("Batch memory: the summary's peak against GNU time, the per-mesh cap", "MEMORY_RESULTS.md",
     "benchmarks/memory_bench.py"),
    ("Scale: the same designs from 15 thousand to 2.4 million triangles, time and memory per "
     "stage", "SCALE_RESULTS.md", "benchmarks/scale_bench.py"),
    ("Cancel: Ctrl-C in every stage, time to stop and what is left", "CANCEL_RESULTS.md",
     "benchmarks/cancel_bench.py"),
    ("Structure: typed stage results against the previous runner, same reports",
     "STRUCTURE_RESULTS.md", "benchmarks/structure_bench.py"),
    ("Unseen SIMP results: new load cases generated here, judged by the independent checks",
     "UNSEEN_RESULTS.md", "benchmarks/unseen_bench.py"),
    ("SIMP designs of genus 0 to 60 with default parameters: valid closed STEP solids",
     "SIMP_GENUS_RESULTS.md", "benchmarks/simp_genus_bench.py"),
    ("Topology-optimisation results of others: seconds per stage, cages, crossings, outside",
     "TO_RESULTS.md", "benchmarks/to_results_bench.py"),
    ("Crossings: self-crossing limit surfaces of the cages and the fits", "CROSSINGS_RESULTS.md",
     "benchmarks/crossings_bench.py"),
    ("Thickness-aware splits before pairing: limit-surface crossings", "THIN_SPLIT_RESULTS.md",
     "benchmarks/thin_split_bench.py"),
    ("Feature networks: machined lines or a voxel staircase", "STAIRCASE_RESULTS.md",
     "benchmarks/staircase_bench.py"),
    ("Tolerance-driven refinement: the deviation asked for against the one measured",
     "TOLERANCE_RESULTS.md", "benchmarks/tolerance_bench.py"),
    ("Stability of the fit under rounding: 8 perturbed copies of every cage",
     "STABILITY_RESULTS.md", "benchmarks/stability_bench.py"),
    ("Exact (graded) against G1 export: size, read time, normal jumps, distance to the limit",
     "G1_EXPORT_RESULTS.md", "benchmarks/g1_export_bench.py"),
    ("GUI responsiveness on a large mesh: event-loop gaps, Esc", "GUI_RESULTS.md",
     "benchmarks/gui_bench.py"),
)
"""Topic result files beside RESULTS.md: (title, file name, script)."""


def _current_pipeline_table():
    """Lines of a compact table of ``basemesh_results.json`` (SIMP results first), if present."""
    import os

    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "basemesh_results.json")
    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as handle:
        data = json.load(handle)
    lines = [f"### Current pipeline on every dev mesh (from `basemesh_results.json`, "
             f"{data['meta']['date']}, commit {data['meta']['commit']})", "",
             "Distances are symmetric, fractions of the bounding-box diagonal, by the independent "
             "`../shared/tools/evaluate.py` on the STEP file (run for the meshes listed there).", "",
             "| mesh | parts | base mesh | route | faces | genus (target) | inverted faces | "
             "STEP valid | mean dist % | max dist % |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in data["rows"]:
        base = row.get("base_mesh") or {}
        metrics = (row.get("solid") or {}).get("evaluation", {})
        symmetric = metrics.get("distance", {}).get("symmetric", {})
        valid = metrics.get("brep", {}).get("is_valid")
        cells = [f"`{row['mesh']}`", row["mode"],
                 row.get("stages", {}).get("basemesh", row.get("error", "?")),
                 base.get("method") or ("polycube" if base else "–"),
                 str(base.get("faces", "–")),
                 f"{base['genus']} ({row['input_genus']})" if base else "–",
                 str(row.get("inverted_faces", "–")),
                 "–" if valid is None else ("yes" if valid else "no"),
                 _pct(symmetric.get("mean_frac")), _pct(symmetric.get("max_frac"))]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _pct(value):
    return "–" if value is None else f"{100.0 * value:.2f}"


def _header(results):
    m = results["machine"]
    s = results["summary"]
    lines = [
        "# Benchmark results",
        "",
        "Written by `benchmarks/run.py`, the one place these figures come from; do not edit by hand.",
        "",
        "Per-topic benchmarks, each written by its own script (newer than this run where their",
        "date says so; they supersede the matching sections below):",
        "",
    ] + [f"- [{title}]({name}) (`{script}`)" for title, name, script in TOPIC_RESULTS] + [
        "",
    ] + _current_pipeline_table() + [
        f"- Date: {m['date']}; run took {results['total_seconds']:.0f} s "
        f"({'quick mode' if results['quick'] else 'full run'}).",
        f"- Machine: {m['cpu_model']}, {m['cpu_count']} CPUs, {m['memory_gb']} GiB RAM, {m['platform']}.",
        f"- Software: Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"trimesh {m['trimesh']}, manifold3d {m['manifold3d']}, matplotlib {m['matplotlib']}, "
        f"FreeCAD {m['freecad']}.",
        f"- Commit: {m['commit']}. Load average (1 min) at start / end: {m['load_start']} / "
        f"{m.get('load_end', '?')} (other processes on the machine slow the timings down).",
        f"- Meshes: {', '.join('`' + d + '`' for d in results['mesh_dirs'])}; "
        f"each case ran in its own process (timeout {results['timeout']} s). "
        "Peak memory is that process's `ru_maxrss`, so it includes the interpreter and the "
        "imported libraries (about 100 MiB for numpy, scipy and trimesh, about 200 MiB with FreeCAD).",
        "",
        "Reproduce (from the repository root, with `../shared/data/meshes` beside the clone):",
        "",
        "```",
        "make setup                                  # once: .venv with FreeCAD importable",
        ".venv/bin/python benchmarks/run.py          # full run, rewrites benchmarks/RESULTS.md,",
        "                                            # results.json and images/",
        ".venv/bin/python benchmarks/run.py --quick  # a few small cases (< 60 s), into out/benchmarks/",
        ".venv/bin/python benchmarks/run.py --only fandisk cube --meshes DIR  # selected cases",
        "```",
        "",
        "## Headlines",
        "",
    ]
    for mode in ("single", "auto"):
        t = s[mode]
        if not t["labeled"]:
            continue
        bad = ", ".join(f"`{n}`" for n in t["invalid_meshes"]) or "none"
        fail = (f"; failed: {', '.join(f'`{n}`' for n in t['failed'])}" if t["failed"] else "")
        lines.append(f"- Labeling, {mode} part{'s' if mode == 'auto' else ''}: "
                     f"**{t['valid_labels_file']} of {t['labeled']}** meshes end fully valid "
                     f"(judged on the `--labels` PLY file; pipeline's own check: "
                     f"{t['valid_pipeline']}; HBECVT before repair: {t['valid_before_repair']}). "
                     f"Still invalid: {bad}{fail}. Largest mean-angle excess over the "
                     f"nearest-direction labeling: {_fmt(t['max_angle_excess_deg'])}°.")
    if s["nearest_identity_labeled"]:
        lines.append(f"- Reference: nearest of six fixed directions (identity frames, one part, no "
                     f"smoothing) is valid on {s['nearest_identity_valid']} of "
                     f"{s['nearest_identity_labeled']} meshes.")
    if s["rejected"]:
        lines.append(f"- Rejected at intake: {', '.join(f'`{n}`' for n in s['rejected'])}.")
    for key, v in s["targets"].items():
        label, limit = TARGETS[key]
        verdict = "PASS" if v["pass"] else "FAIL"
        lines.append(f"- Target, {label}: {_fmt(v['seconds'])} s (limit {limit:g} s): **{verdict}**.")
    lines.append("")
    return lines


def _intake_section(results):
    lines = ["## 1. Intake", "",
             "Reading, vertex merging and validation (watertight, manifold, orientation, "
             "degenerate and duplicate faces, self-intersections). Time is the intake stage; peak "
             "memory is the process peak when intake finished.", ""]
    rows, rejected = [], []
    for name, mesh in results["meshes"].items():
        case = mesh.get("single") or {}
        inp = case.get("input")
        if inp is None:
            rejected.append([f"`{name}`", case.get("status", "?"), case.get("error", "")])
            continue
        warnings = "; ".join(inp.get("warnings") or []) or "–"
        rows.append([f"`{name}`", inp["triangles"], inp["vertices"], inp["genus"],
                     inp["components"], inp["bbox_diagonal"], inp.get("merged_vertices"),
                     warnings, case["stages"]["intake"]["seconds"],
                     case["peak_memory_mb"]["intake"]])
    lines += _table(["mesh", "triangles", "vertices", "genus", "components", "bbox diagonal",
                     "merged vertices", "warnings", "time s", "peak MiB"], rows)
    if rejected:
        lines += ["", "Meshes that did not pass intake (the error line):", ""]
        lines += _table(["mesh", "status", "error"], rejected)
    lines.append("")
    return lines


def _parts_section(results):
    lines = ["## 2. Parts and frames", "",
             "`parts='auto'`: curve-skeleton segmentation; `single`: the whole mesh is one part. "
             "Interfaces are the edge loops between parts.", ""]
    rows = []
    for name, mesh in results["meshes"].items():
        auto, single = mesh.get("auto") or {}, mesh.get("single") or {}
        if "frames" not in auto and "frames" not in single:
            continue
        pa = auto.get("parts", {})
        stages_a, stages_s = auto.get("stages", {}), single.get("stages", {})
        rows.append([f"`{name}`", pa.get("parts"), (auto.get("frames") or {}).get("interfaces"),
                     pa.get("junctions"), pa.get("pieces"),
                     (stages_a.get("parts") or {}).get("seconds"),
                     (stages_a.get("frames") or {}).get("seconds"),
                     (auto.get("peak_memory_mb") or {}).get("parts_frames"),
                     (stages_s.get("frames") or {}).get("seconds"),
                     auto.get("error", "") if not _ok(auto) else ""])
    lines += _table(["mesh", "auto parts", "interfaces", "skeleton junctions", "skeleton pieces",
                     "auto parts s", "auto frames s", "peak MiB (auto)", "single frames s",
                     "error"], rows)
    lines.append("")
    return lines


def _labeling_rows(results, mode):
    rows = []
    for name, mesh in results["meshes"].items():
        case = mesh.get(mode)
        if case is None or case.get("status") == "rejected":
            continue
        if "labeling" not in case:
            rows.append([f"`{name}`"] + ["–"] * 12 + [case.get("error", case.get("status"))])
            continue
        lab, lf = case["labeling"], case["labels_file"]
        verdict = "yes" if lf["valid"] else f"**no** ({_tally(lf)})"
        rows.append([f"`{name}`", lab["parts"], lab["charts"], lab["corners"],
                     _tally(case["before_repair"]), _tally(lab), verdict,
                     lab["mean_angle_deg"], lab["nearest_direction_mean_angle_deg"],
                     lab["mean_angle_deg"] - lab["nearest_direction_mean_angle_deg"],
                     case["before_repair"]["hbecvt_seconds"], case["stages"]["labeling"]["seconds"],
                     case["pipeline_seconds"], case["peak_memory_mb"]["labeling"]])
    return rows


def _example(item):
    """One validity example as ``key=value`` text (coordinates rounded)."""
    parts = []
    for key, value in item.items():
        if key == "point":
            value = "(" + ", ".join(f"{x:.4g}" for x in value) + ")"
        elif isinstance(value, list):
            value = ",".join(str(v) for v in value)
        parts.append(f"{key}={value}")
    return " ".join(parts)


def _why(results, mode):
    """Bullet list of the items still invalid in the labels file, one example each."""
    lines = []
    for name, mesh in results["meshes"].items():
        case = mesh.get(mode) or {}
        lf = case.get("labels_file")
        if not lf or lf["valid"]:
            continue
        items = [f"{lf[k]} {k.replace('_', ' ')} (e.g. {_example(ex)})"
                 for k, ex in lf.get("examples", {}).items()]
        lines.append(f"- `{name}`: " + "; ".join(items))
    if lines:
        lines = ["Still invalid in the labels file (count, first example):", ""] + lines + [""]
    return lines


def _labeling_section(results):
    s = results["summary"]
    lines = ["## 3. Labeling", "",
             "Invalid items are written `charts/boundaries/corners/turning points`. *Before repair*: "
             "HBECVT alone (`hbecvt_labeling` + `check_validity`, same frames). *After repair*: the "
             "pipeline's labeling stage. *Labels file valid*: validity recomputed from the written "
             "`--labels` PLY (`validity_from_labels_file`), the independent judge; turning points are "
             "counted but do not make a labeling invalid. Mean angle: between face normal and label "
             "direction, against the nearest-direction labeling in the same frames (Δ = excess; "
             "the goal is at most 5°). HBECVT s: the energy minimisation alone; labeling s: the "
             "whole stage (HBECVT, repair, validity, figures); pipeline s: intake to labeling; peak "
             "MiB: process peak at the end of the pipeline.", ""]
    header = ["mesh", "parts", "charts", "corners", "invalid before repair", "invalid after repair",
              "labels file valid", "mean angle °", "nearest angle °", "Δ °", "HBECVT s",
              "labeling s", "pipeline s", "peak MiB"]
    for mode in ("single", "auto"):
        t = s[mode]
        lines += [f"### {'Single part' if mode == 'single' else 'Automatic parts'} "
                  f"({t['valid_labels_file']} of {t['labeled']} valid)", ""]
        lines += _table(header, _labeling_rows(results, mode))
        lines.append("")
        lines += _why(results, mode)
    lines += ["### Nearest-direction baselines (no smoothing, no repair)", "",
              f"Identity frames, one part (the reference): valid on "
              f"{s['nearest_identity_valid']} of {s['nearest_identity_labeled']}. "
              "Same frames as the pipeline (PCA, blended), per part mode:", ""]
    rows = []
    for name, mesh in results["meshes"].items():
        single, auto = mesh.get("single") or {}, mesh.get("auto") or {}
        if "nearest_identity" not in single:
            continue
        ni = single["nearest_identity"]
        rows.append([f"`{name}`", ni["valid"], ni["charts"], _tally(ni),
                     single["nearest_same_frames"]["valid"], _tally(single["nearest_same_frames"]),
                     (auto.get("nearest_same_frames") or {}).get("valid"),
                     _tally(auto.get("nearest_same_frames"))])
    lines += _table(["mesh", "identity valid", "identity charts", "identity invalid",
                     "PCA frames valid (single)", "invalid (single)", "PCA frames valid (auto)",
                     "invalid (auto)"], rows)
    lines.append("")
    return lines


def _images_section(results):
    lines = ["## 6. Renderings", "",
             "Faces coloured by label (colours of `labels_file.LABEL_COLOURS`: +X red, −X orange, "
             "+Y green, −Y lime, +Z blue, −Z purple, in each face's own frame) and by automatic "
             "part; two opposite views, headlight shading. Files in `images/`.", ""]
    for name, mesh in results["meshes"].items():
        images = []
        for mode in ("single", "auto"):
            case = mesh.get(mode) or {}
            for key in ("labels", "parts"):
                file = (case.get("images") or {}).get(key)
                if file:
                    images.append(f"![{name} {key} {mode}](images/{file})")
        if images:
            lines += [f"### `{name}`", ""] + images + [""]
    return lines


def _cage_rows(cages):
    rows = []
    for name, case in cages.items():
        if not _ok(case):
            rows.append([f"`{name}`"] + ["–"] * 15 + [case.get("error", case.get("status"))])
            continue
        b, p, rt, st = case["base_mesh"], case["patches"], case["round_trip"], case["stages"]
        rows.append([f"`{name}`", b["faces"], f"{b['quads']}/{b['triangles']}/{b['other']}",
                     f"{b['extraordinary_vertices']} / {p['n_extraordinary_vertices']}",
                     b["genus"], p["n_patches"],
                     p.get("max_ev_error_rel"), p.get("normal_jump_max_deg"),
                     p.get("normal_jump_p95_deg"), case["brep"]["valid"], case["brep"]["closed"],
                     case["brep"]["faces"], case["brep"]["volume_error_rel"],
                     rt["volume_rel_error"],
                     " / ".join(_fmt(st[k]["seconds"]) for k in ("patches", "solid", "step")
                                if k in st),
                     case["api_wall_seconds"], "" if rt["ok"] else "STEP round trip failed"])
    return rows


def _export_section(results):
    lines = ["## 5. Subdivision and export", "",
             "Sample cages (`core.subdivision.sample_cages`) written as OBJ, then "
             "`polycube_wb.api.subd_to_solid` (default depth, with measurement) to a STEP file, "
             "then `step_round_trip`. EV error: largest distance between the B-spline patches and "
             "the exact limit surface near extraordinary vertices, as a fraction of the bbox "
             "diagonal (target ≤ 1e-4). Normal jump: angle across patch edges (target ≤ 1°). "
             "Volume error: B-rep volume against the limit volume by deep subdivision (target ≤ "
             "1e-3); round trip: volume read back from STEP against the written solid (target ≤ "
             "1e-6). Times: patches / solid / STEP write, and the whole `subd_to_solid` call "
             "(includes measuring and loading FreeCAD's modules).", ""]
    header = ["cage", "faces", "quads/tris/other", "EVs (base / patch mesh)", "genus", "patches",
              "max EV error", "normal jump max °", "normal jump p95 °", "valid", "closed", "B-rep faces",
              "volume error", "STEP round-trip volume error", "patches/solid/STEP s", "total s",
              "note"]
    lines += _table(header, _cage_rows(results.get("cages", {})))
    speed = results.get("speed", {})
    lines += ["", "### Speed targets", ""]
    rows = []
    s2k = speed.get("step_2k")
    targets = results["summary"]["targets"]
    for key, (label, limit) in TARGETS.items():
        case = speed.get(key)
        if case is None:
            continue
        verdict = targets.get(key, {})
        rows.append([label, _fmt(verdict.get("seconds")), f"{limit:g}",
                     "PASS" if verdict.get("pass") else "**FAIL**", _speed_detail(key, case)])
    lines += _table(["target", "measured s", "limit s", "verdict", "details"], rows)
    if s2k is not None and _ok(speed.get("step_2k_no_measure")):
        nm = speed["step_2k_no_measure"]
        times = ", ".join(f"{k} {_fmt(v['seconds'])}" for k, v in nm["stages"].items())
        lines += ["", f"Same 2,000-face cage without measurement (`subd-to-step --no-measure`): "
                      f"{_fmt(nm['api_wall_seconds'])} s, valid {_fmt(nm['brep']['valid'])}; "
                      f"stages s: {times}; peak {nm['peak_memory_mb']} MiB."]
    lines.append("")
    return lines


def _speed_detail(key, case):
    if not _ok(case):
        return case.get("error", case.get("status", ""))
    if key == "step_2k":
        st = case["stages"]
        times = ", ".join(f"{k} {_fmt(v['seconds'])}" for k, v in st.items())
        return (f"{case['base_mesh']['faces']} faces, {case['brep']['faces']} B-rep faces, "
                f"valid {_fmt(case['brep']['valid'])}, closed {_fmt(case['brep']['closed'])}, "
                f"round trip ok {_fmt(case['round_trip']['ok'])}; stages s: {times}; "
                f"peak {case['peak_memory_mb']} MiB")
    if key == "subdivision_10k":
        return (f"{case['base_faces']} faces to level {case['levels']}: {case['fine_faces']} faces, "
                f"composite {case['composite_shape'][0]}x{case['composite_shape'][1]} with "
                f"{case['composite_nnz']} non-zeros; runs s: "
                f"{', '.join(_fmt(t) for t in case['seconds_all'])}; peak {case['peak_memory_mb']} MiB")
    return (f"`{case['source']}` refined by midpoint subdivision to {case['triangles']} triangles; "
            f"valid {_fmt(case['valid'])}, {case['charts']} charts; frames "
            f"{_fmt(case['frames_seconds'])} s; peak {case['peak_memory_mb']} MiB")


def _reconstruction_section(results):
    """Whole pipeline per mesh (one part): stages reached, base mesh, fit, solid, check."""
    cases = results.get("reconstruction", {})
    if not cases:
        return []
    lines = ["## 4. Whole pipeline to STEP (one part)", "",
             "`reconstruct_to_step` with default parameters, then `check` of the STEP against the "
             "target. 'Reached' is the last stage that ran; distances are fractions of the bounding-box "
             "diagonal (samples of the result to the target); volumes are fractions of the target volume.",
             ""]
    header = ["mesh", "reached", "flipped (polycube)", "base faces", "EVs", "fit iterations",
              "B-rep faces", "valid", "mean dist", "max dist", "outside vol", "uncovered vol",
              "total s", "note"]
    rows = []
    for name, case in sorted(cases.items()):
        stages = case.get("stages", {})
        reached = [k for k, v in stages.items() if v.get("status") == "ok"]
        base = case.get("base_mesh", {})
        chk = case.get("check", {})
        dist = chk.get("distances", {})
        rows.append([f"`{name}`", reached[-1] if reached else case.get("status", "?"),
                     case.get("polycube", {}).get("flipped_triangles"), base.get("faces"),
                     base.get("extraordinary_vertices"), case.get("fit", {}).get("iterations"),
                     case.get("brep", {}).get("faces"), chk.get("valid"),
                     dist.get("result_to_target_mean"), dist.get("result_to_target_max"),
                     chk.get("outside_volume_fraction"), chk.get("uncovered_volume_fraction"),
                     case.get("seconds"), (case.get("error") or "")[:90]])
    lines += _table(header, rows) + [""]
    return lines


def markdown(results):
    """The whole RESULTS.md text."""
    lines = _header(results)
    lines += _intake_section(results)
    lines += _parts_section(results)
    lines += _labeling_section(results)
    lines += _reconstruction_section(results)
    lines += _export_section(results)
    lines += _images_section(results)
    return "\n".join(lines).rstrip() + "\n"
