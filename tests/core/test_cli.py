# SPDX-License-Identifier: LGPL-2.1-or-later
"""The command line: exit codes, messages, outputs, and that bad input writes nothing."""
import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SAMPLE = os.path.join(REPO, "examples", "to_simp_cantilever.stl")


def run(*args):
    return subprocess.run([sys.executable, "-m", "polycube_wb", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=300)


def digest(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@pytest.mark.parametrize("command", ["reconstruct", "subd-to-step", "check"])
def test_help(command):
    result = run(command, "--help")
    assert result.returncode == 0 and "usage:" in result.stdout


@pytest.mark.slow
def test_labeling_run_writes_labels_and_report(tmp_path):
    before = digest(SAMPLE)
    result = run("reconstruct", SAMPLE, "--stop-after", "labeling", "--labels",
                 tmp_path / "l.ply", "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["input"]["triangles"] == 15388 and report["input"]["genus"] == 0
    assert report["stages"]["labeling"]["status"] == "ok"
    assert report["labeling"]["valid"] is True
    for key in ("charts", "corners", "invalid_charts", "invalid_boundaries", "invalid_corners",
                "turning_points", "parts"):
        assert key in report["labeling"]
    assert report["peak_memory_mb"] > 0 and report["total_seconds"] > 0
    labels = trimesh.load(tmp_path / "l.ply", process=False)
    assert len(labels.faces) == 15388
    assert digest(SAMPLE) == before
    again = run("reconstruct", SAMPLE, "--stop-after", "labeling", "--labels", tmp_path / "m.ply")
    assert again.returncode == 0 and digest(tmp_path / "l.ply") == digest(tmp_path / "m.ply")


@pytest.mark.slow
def test_full_run_writes_a_step_solid_and_every_report_section(tmp_path):
    result = run("reconstruct", SAMPLE, "-o", tmp_path / "out.step", "--report", tmp_path / "r.json",
                 "--base-mesh", tmp_path / "base.obj", "--fit-iterations", "5")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert all(entry["status"] == "ok" for entry in report["stages"].values()), report["stages"]
    base = report["base_mesh"]
    assert base["faces"] == base["quads"] + base["triangles"] + base["other"] and base["genus"] == 0
    fit = report["fit"]
    assert fit["iterations"] == 5 and fit["mode"] == "inside" and fit["self_intersections"] == 0
    for key in ("mean_distance", "max_distance", "outside_volume_fraction",
                "uncovered_volume_fraction"):
        assert 0 <= fit[key] < 1, key
    assert fit["outside_volume_fraction"] <= 0.005  # inside mode: at most 0.5 % outside
    assert fit["mean_distance"] < fit["initial_mean_distance"]
    brep = report["brep"]
    assert brep["valid"] and brep["closed"] and brep["faces"] == base["faces"]
    assert (tmp_path / "out.step").stat().st_size > 0 and (tmp_path / "base.obj").exists()


@pytest.mark.slow
def test_automatic_parts_are_assembled_into_one_base_mesh(tmp_path):
    result = run("reconstruct", SAMPLE, "--parts", "auto", "--stop-after", "basemesh",
                 "--report", tmp_path / "r.json", "--base-mesh", tmp_path / "base.obj")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["parts"]["parts"] >= 2 and report["stages"]["basemesh"]["status"] == "ok"
    base = report["base_mesh"]
    assert base["genus"] == report["input"]["genus"] and base["quads"] == base["faces"]
    assert (tmp_path / "base.obj").exists()

def assert_rejected(result, *words):
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), result.stderr
    for word in words:
        assert word in lines[0]


def test_open_mesh_exits_2_and_writes_nothing(tmp_path):
    mesh = trimesh.creation.box()
    path = tmp_path / "open.stl"
    trimesh.Trimesh(mesh.vertices, mesh.faces[:-2], process=False).export(path)
    before = digest(path)
    out = tmp_path / "out"
    out.mkdir()
    result = run("reconstruct", path, "--stop-after", "labeling", "--labels", out / "l.ply",
                 "--report", out / "r.json")
    assert_rejected(result, "boundary edges")
    assert list(out.iterdir()) == [] and digest(path) == before


def test_wrong_format_and_missing_file(tmp_path):
    path = tmp_path / "mesh.step"
    path.write_text("ISO-10303-21;")
    assert_rejected(run("reconstruct", path, "--stop-after", "intake"), "unsupported file type")
    assert_rejected(run("reconstruct", tmp_path / "none.stl", "--stop-after", "intake"), "no such file")


@pytest.mark.parametrize("option, value, words", [
    ("--lam", "-1", ["lam"]), ("--blend-factor", "nan", ["blend_factor"]),
    ("--penalty", "1e30", ["penalty"]), ("--units", "furlong", ["invalid choice"]),
    ("--max-sweeps", "0", ["max_sweeps"]), ("--subdivision-levels", "9", ["subdivision_levels"]),
])
def test_absurd_parameters_exit_2(option, value, words):
    assert_rejected(run("reconstruct", SAMPLE, "--stop-after", "intake", option, value), *words)


def test_option_defaults_are_the_parameter_defaults():
    """Every reconstruct option named after a parameter defaults to core.params' value
    (``--parts-file`` and ``--tolerance`` are parsed from text into their parameters)."""
    from core.params import EXPORT_DEPTH, ReconstructionParams
    from polycube_wb.cli import build_parser

    parser = build_parser()
    parsed = vars(parser.parse_args(["reconstruct", "target.stl"]))
    shared = {name: value for name, value in ReconstructionParams().to_dict().items()
              if name in parsed and name not in ("parts_file", "tolerance")}
    assert {"lam", "penalty", "max_sweeps", "subdivision_levels", "fit_iterations"} <= set(shared)
    assert {name: parsed[name] for name in shared} == shared
    assert parser.parse_args(["subd-to-step", "cage.obj", "-o", "x.step"]).depth == EXPORT_DEPTH


def _other_value(item, option):
    """A valid value of a parameter other than its default, as command-line words and as
    the value it must become."""
    if item.type is bool:
        return [option.flag], not item.default
    if option.choices is not None:
        choice = next(c for c in option.choices if c != item.default)
        return [option.flag, choice], choice
    value = item.type(option.low + 1 if item.default == option.low else option.low)
    return [option.flag, str(value)], value


COMPANION_OPTIONS = {"faces": ["--export", "g1"]}
"""Options a parameter's other value needs (merged faces are made of the G1 export only)."""


def test_every_parameter_option_reaches_the_parameters_and_the_help():
    """The options are made from ``core.params`` alone: each flagged field, set on the
    command line to a value other than its default, arrives in ``pipeline_params`` (and
    ``ReconstructionParams`` accepts the result); ``--help`` of both commands names every
    flag and prints each number's range."""
    from core.params import ReconstructionParams, parameter_options
    from polycube_wb.cli import build_parser, pipeline_params

    parser = build_parser()
    flagged = [(item, option) for item, option in parameter_options() if option.flag]
    assert {item.name for item, option in parameter_options() if not option.flag} == \
        {"fit_t_min", "tolerance_mm"}  # set through the API, or --tolerance with a unit
    for item, option in flagged:
        if item.name in ("parts_file", "tolerance"):
            continue  # text options, below
        words, expected = _other_value(item, option)
        words += COMPANION_OPTIONS.get(item.name, [])
        values = pipeline_params(parser.parse_args(["reconstruct", "t.stl", *words]))
        assert values[item.name] == expected, (item.name, values[item.name], expected)
        assert getattr(ReconstructionParams(**values), item.name) == expected
    text = pipeline_params(parser.parse_args(["batch", "in", "-o", "out", "--parts-file",
                                              "p.json", "--tolerance", "0.5mm"]))
    assert (text["parts"], text["parts_file"], text["tolerance_mm"]) == ("file", "p.json", 0.5)
    assert "tolerance" not in text and ReconstructionParams(**text).tolerance == 0.0
    for command in ("reconstruct", "batch"):
        shown = run(command, "--help").stdout
        assert all(option.flag in shown for _, option in flagged), command
        assert "levels of the fit (paper: 2) [1..5]" in " ".join(shown.split())


@pytest.mark.slow
def test_max_sweeps_and_subdivision_levels_reach_the_run(tmp_path):
    result = run("reconstruct", SAMPLE, "--stop-after", "labeling", "--max-sweeps", "3",
                 "--subdivision-levels", "1", "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    parameters = json.loads((tmp_path / "r.json").read_text())["parameters"]
    assert (parameters["max_sweeps"], parameters["subdivision_levels"]) == (3, 1)


def test_output_over_the_input_is_refused(tmp_path):
    copy = tmp_path / "target.stl"
    copy.write_bytes(open(SAMPLE, "rb").read())
    before = digest(copy)
    assert_rejected(run("reconstruct", copy, "--stop-after", "labeling", "--report", copy),
                    "overwrite the input file")
    assert digest(copy) == before


def test_output_folder_missing(tmp_path):
    assert_rejected(run("reconstruct", SAMPLE, "--stop-after", "intake", "--report",
                        tmp_path / "nope" / "r.json"), "does not exist")


def test_self_intersecting_mesh_exits_2(tmp_path):
    mesh = trimesh.creation.box()
    V = np.asarray(mesh.vertices).copy()
    V[int(np.argmax(V.sum(axis=1)))] = [-0.9, 0.3, 0.2]
    path = tmp_path / "crossed.stl"
    trimesh.Trimesh(V, mesh.faces, process=False).export(path)
    assert_rejected(run("reconstruct", path, "--stop-after", "intake"), "intersecting faces")


@pytest.mark.slow
def test_user_parts_from_a_file(tmp_path):
    planes = tmp_path / "planes.json"
    planes.write_text(json.dumps({"planes": [[[80.0, 0.0, 0.0], [1.0, 0.0, 0.0]]]}))
    result = run("reconstruct", SAMPLE, "--parts-file", planes, "--stop-after", "labeling",
                 "--report", tmp_path / "r.json", "--labels", tmp_path / "l.ply")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["parts"]["mode"] == "file" and report["parts"]["parts"] >= 2
    assert report["labeling"]["parts"] == report["parts"]["parts"]
    short = tmp_path / "short.json"
    short.write_text(json.dumps({"face_part": [0, 0, 1]}))
    assert_rejected(run("reconstruct", SAMPLE, "--parts-file", short, "--stop-after", "parts"),
                    "face_part")
    assert_rejected(run("reconstruct", SAMPLE, "--parts-file", tmp_path / "none.json",
                        "--stop-after", "parts"), "cannot read the parts file")


def test_every_component_is_a_part_with_components_all(tmp_path):
    boxes = [trimesh.creation.box(), trimesh.creation.box()]
    boxes[1].apply_translation([3.0, 0.0, 0.0])
    path = tmp_path / "two.stl"
    trimesh.util.concatenate(boxes).export(path)
    result = run("reconstruct", path, "--components", "all", "--stop-after", "labeling",
                 "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["input"]["components"] == 2 and report["parts"]["parts"] == 2
    assert report["labeling"]["valid"] and report["labeling"]["charts"] == 12


@pytest.mark.parametrize("option, value, message", [
    ("--target-faces", "3", "target_faces must be between 6 and 200000, got 3"),
    ("--max-base-faces", "0", "max_base_faces must be between 6 and 1000000, got 0"),
    ("--target-faces", "many", "argument --target-faces: invalid int value: 'many'")])
def test_bad_base_mesh_options_exit_2_and_write_nothing(tmp_path, option, value, message):
    before = digest(SAMPLE)
    result = run("reconstruct", SAMPLE, "-o", tmp_path / "out.step", "--report",
                 tmp_path / "r.json", option, value)
    assert result.returncode == 2 and result.stderr.startswith("error: " + message), result.stderr
    assert list(tmp_path.iterdir()) == [] and digest(SAMPLE) == before


@pytest.mark.slow
def test_a_layout_over_the_users_max_base_faces_exits_2_and_writes_nothing(tmp_path):
    """The user's own face limit is bad input (exit 2, what to change), not a labeling
    failure: fandisk's polycube layout needs 112 quads at least."""
    mesh = os.path.join(REPO, "..", "shared", "data", "meshes", "fandisk.obj")
    result = run("reconstruct", mesh, "--stop-after", "basemesh", "--base-mesh-method",
                 "polycube", "--target-faces", "6", "--max-base-faces", "10",
                 "--report", tmp_path / "r.json", "--base-mesh", tmp_path / "base.obj")
    assert_rejected(result, "more than max_base_faces=10", "raise --max-base-faces", "charts")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_labeling_that_cannot_be_quantized_exits_1_naming_the_charts_or_falls_back(tmp_path):
    # the gripper's labeling with automatic parts is valid, but some of its charts do not close
    # as rectilinear polygons (benchmarks/BASEMESH_RESULTS.md)
    mesh = os.path.join(REPO, "..", "shared", "data", "meshes", "gripper_domain.stl")
    before = digest(mesh)
    result = run("reconstruct", mesh, "-o", tmp_path / "out.step", "--report", tmp_path / "r.json",
                 "--base-mesh", tmp_path / "base.obj", "--parts", "auto",
                 "--base-mesh-method", "polycube")
    assert result.returncode == 1 and "failed:" in result.stderr and "charts" in result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["stages"]["labeling"]["status"] == "ok"
    assert report["stages"]["basemesh"]["status"] == "failed"
    assert report["stages"]["fit"]["status"] == "skipped"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"] and digest(mesh) == before
    # the default route falls back to the paired decimation and says why
    result = run("reconstruct", mesh, "--report", tmp_path / "a.json", "--parts", "auto",
                 "--stop-after", "basemesh")
    assert result.returncode == 0, result.stderr
    base = json.loads((tmp_path / "a.json").read_text())["base_mesh"]
    assert base["method"] == "paired decimation" and "charts" in base["fallback_reason"]
    assert base["genus"] == 3 and base["within_budget"] and base["quads"] >= 0.9 * base["faces"]
