# SPDX-License-Identifier: LGPL-2.1-or-later
"""Command line: ``python -m polycube_wb {reconstruct, batch, subd-to-step, check} ...``.

Exit codes: 0 success; 2 bad input (one line on stderr starting ``error:``);
1 internal failure (message; the traceback
only with ``--debug``); 130 cancelled with Ctrl-C (one line ``cancelled at stage S``;
no output is written, an existing output is unchanged).
"""
import argparse
import json
import os
import sys
import traceback

from core.errors import PolycubeInputError
from core.output_files import committed_count
from core.params import (DEFAULT_EXPORT_FORM, DEFAULT_FACE_FORM, EXPORT_DEPTH, EXPORT_FORMS,
                         FACE_FORMS, MAX_EXPORT_DEPTH,
                         UNIT_TO_MM, ReconstructionParams,
                         parameter_options)
from core.pipeline import STOP_AFTER_CHOICES
from polycube_wb.stage_lines import StageLines

EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT, EXIT_CANCELLED = 0, 1, 2, 130


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one ``error:`` line and exit code 2."""

    def error(self, message):
        sys.stderr.write(f"error: {message} (see '{self.prog} --help')\n")
        sys.exit(EXIT_BAD_INPUT)


def add_pipeline_options(parser, defaults):
    """Add the pipeline parameters shared by ``reconstruct`` and ``batch`` to ``parser``.

    One option per ``ReconstructionParams`` field with a flag (``core.params``: name, type,
    default, help and valid values come from there; a number's help ends with its range);
    the options given as text (``_FROM_TEXT``) are parsed by :func:`pipeline_params`.
    """
    for item, option in parameter_options():
        if option.flag is None:
            continue
        default = getattr(defaults, item.name)
        help_text = option.help if option.low is None or item.name in _FROM_TEXT else \
            f"{option.help} [{_number(option.low)}..{_number(option.high)}]"
        if item.type is bool:
            parser.add_argument(option.flag, dest=item.name, default=default, help=help_text,
                                action="store_false" if default else "store_true")
        elif item.name in _FROM_TEXT:
            parser.add_argument(option.flag, dest=item.name, default=f"{default:g}"
                                if isinstance(default, float) else default,
                                metavar=option.metavar, help=help_text)
        else:
            parser.add_argument(option.flag, dest=item.name, type=item.type, default=default,
                                choices=option.choices, metavar=option.metavar, help=help_text)


def build_parser():
    defaults = ReconstructionParams()
    parser = _Parser(prog="python -m polycube_wb",
                     description="Turn a watertight triangle mesh into a CAD solid made of "
                                 "B-spline patches (polycube labeling + Catmull-Clark).")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    rec = commands.add_parser("reconstruct", help="target mesh -> STEP solid (whole pipeline)",
                              description="Run the pipeline on a target mesh (STL, OBJ, PLY, OFF).")
    rec.add_argument("target", help="target mesh file")
    rec.add_argument("-o", "--output", help="STEP file to write (needs --stop-after solid)")
    rec.add_argument("--base-mesh", help="write the base mesh (polygon OBJ) here")
    rec.add_argument("--report", help="write the JSON report here")
    rec.add_argument("--labels", help="write the per-face parts and polycube labels (binary PLY)")
    rec.add_argument("--stop-after", choices=STOP_AFTER_CHOICES, default="solid",
                     help="run the pipeline up to this stage (default: solid)")
    add_pipeline_options(rec, defaults)
    rec.add_argument("--progress", action="store_true",
                     help="print a line 'STAGE <name>' on stderr as each stage starts")
    rec.add_argument("--debug", action="store_true", help="print tracebacks")

    bat = commands.add_parser("batch", help="many target meshes -> STEP solids + summary",
                              description="Run the reconstruct pipeline on many meshes (files, "
                                          "folders, glob patterns), each in its own process; "
                                          "writes OUT_DIR/summary.csv and summary.html.")
    bat.add_argument("inputs", nargs="+", help="mesh files, folders of meshes or glob patterns")
    bat.add_argument("-o", "--output-dir", required=True, help="folder for every output")
    bat.add_argument("--overrides", metavar="JSON",
                     help="per-mesh parameters: {\"file name or glob\": {\"fit_iterations\": 50}}")
    bat.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                     help="meshes at once on this machine (default: the number of cores)")
    bat.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                     help="time cap per mesh; a mesh over it is stopped and reported")
    bat.add_argument("--memory-limit", type=float, default=None, metavar="MB",
                     help="resident-memory cap per mesh process in MiB, watched from outside "
                          "it; 0 for none (default: 80%% of the RAM shared by the meshes at "
                          "once, at least 512)")
    bat.add_argument("--scheduler", metavar="ADDRESS",
                     help="send the meshes to this Dask distributed scheduler (tcp://host:8786); "
                          "inputs and OUT_DIR must be on a path every worker shares")
    bat.add_argument("--force", action="store_true",
                     help="run meshes again even when their outputs are up to date")
    bat.add_argument("--quiet", action="store_true", help="no progress bar")
    bat.add_argument("--progress-lines", action="store_true",
                     help="progress as lines for another program on stdout: PROGRESS {json} "
                          "and MESH {json} (the GUI's Reconstruct folder reads them)")
    add_pipeline_options(bat, defaults)
    bat.add_argument("--debug", action="store_true", help="print tracebacks")

    sub = commands.add_parser("subd-to-step", help="Catmull-Clark cage (OBJ) -> STEP solid",
                              description="Turn a closed polygon base mesh (SubD cage) into a "
                                          "STEP solid of its Catmull-Clark limit surface.")
    sub.add_argument("base_mesh", help="closed polygon mesh, OBJ")
    sub.add_argument("-o", "--output", required=True, help="STEP file to write")
    sub.add_argument("--report", help="write the JSON report here")
    sub.add_argument("--depth", type=int, default=EXPORT_DEPTH,
                     help=f"patch grading depth at extraordinary vertices, 1..{MAX_EXPORT_DEPTH} "
                          f"(default {EXPORT_DEPTH}; exact export only)")
    sub.add_argument("--export", choices=EXPORT_FORMS, default=DEFAULT_EXPORT_FORM,
                     help="exact: graded patches, the Catmull-Clark limit except in a 2^-depth "
                          "cell at each extraordinary vertex (large STEP); g1: one light "
                          "tangent-continuous patch per quad, close to the limit near "
                          "extraordinary vertices (cages without creases) "
                          f"(default {DEFAULT_EXPORT_FORM})")
    sub.add_argument("--faces", choices=FACE_FORMS, default=DEFAULT_FACE_FORM,
                     help="B-rep faces of the g1 export: quad: one face per quad; chart: one "
                          "multi-span face per rectangular block of quads (fewer faces, faster "
                          f"to read) (default {DEFAULT_FACE_FORM})")
    sub.add_argument("--no-measure", action="store_true",
                     help="skip measuring approximation error and continuity (faster)")
    sub.add_argument("--progress", action="store_true",
                     help="print a line 'STAGE <name>' on stderr as each stage starts")
    sub.add_argument("--debug", action="store_true", help="print tracebacks")

    chk = commands.add_parser("check", help="compare a result STEP with the target mesh",
                              description="Watertightness, containment and distances of a "
                                          "result solid against the target mesh.")
    chk.add_argument("target", help="target mesh file")
    chk.add_argument("result", help="result STEP file")
    chk.add_argument("--report", help="write the JSON result here")
    chk.add_argument("--debug", action="store_true", help="print tracebacks")
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    stages = StageLines(echo=getattr(args, "progress", False), stage=args.command)
    committed_before = committed_count()
    try:
        with stages.ctrl_c_remembered():
            return _COMMANDS[args.command](args, stages)
    except PolycubeInputError as exc:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"error: {exc}\n")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # Ctrl-C: the outputs are written together or not at all
        if args.debug:
            traceback.print_exc()
        if args.command != "batch" and committed_count() > committed_before:
            sys.stderr.write("cancelled after the outputs were written; they are complete\n")
        else:
            sys.stderr.write(_CANCELLED[args.command].format(stage=stages.stage) + "\n")
        return EXIT_CANCELLED
    except Exception as exc:  # internal failure: message, traceback only with --debug
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"failed: {type(exc).__name__}: {exc}\n")
        return EXIT_INTERNAL


_CANCELLED = {
    "reconstruct": "cancelled at stage {stage}; nothing was written",
    "subd-to-step": "cancelled at stage {stage}; nothing was written",
    "check": "cancelled; nothing was written",
    "batch": "cancelled; the meshes that had finished keep their outputs, the others have none, "
             "and the summary was not written",
}
"""The line a Ctrl-C prints, per command (``stage``: the stage the run was in)."""


def _reconstruct(args, stages):
    from polycube_wb.api import reconstruct_to_step

    params = pipeline_params(args)
    if args.stop_after == "solid" and args.output is None:
        raise PolycubeInputError("reconstruct needs -o OUT.step (or --stop-after an earlier stage)")
    report = reconstruct_to_step(args.target, args.output, args.base_mesh, args.report,
                                 args.labels, args.stop_after, progress=stages, **params)
    _print_summary(report)
    return EXIT_OK


def _number(value):
    """``value`` as short text: 0.001, 1000, 1e6, 1e12."""
    return format(value, "g").replace("e+0", "e").replace("e+", "e")


def pipeline_params(args):
    """Keyword arguments of ``reconstruct_to_step`` from the options of :func:`add_pipeline_options`."""
    values = {}
    for item, option in parameter_options():
        if option.flag is not None:
            value = getattr(args, item.name)
            values.update(_FROM_TEXT[item.name](value) if item.name in _FROM_TEXT
                          else {item.name: value})
    return values


def _parts_file(path):
    """``--parts-file`` implies ``--parts file``."""
    return {"parts": "file", "parts_file": path} if path else {"parts_file": ""}


def _tolerance(text):
    """``{"tolerance": fraction}`` or ``{"tolerance_mm": mm}`` from ``--tolerance`` text."""
    text = text.strip()
    unit = next((u for u in sorted(UNIT_TO_MM, key=len, reverse=True) if text.endswith(u)), None)
    number = text[:-len(unit)] if unit else text
    try:
        value = float(number)
    except ValueError:
        raise PolycubeInputError(f"--tolerance must be a number, optionally followed by a unit "
                                 f"({', '.join(UNIT_TO_MM)}), got {text!r}") from None
    return {"tolerance_mm": value * UNIT_TO_MM[unit]} if unit else {"tolerance": value}


def _print_summary(report):
    source = report.get("input", {})
    print(f"input: {source.get('file')}: {source.get('triangles')} triangles, genus "
          f"{source.get('genus')}, bbox diagonal {source.get('bbox_diagonal', 0):.4g} {source.get('units')}"
          f" (x {source.get('unit_to_mm', 1.0):g} to mm)")
    for warning in source.get("warnings", []):
        print(f"  warning: {warning}")
    for name, entry in report.get("stages", {}).items():
        message = f" - {entry['message']}" if entry.get("message") else ""
        print(f"  {name:<10} {entry['status']:<14} {entry['seconds']:8.2f} s{message}")
    labeling = report.get("labeling")
    if labeling:
        print(f"labeling: valid={labeling['valid']} parts={labeling['parts']} charts="
              f"{labeling['charts']} corners={labeling['corners']} invalid charts/boundaries/corners="
              f"{labeling['invalid_charts']}/{labeling['invalid_boundaries']}/{labeling['invalid_corners']}")
    for kind, path in report.get("outputs", {}).items():
        print(f"wrote {kind}: {path}")


def _subd_to_step(args, stages):
    from polycube_wb.api import subd_to_solid

    _, report = subd_to_solid(args.base_mesh, args.output, args.report, depth=args.depth,
                              measure=not args.no_measure, progress=stages, export=args.export,
                              faces=args.faces)
    base, brep, patches = report["base_mesh"], report["brep"], report["patches"]
    print(f"base mesh: {base['faces']} faces ({base['quads']} quads, {base['triangles']} triangles, "
          f"{base['other']} other), {base['extraordinary_vertices']} extraordinary vertices, genus {base['genus']}")
    reference = ("" if brep["limit_volume"] is None else
                 f" (limit surface {brep['limit_volume']:.6g}, rel. error {brep['volume_error_rel']:.1e})")
    per_face = ("one per rectangular block of quads" if patches.get("faces") == "chart" else
                "per base face: " + ", ".join(f"{n}-gon {k:g}" for n, k
                                               in patches["patches_per_base_face"].items()))
    print(f"solid: {brep['faces']} B-spline faces ({per_face}), valid={brep['valid']} "
          f"closed={brep['closed']} volume={brep['volume']:.6g}{reference}, built from "
          f"{brep['construction'].replace('_', ' ')}")
    if brep["construction_note"]:
        print(f"  note: {brep['construction_note']}")
    if patches.get("max_error_rel") is not None:
        print(f"patches: max deviation from the limit surface {patches['max_error_rel']:.1e} of the "
              f"bbox diagonal, normal jump max {patches['normal_jump_max_deg']:.3f} deg")
    print(f"wrote STEP: {brep['step_path']}  ({report['total_seconds']:.2f} s)")
    return EXIT_OK


def _check(args, stages):
    from core.output_files import check_output_path, write_json_atomic
    from polycube_wb.api import check

    if args.report:
        check_output_path(args.report, (args.target, args.result), "report")
    result = check(args.target, args.result)
    if args.report:
        write_json_atomic(args.report, result, (args.target, args.result))
    print(json.dumps(result, indent=2))
    return EXIT_OK


def _batch(args, stages):
    from polycube_wb.batch import run_batch_command

    for value, what in ((args.jobs, "--jobs"), (args.timeout, "--timeout")):
        if value is not None and not value > 0:
            raise PolycubeInputError(f"{what} must be positive, got {value:g}")
    if args.memory_limit is not None and args.memory_limit < 0:
        raise PolycubeInputError(f"--memory-limit must be positive (MiB) or 0 for no cap, "
                                 f"got {args.memory_limit:g}")
    from polycube_wb.batch_progress import ProgressBar, ProgressLines

    progress = ProgressLines() if args.progress_lines else \
        ProgressBar() if not args.quiet and sys.stderr.isatty() else None
    result = run_batch_command(args.inputs, args.output_dir, pipeline_params(args),
                               overrides_path=args.overrides, jobs=args.jobs,
                               timeout=args.timeout, memory_mb=args.memory_limit,
                               scheduler=args.scheduler, force=args.force, progress=progress)
    if not args.quiet:
        print(f"{len(result.rows)} meshes, {len(result.rows) - result.failures} solids, "
              f"{result.failures} failed, {result.seconds:.1f} s")
        for row in result.rows:
            if row.status != "ok":
                print(f"  {row.name}: {row.status} at {row.failed_stage or '-'}: {row.message}")
        print(f"wrote {result.summary_csv}\nwrote {result.summary_html}")
    return EXIT_OK


_FROM_TEXT = {"parts_file": _parts_file, "tolerance": _tolerance}
"""Parameters whose option is text turned into parameter values (a dict) by the function."""
_COMMANDS = {"reconstruct": _reconstruct, "batch": _batch, "subd-to-step": _subd_to_step, "check": _check}
