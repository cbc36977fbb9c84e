# SPDX-License-Identifier: LGPL-2.1-or-later
"""Documents: results saved in an FCStd file reopen unchanged; the manifest parses."""
import os

import FreeCAD

from core.polymesh_io import write_polymesh
from core.subdivision import sample_cages

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def test_solid_and_target_survive_save_and_reopen(tmp_path):
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target
    from polycube_wb.api import subd_to_solid
    from polycube_wb.document import add_solid, add_target_mesh

    cage = tmp_path / "torus.obj"
    write_polymesh(cage, sample_cages.torus())
    solid, _ = subd_to_solid(cage, measure=False)
    target, _ = validate_target(*read_triangle_soup(os.path.join(REPO, "examples", "to_simp_cantilever.stl")))
    doc = FreeCAD.newDocument("PolycubeSaveTest")
    add_target_mesh(doc, target, "Target")
    add_solid(doc, solid, "Solid")
    path = str(tmp_path / "saved.FCStd")
    doc.saveAs(path)
    FreeCAD.closeDocument(doc.Name)
    reopened = FreeCAD.openDocument(path)
    try:
        shape = reopened.getObject("Solid").Shape
        assert shape.isValid() and len(shape.Faces) == 48
        assert abs(shape.Volume - solid.Volume) <= 1e-9 * solid.Volume
        assert reopened.getObject("Target").Mesh.CountFacets == len(target.faces)
    finally:
        FreeCAD.closeDocument(reopened.Name)


def test_package_manifest_parses():
    meta = FreeCAD.Metadata(os.path.join(REPO, "package.xml"))
    workbench = meta.Content["workbench"][0]
    assert meta.Name == "Polycube" and workbench.Classname == "PolycubeWorkbench"
    assert os.path.isfile(os.path.join(REPO, meta.Icon))
    with open(os.path.join(REPO, "InitGui.py"), encoding="utf-8") as handle:
        assert f"class {workbench.Classname}" in handle.read() or \
            workbench.Classname in open(os.path.join(REPO, "polycube_wb", "gui", "workbench.py")).read()
