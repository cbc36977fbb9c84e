# SPDX-License-Identifier: LGPL-2.1-or-later
"""``python -m polycube_wb batch``: per-mesh outputs, failures per row, skip/--force, time cap,
memory cap, honest peak memory, bad input, the same batch on a two-worker Dask LocalCluster, and the summary page in chromium.

Small meshes only (the tiny level-set cantilever, a box built here, a broken file) with a few
fit iterations, so the whole module stays at a minute or so.
"""
import csv
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import trimesh

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TINY = os.path.join(REPO, "..", "shared", "data", "meshes", "to_levelset_cantilever_tiny.stl")
FAST = ("--fit-iterations", "3", "--target-faces", "60")
ARTIFACTS = os.environ.get("POLYCUBE_GUI_OUTPUT") or os.path.join(REPO, "tests", "gui", "output")


def run_batch(*args):
    return subprocess.run([sys.executable, "-m", "polycube_wb", "batch", *map(str, args)],
                          cwd=REPO, capture_output=True, text=True, timeout=600)


def make_box(path):
    mesh = trimesh.creation.box((20.0, 10.0, 6.0))
    for _ in range(3):
        mesh = mesh.subdivide()
    mesh.export(path)
    return path


def make_broken(path):
    path.write_text("solid broken\nendsolid broken\n")
    return path


def read_rows(out):
    with open(out / "summary.csv", newline="") as handle:
        return {row["name"]: row for row in csv.DictReader(handle)}


def output_times(out):
    return {p.name: p.stat().st_mtime_ns for p in out.iterdir() if not p.name.startswith("summary")}


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    """One batch (--jobs 2) over the tiny cantilever, a box and a broken file."""
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")
    inputs = tmp_path_factory.mktemp("inputs")
    shutil.copy(TINY, inputs / "tiny.stl")
    make_box(inputs / "box.stl")
    make_broken(inputs / "broken.stl")
    out = tmp_path_factory.mktemp("batch") / "out"
    result = run_batch(inputs, "-o", out, "--jobs", "2", *FAST)
    assert result.returncode == 0, result.stderr
    return inputs, out, result


def test_every_output_and_a_row_per_mesh(batch_run):
    import FreeCAD  # noqa: F401
    import Part

    inputs, out, result = batch_run
    rows = read_rows(out)
    assert set(rows) == {"tiny", "box", "broken"}
    with open(out / "summary.csv", newline="") as handle:
        assert next(csv.DictReader(handle))["name"] == "broken"  # failures first
    for name in ("tiny", "box"):
        row = rows[name]
        assert row["status"] == "ok" and row["stage_reached"] == "solid", row
        for suffix in (".step", ".base.obj", ".labels.ply", ".json", ".png"):
            assert (out / f"{name}{suffix}").stat().st_size > 0, (name, suffix)
        shape = Part.read(str(out / f"{name}.step"))
        assert len(shape.Solids) == 1 and shape.Solids[0].isValid()
        assert len(shape.Solids[0].Faces) == int(row["faces"])
        report = json.loads((out / f"{name}.json").read_text())
        assert report["batch"]["params"]["fit_iterations"] == 3
        assert float(row["mean_deviation"]) == pytest.approx(report["fit"]["mean_distance"])
        assert float(row["max_deviation"]) == pytest.approx(
            max(report["fit"]["max_distance"], report["fit"]["target_max_distance"]))
        assert 0.0 < float(row["mean_deviation"]) <= float(row["max_deviation"]) < 0.05
        assert int(row["triangles"]) == report["input"]["triangles"]
    assert rows["box"]["triangles"] == "768" and rows["box"]["genus"] == "0"
    broken = rows["broken"]
    assert broken["status"] == "failed" and broken["failed_stage"] == "intake"
    assert "no triangles" in broken["message"] and broken["thumbnail"] == ""
    assert not (out / "broken.step").exists()
    assert "1 failed" in result.stdout and "broken: failed at intake" in result.stdout
    assert result.stderr == ""  # no progress bar when not on a terminal


def test_rerun_skips_current_meshes_and_redoes_changed_ones(tmp_path):
    inputs = tmp_path / "in"
    inputs.mkdir()
    make_box(inputs / "box.stl")
    make_broken(inputs / "broken.stl")
    out = tmp_path / "out"
    assert run_batch(inputs, "-o", out, "--jobs", "1", *FAST).returncode == 0
    first = output_times(out)

    again = run_batch(inputs / "*.stl", "-o", out, *FAST)
    assert again.returncode == 0, again.stderr
    assert output_times(out) == first
    assert {r["skipped"] for r in read_rows(out).values()} == {"True"}

    os.utime(inputs / "box.stl", ns=(first["box.json"] + 10**9,) * 2)  # the input changed
    assert run_batch(inputs, "-o", out, *FAST).returncode == 0
    rows, times = read_rows(out), output_times(out)
    assert rows["box"]["skipped"] == "False" and rows["broken"]["skipped"] == "True"
    assert times["box.step"] > first["box.step"] and times["broken.json"] == first["broken.json"]

    overrides = tmp_path / "overrides.json"
    overrides.write_text(json.dumps({"box*": {"fit_mode": "none"}}))
    assert run_batch(inputs, "-o", out, "--overrides", overrides, *FAST).returncode == 0
    rows = read_rows(out)
    assert rows["box"]["skipped"] == "False" and rows["broken"]["skipped"] == "True"
    report = json.loads((out / "box.json").read_text())
    assert report["batch"]["params"]["fit_mode"] == "none" and report["fit"]["mode"] == "none"

    forced = run_batch(inputs, "-o", out, "--overrides", overrides, "--force", *FAST)
    assert forced.returncode == 0
    assert {r["skipped"] for r in read_rows(out).values()} == {"False"}


def test_time_cap_stops_a_mesh_and_it_runs_again_next_time(tmp_path):
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")
    out = tmp_path / "out"
    result = run_batch(TINY, "-o", out, "--timeout", "1")
    assert result.returncode == 0, result.stderr
    row = read_rows(out)["to_levelset_cantilever_tiny"]
    assert row["status"] == "timeout" and "1 s time cap at stage" in row["message"]
    assert float(row["peak_memory_mb"]) > 0.0  # the largest reading before it was stopped
    assert not (out / "to_levelset_cantilever_tiny.step").exists()
    report = json.loads((out / "to_levelset_cantilever_tiny.json").read_text())
    assert report["batch"]["status"] == "timeout"
    result = run_batch(TINY, "-o", out, "--timeout", "1")
    assert read_rows(out)["to_levelset_cantilever_tiny"]["skipped"] == "False"


STAGES = ("startup", "intake", "parts", "frames", "labeling", "basemesh", "fit", "patches",
          "solid", "writing", "thumbnail")
CAP_MESSAGE = re.compile(r"memory limit of 120 MB exceeded at stage (\w+)$")


def test_memory_cap_fails_the_mesh_at_its_stage_and_it_runs_again_next_time(tmp_path):
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")
    out = tmp_path / "out"
    result = run_batch(TINY, "-o", out, "--memory-limit", "120", *FAST)
    assert result.returncode == 0, result.stderr
    row = read_rows(out)["to_levelset_cantilever_tiny"]
    match = CAP_MESSAGE.match(row["message"])
    assert row["status"] == "failed" and match, row
    assert row["failed_stage"] == match.group(1) and match.group(1) in STAGES[1:]
    assert float(row["peak_memory_mb"]) > 120.0  # its resident memory when it was stopped
    assert f"failed at {match.group(1)}: memory limit of 120 MB" in result.stdout
    assert not (out / "to_levelset_cantilever_tiny.step").exists()
    report = json.loads((out / "to_levelset_cantilever_tiny.json").read_text())
    assert report["batch"]["memory_limit_exceeded"] is True
    run_batch(TINY, "-o", out, "--memory-limit", "120", *FAST)
    assert read_rows(out)["to_levelset_cantilever_tiny"]["skipped"] == "False"


def test_a_mesh_over_its_cap_does_not_stop_the_others(tmp_path):
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")
    from polycube_wb.batch import plan_jobs, run_batch as run_jobs

    box = make_box(tmp_path / "box.stl")
    params = {"fit_iterations": 3, "target_faces": 60}
    capped, free = plan_jobs([TINY, str(box)], tmp_path / "out", params, memory_mb=120.0)
    (tmp_path / "out").mkdir()
    free.memory_mb = None
    rows = run_jobs([capped, free], jobs_at_once=2)
    assert rows[0].status == "failed" and CAP_MESSAGE.match(rows[0].message)
    assert rows[1].status == "ok" and rows[1].stage_reached == "solid" and rows[1].faces > 0
    assert 0.0 < rows[1].peak_memory_mb  # measured, below the default cap of the machine


def test_peak_memory_is_the_worker_s_own(batch_run):
    """A worker's peak is its own resident peak at its end, not its parent's (ru_maxrss
    inherits the parent's across fork + exec) and not the pipeline's before the thumbnail."""
    _, out, _ = batch_run
    rows = read_rows(out)
    for name in ("tiny", "box"):
        report = json.loads((out / f"{name}.json").read_text())
        assert float(rows[name]["peak_memory_mb"]) == report["peak_memory_mb"]
        assert 50.0 < report["peak_memory_mb"] < 2000.0, report["peak_memory_mb"]
    broken = float(rows["broken"]["peak_memory_mb"])
    assert 0.0 < broken < float(rows["box"]["peak_memory_mb"])  # stopped at intake: less


@pytest.mark.parametrize("case, words", [
    ("missing", "is not a mesh file, a folder"),
    ("overrides", "unknown parameter(s) fit_iters"),
    ("no_parent", "its parent does not exist"),
    ("jobs", "--jobs must be positive"),
    ("memory", "--memory-limit must be positive (MiB) or 0 for no cap"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, case, words):
    box = make_box(tmp_path / "box.stl")
    out = tmp_path / "out"
    overrides = tmp_path / "o.json"
    overrides.write_text(json.dumps({"*": {"fit_iters": 3}}))
    args = {"missing": (tmp_path / "nothing*.stl", "-o", out),
            "overrides": (box, "-o", out, "--overrides", overrides),
            "no_parent": (box, "-o", tmp_path / "a" / "b"),
            "jobs": (box, "-o", out, "--jobs", "0"),
            "memory": (box, "-o", out, "--memory-limit", "-5")}[case]
    result = run_batch(*args)
    assert result.returncode == 2
    assert result.stderr.startswith("error:") and words in result.stderr, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["box.stl", "o.json"]


def test_same_batch_on_a_two_worker_dask_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    from polycube_wb.batch import run_batch_command
    from polycube_wb.cli import build_parser, pipeline_params

    inputs = tmp_path / "in"
    inputs.mkdir()
    make_box(inputs / "box.stl")
    make_box(inputs / "box_b.stl")
    make_broken(inputs / "broken.stl")
    args = build_parser().parse_args(["batch", str(inputs), "-o", "x", *FAST])
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        result = run_batch_command([str(inputs)], tmp_path / "out", pipeline_params(args),
                                   scheduler=cluster.scheduler_address)
    rows = {row.name: row for row in result.rows}
    assert [row.status for row in result.rows] == ["ok", "ok", "failed"]
    assert rows["broken"].failed_stage == "intake"
    for name in ("box", "box_b"):
        assert rows[name].faces == rows["box"].faces > 0
        assert (tmp_path / "out" / f"{name}.step").stat().st_size > 0
    assert rows["box_b"].mean_deviation == pytest.approx(rows["box"].mean_deviation, rel=1e-9)
    assert read_rows(tmp_path / "out").keys() == rows.keys()


def chromium_command():
    """The headless chromium command line, or skip with the reason it cannot run."""
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip("chromium is not installed (scripts/setup.sh installs Debian's chromium)")
    return [browser, "--headless", "--no-sandbox", "--disable-gpu",
            "--disable-background-networking", "--disable-component-update", "--no-first-run",
            "--allow-file-access-from-files", "--window-size=1400,900"]


def test_summary_page_in_headless_chromium(batch_run, tmp_path):
    import matplotlib.image

    _, out, _ = batch_run
    page = (out / "summary.html").as_uri()
    base = chromium_command()
    dom = subprocess.run(base + [f"--user-data-dir={tmp_path / 'profile-a'}",
                                 "--virtual-time-budget=5000", "--dump-dom", page],
                         capture_output=True, text=True, timeout=120)
    if dom.returncode != 0 or "<table" not in dom.stdout:
        pytest.skip(f"chromium cannot run here: {dom.stderr.strip()[-300:]}")
    html_text = dom.stdout
    assert re.search(r'<body[^>]*data-thumbnails="2"', html_text), "both thumbnails load"
    body = html_text.split("<tbody>")[1].split("</tbody>")[0]
    assert body.count("<tr") == 3 and "thumbnail missing" not in body
    assert body.index('class="failed"') < body.index('class="ok"')
    source = (out / "summary.html").read_text()
    assert not re.search(r'(src|href)="(?!box\.png|tiny\.png)', source)  # nothing fetched elsewhere

    os.makedirs(ARTIFACTS, exist_ok=True)
    shot = os.path.join(ARTIFACTS, "batch_summary.png")
    if os.path.exists(shot):
        os.remove(shot)
    subprocess.run(base + [f"--user-data-dir={tmp_path / 'profile-b'}",
                           "--virtual-time-budget=5000", f"--screenshot={shot}", page],
                   capture_output=True, text=True, timeout=120, check=True)
    pixels = matplotlib.image.imread(shot)
    assert pixels.shape[:2] == (900, 1400)
    assert np.std(pixels[..., :3]) > 0.05  # not a blank page
