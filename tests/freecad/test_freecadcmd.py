# SPDX-License-Identifier: LGPL-2.1-or-later
"""The workbench in FreeCAD's own Python: ``freecadcmd`` subprocesses and the .venv.

- FreeCAD runs with the temporary user folder of ``tests/conftest.py``;
- the runtime packages (trimesh, manifold3d) import inside ``freecadcmd``;
- a FreeCADCmd script turns a SubD cage into a STEP solid through ``polycube_wb.api``;
- the parametric stage objects recompute, save and reopen in ``freecadcmd``;
- ``from core.x import y`` keeps finding our ``core`` after another addon (CfdOF)
  replaced ``sys.modules['core']``, in ``freecadcmd`` and in plain Python;
- the progress adapter (``polycube_wb.gui.fc_progress``) runs one bar forwards and maps FreeCAD's abort to
  ``core.errors.Cancelled``.

Subprocesses run in a temporary folder, so nothing in the working directory can
shadow a module.
"""
import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FREECADCMD = shutil.which("freecadcmd")
TIMEOUT = 120
RESULT_TAG = "POLYCUBE_RESULT="

needs_freecadcmd = pytest.mark.skipif(FREECADCMD is None, reason="freecadcmd is not installed")


def _run(command, cwd):
    completed = subprocess.run(command, cwd=cwd, capture_output=True, text=True,
                               timeout=TIMEOUT)
    output = completed.stdout + completed.stderr
    assert completed.returncode == 0, f"{command[0]} exited {completed.returncode}:\n{output}"
    lines = [line for line in completed.stdout.splitlines() if line.startswith(RESULT_TAG)]
    assert lines, f"no {RESULT_TAG} line in the output:\n{output}"
    return json.loads(lines[-1][len(RESULT_TAG):])


def _freecadcmd(code, cwd, load_addon=False):
    """Run ``code`` with ``freecadcmd -c``; with ``load_addon`` also ``-M <repo>``."""
    command = [FREECADCMD, "-c", code]
    if load_addon:
        command += ["-M", REPO]
    return _run(command, cwd)


def _script(body):
    """Python source: put the repo on sys.path, run ``body``, which sets ``result``.

    ``addon_init_ran`` tells whether ``polycube_wb`` was imported before the script
    (by our Init.py, when freecadcmd got ``-M <repo>``).
    """
    return textwrap.dedent(f"""\
        import json, sys
        addon_init_ran = "polycube_wb" in sys.modules
        sys.path.insert(0, {REPO!r})
        """) + textwrap.dedent(body) + textwrap.dedent(f"""\
        print({RESULT_TAG!r} + json.dumps(result))
        """)


@needs_freecadcmd
def test_freecad_uses_the_temporary_user_folder(tmp_path):
    """tests/conftest.py gives FreeCAD a temporary user folder, here and in freecadcmd: no
    workbench from the user's ``Mod`` folder loads, the runtime packages still import."""
    import FreeCAD

    home = os.path.realpath(os.environ["FREECAD_USER_HOME"])
    assert os.path.realpath(FreeCAD.getUserAppDataDir()) == home
    assert not home.startswith(os.path.realpath(os.path.expanduser("~")) + os.sep)
    result = _freecadcmd(_script("""
        import os
        import FreeCAD, trimesh
        result = {"data": os.path.realpath(FreeCAD.getUserAppDataDir()),
                  "config": os.path.realpath(FreeCAD.ConfigGet("UserConfigPath")),
                  "trimesh": os.path.realpath(trimesh.__file__),
                  "user_mods": [p for p in sys.path if os.path.realpath(p).startswith((
                      os.path.expanduser("~/.local/share/FreeCAD/Mod"),
                      os.path.join(FreeCAD.getUserAppDataDir(), "Mod")))]}
    """), tmp_path)
    assert result["data"] == result["config"] == home
    assert result["user_mods"] == []
    packages = os.path.realpath(os.path.join(home, "AdditionalPythonPackages"))
    assert result["trimesh"].startswith(packages + os.sep)


@needs_freecadcmd
def test_runtime_packages_import_in_freecadcmd(tmp_path):
    result = _freecadcmd(_script("""
        import numpy, scipy, trimesh, manifold3d
        box = trimesh.creation.box()
        cube = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
        result = {"trimesh": trimesh.__version__, "numpy": numpy.__version__,
                  "box_watertight": bool(box.is_watertight), "cube_volume": cube.volume()}
    """), tmp_path)
    assert result["box_watertight"]
    assert result["cube_volume"] == pytest.approx(1.0, abs=1e-12)


@needs_freecadcmd
@pytest.mark.parametrize("load_addon", [False, True], ids=["sys_path", "dash_M"])
def test_freecadcmd_script_subd_cage_to_step(tmp_path, load_addon):
    cage = tmp_path / "cube.obj"
    step = tmp_path / "cube.step"
    result = _freecadcmd(_script(f"""
        import FreeCAD
        import Part
        import polycube_wb
        from core.polymesh_io import write_polymesh
        from core.subdivision.sample_cages import cube
        from polycube_wb.api import subd_to_solid

        write_polymesh({str(cage)!r}, cube(10.0))
        solid, report = subd_to_solid({str(cage)!r}, step_path={str(step)!r})
        read = Part.read({str(step)!r})
        result = {{"valid": solid.isValid(), "faces": len(solid.Faces),
                  "volume": solid.Volume, "limit_volume": report["brep"]["limit_volume"],
                  "read_solids": len(read.Solids), "read_volume": read.Volume,
                  "addon_init_ran": addon_init_ran,
                  "polycube_wb": polycube_wb.__file__}}
    """), tmp_path, load_addon=load_addon)
    # With -M <repo>, freecadcmd runs our Init.py, which imports polycube_wb.
    assert result["addon_init_ran"] == load_addon
    assert result["valid"]
    assert result["faces"] == 6
    assert result["read_solids"] == 1
    assert result["polycube_wb"].startswith(REPO)
    # B-spline patches reproduce the Catmull-Clark limit volume of the cube cage.
    assert abs(result["volume"] - result["limit_volume"]) / result["limit_volume"] < 1e-4
    assert result["read_volume"] == pytest.approx(result["volume"], rel=1e-6)
    assert step.stat().st_size > 1000


@needs_freecadcmd
def test_stage_objects_in_freecadcmd_save_and_reopen(tmp_path):
    """The App side of the stage objects works in FreeCAD's own console Python."""
    mesh = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
    saved = tmp_path / "segmented.FCStd"
    result = _freecadcmd(_script(f"""
        import FreeCAD
        from polycube_wb import api

        doc = FreeCAD.newDocument("Cmd")
        target = api.make_target(doc, {mesh!r}, check_self_intersections=False)
        seg = api.make_segmentation(doc, target, Lambda=0.5)
        outcome = api.recompute(doc)
        names = (target.Name, seg.Name)
        doc.saveAs({str(saved)!r})
        FreeCAD.closeDocument(doc.Name)
        doc = FreeCAD.openDocument({str(saved)!r})
        seg = doc.getObject(names[1])
        result = {{"ok": outcome.ok, "gui": bool(FreeCAD.GuiUp),
                  "proxy": type(seg.Proxy).__module__ + "." + type(seg.Proxy).__name__,
                  "valid": seg.Valid, "labels": len(seg.FaceLabel),
                  "facets": doc.getObject(names[0]).Mesh.CountFacets,
                  "status": seg.Status}}
    """), tmp_path, load_addon=True)
    assert result["ok"] and not result["gui"]
    assert result["proxy"] == "polycube_wb.objects.segmentation.SegmentationProxy"
    assert result["valid"] and result["status"] == "ok"
    assert result["labels"] == result["facets"] == 15388


COLLISION_BODY = """
    import os, types
    import polycube_wb

    # What CfdOF's InitGui does: put its own package in sys.modules['core'].
    foreign = types.ModuleType("core")
    foreign.__file__ = os.path.join({tmp!r}, "CfdOF", "__init__.py")
    foreign.__path__ = [os.path.join({tmp!r}, "CfdOF")]
    sys.modules["core"] = foreign

    import numpy as np
    import trimesh
    from core.segmentation.labeling import hbecvt_labeling, nearest_direction_labels
    from core.segmentation.labeling import face_normals

    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    V, F = np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64)
    frames = np.repeat(np.eye(3)[None], len(F), axis=0)
    parts = np.zeros(len(F), dtype=np.int32)
    labels, info = hbecvt_labeling(V, F, parts, frames)
    expected = nearest_direction_labels(face_normals(V, F), frames)
    import core.segmentation.labeling as labeling_module
    result = {{"labels": labels.tolist(), "expected": expected.tolist(),
              "module_file": labeling_module.__file__,
              "core_still_foreign": sys.modules["core"] is foreign}}
"""


def _check_collision_result(result):
    assert result["core_still_foreign"], "our import must not take sys.modules['core'] back"
    assert result["module_file"] == os.path.join(REPO, "core", "segmentation", "labeling.py")
    # Every face of an axis-aligned box gets the label of its own normal direction.
    assert result["labels"] == result["expected"]
    assert sorted(set(result["labels"])) == [0, 1, 2, 3, 4, 5]


@needs_freecadcmd
def test_core_survives_foreign_core_module_in_freecadcmd(tmp_path):
    body = COLLISION_BODY.format(tmp=str(tmp_path))
    _check_collision_result(_freecadcmd(_script(body), tmp_path, load_addon=True))


def test_core_survives_foreign_core_module_in_plain_python(tmp_path):
    body = COLLISION_BODY.format(tmp=str(tmp_path))
    script = tmp_path / "collision.py"
    script.write_text(_script(body), encoding="utf-8")
    _check_collision_result(_run([sys.executable, str(script)], tmp_path))


class _FakeIndicator:
    """Stands in for ``Base.ProgressIndicator``; raises FreeCAD's abort after N steps."""

    log = []

    def __init__(self, abort_after=None):
        self.abort_after = abort_after
        self.steps = 0

    def start(self, text, steps):
        self.log.append(("start", text, steps))

    def next(self, can_abort=False):
        assert can_abort, "the adapter must let the user abort"
        if self.abort_after is not None and self.steps >= self.abort_after:
            raise RuntimeError("abort progress indicator")
        self.steps += 1

    def stop(self):
        self.log.append(("stop", self.steps))


def test_progress_adapter_runs_one_bar_forwards_and_clamps():
    from core.progress import SubProgress
    from polycube_wb.gui.fc_progress import STEPS, FreeCADProgress

    _FakeIndicator.log = []
    with FreeCADProgress("Job", indicator_factory=_FakeIndicator) as progress:
        progress.report("intake", 0.25)
        progress.report("intake", 0.1)
        fit = SubProgress(progress, 0.5, 0.9)
        fit.report("fit", 0.5)
        fit.report("fit", 2.0)
        progress.check_cancel()
    assert _FakeIndicator.log == [("start", "Job", STEPS), ("stop", round(0.9 * STEPS))]


def test_progress_adapter_turns_abort_into_cancelled():
    from core.errors import Cancelled
    from polycube_wb.gui.fc_progress import STEPS, FreeCADProgress

    _FakeIndicator.log = []
    progress = FreeCADProgress("Job", indicator_factory=lambda: _FakeIndicator(abort_after=3))
    with pytest.raises(Cancelled, match="cancelled by the user"):
        progress.report("fit", 0.5)
    assert progress.cancelled
    with pytest.raises(Cancelled):
        progress.check_cancel()
    with pytest.raises(Cancelled):
        progress.report("fit", 0.6)
    progress.stop()
    assert _FakeIndicator.log == [("start", "Job", STEPS)], "FreeCAD stops itself on abort"


def test_progress_adapter_with_freecads_indicator(tmp_path):
    from core.polymesh_io import write_polymesh
    from core.subdivision.sample_cages import cube
    from polycube_wb.api import subd_to_solid
    from polycube_wb.gui.fc_progress import FreeCADProgress

    cage = str(tmp_path / "cube.obj")
    write_polymesh(cage, cube())
    with FreeCADProgress("SubD") as progress:
        solid, _ = subd_to_solid(cage, measure=False, progress=progress)
    assert solid.isValid()
    assert not progress.cancelled
