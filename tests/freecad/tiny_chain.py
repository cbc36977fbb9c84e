# SPDX-License-Identifier: LGPL-2.1-or-later
"""What the document tests on the tiny level-set cantilever share: its path, the stage
object kinds of the whole chain, and a recorder of which stage objects run."""
import os

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TINY = os.path.join(REPO, "..", "shared", "data", "meshes", "to_levelset_cantilever_tiny.stl")
KINDS = ("Target", "Segmentation", "BaseMesh", "Fit", "Solid", "Deviation")
"""Stage object kinds of the whole chain, in pipeline order."""


def record_runs(objects):
    """The list the names of ``objects`` are appended to when their stage runs
    synchronously (their proxy's ``run``)."""
    ran = []
    for obj in objects:
        original = obj.Proxy.run

        def run(o, progress, original=original):
            ran.append(o.Name)
            return original(o, progress)

        obj.Proxy.run = run
    return ran
