# SPDX-License-Identifier: LGPL-2.1-or-later
"""GUI smoke test: the real FreeCAD GUI under Xvfb runs tests/gui/gui_cases.py.

Runs ``xvfb-run -a -s "-screen 0 1280x1024x24" freecad -t TestPolycubeGui -M <repo>``
(``-t`` before ``-M``: FreeCAD 0.20.2 rejects the other order), then checks the exit
code, that unittest reports every case passed, and that the screenshots exist and show
something (size on disk, pixel size and colours). Screenshots go to
``$POLYCUBE_GUI_OUTPUT`` or ``tests/gui/output/`` and stay there for a human to look at.

``QT_QPA_PLATFORM=offscreen`` is not an option: FreeCAD 0.20.2 aborts with it.
"""
import os
import re
import shutil
import signal
import struct
import subprocess

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUTPUT = os.environ.get("POLYCUBE_GUI_OUTPUT") or os.path.join(REPO, "tests", "gui", "output")
SCREENSHOTS = ("polycube_torus_solid.png", "polycube_target_mesh.png", "polycube_parts.png",
               "polycube_labels.png", "polycube_base_mesh.png", "polycube_solid.png",
               "polycube_deviation.png", "polycube_edited_cage.png", "polycube_reconstructed.png",
               "polycube_large_solid.png")
CAGE_SCREENSHOTS = ("polycube_base_mesh.png",)
WINDOW_GRABS = ("polycube_fit_progress.png", "polycube_batch_progress.png",
                "polycube_cancelled.png", "polycube_fit_panel.png", "polycube_solid_panel.png",
                "polycube_responsive_fit.png", "polycube_deviation_16x9.png",
                "polycube_deviation_21x9.png")
"""The main window during the fit (progress bar), during Reconstruct folder (its dialog),
after Esc in the fit (the Fit marked in the tree), with the Fit's and the Solid's task panels
open and during the torsion arm's fit, grabbed at the window's own size."""
MIN_CASES = 10
TIMEOUT = 1200
"""Guard against a hung GUI (FreeCAD under Xvfb without a window manager), not a timing
check: the run takes about 1 min of CPU, longer in wall-clock on a loaded machine."""
MIN_PNG_BYTES = 10_000
"""A uniform 1024 x 768 PNG compresses to a few kB; a rendered model is far larger."""

XVFB_RUN = shutil.which("xvfb-run")
FREECAD = shutil.which("freecad")


def _png_size(path):
    """(width, height) from a PNG's IHDR chunk."""
    with open(path, "rb") as handle:
        head = handle.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG file"
    return struct.unpack(">II", head[16:24])


def _colour_figures(path):
    """(distinct colours, fraction of non-white pixels), or None without Pillow."""
    try:
        from PIL import Image
    except ImportError:
        return None
    with Image.open(path) as image:
        small = image.convert("RGB").resize((128, 96), Image.NEAREST)
        pixels = list(small.getdata())
    covered = sum(pixel != (255, 255, 255) for pixel in pixels) / len(pixels)
    return len(set(pixels)), covered


@pytest.mark.slow
@pytest.mark.skipif(XVFB_RUN is None or FREECAD is None,
                    reason="needs xvfb-run and the freecad GUI (apt install xvfb freecad)")
def test_workbench_in_real_gui():
    os.makedirs(OUTPUT, exist_ok=True)
    for name in SCREENSHOTS + WINDOW_GRABS:
        if os.path.exists(os.path.join(OUTPUT, name)):
            os.remove(os.path.join(OUTPUT, name))
    env = dict(os.environ, QTWEBENGINE_CHROMIUM_FLAGS="--no-sandbox",
               QTWEBENGINE_DISABLE_SANDBOX="1", POLYCUBE_GUI_OUTPUT=OUTPUT)
    command = [XVFB_RUN, "-a", "-s", "-screen 0 1280x1024x24", FREECAD,
               "-t", "TestPolycubeGui", "-M", REPO]
    process = subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        stdout, stderr = process.communicate()
        pytest.fail(f"the FreeCAD GUI did not finish within {TIMEOUT} s:\n"
                    f"{stdout[-3000:]}\n{stderr[-3000:]}")
    log = f"--- stdout ---\n{stdout[-6000:]}\n--- stderr ---\n{stderr[-3000:]}"
    assert process.returncode == 0, f"freecad exited {process.returncode}\n{log}"
    ran = re.search(r"^Ran (\d+) tests? in ", stdout, re.MULTILINE)
    assert ran, f"no unittest summary in the output\n{log}"
    assert int(ran.group(1)) >= MIN_CASES, log
    assert re.search(r"^OK\s*$", stdout, re.MULTILINE), log
    passed = re.findall(r"^test_\w+ \(polycube_gui_cases\w*\.\w+\.test_\w+\) \.\.\. .*?ok$",
                        stdout, re.MULTILINE | re.DOTALL)
    assert len(passed) == int(ran.group(1)), log
    for line in stdout.splitlines():  # the responsiveness figures, for pytest -s
        if "event-loop gap" in line or line.startswith("Esc "):
            print(line)
    for name in SCREENSHOTS:
        path = os.path.join(OUTPUT, name)
        assert os.path.isfile(path), f"screenshot {path} was not written\n{log}"
        assert os.path.getsize(path) > MIN_PNG_BYTES, f"{path} is nearly empty"
        assert _png_size(path) == (1024, 768)
        figures = _colour_figures(path)
        if figures is not None:
            colours, covered = figures
            cage = name in CAGE_SCREENSHOTS  # a wireframe: two colours, thin lines
            assert colours >= (2 if cage else 20), f"{path}: {colours} colours, looks empty"
            assert covered > (0.01 if cage else 0.03), \
                f"{path}: the model covers only {covered:.1%} of the view"
    for name in WINDOW_GRABS:
        path = os.path.join(OUTPUT, name)
        assert os.path.isfile(path) and os.path.getsize(path) > MIN_PNG_BYTES, path
