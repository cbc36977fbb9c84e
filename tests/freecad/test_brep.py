# SPDX-License-Identifier: LGPL-2.1-or-later
"""PatchSet -> FreeCAD solid -> STEP, on hand-built closed patch sets."""
import os
import shutil
import tempfile

import numpy as np
import pytest

import FreeCAD  # noqa: F401  (must precede Part)
import Part

from core.errors import ExportError, InvalidMeshError, PolycubeInputError, StepPathError
from core.quality import is_watertight_manifold
from core.types import PatchSet
from polycube_wb.brep import make_solid, patches_to_solid, solid_report, tessellate
from polycube_wb.convert import arrays_to_mesh, mesh_to_arrays
from polycube_wb.step_io import read_step, step_round_trip, write_step
from synthetic_patches import divergence_volume, lattice_patchset, superellipsoid_map


@pytest.fixture(scope="module")
def curved():
    """24 bicubic patches (interior knot) on a superellipsoid-like closed surface."""
    patchset = lattice_patchset(2, superellipsoid_map(exponent=4.0, radius=1.5))
    return patchset, patches_to_solid(patchset)


@pytest.mark.parametrize("m", [1, 2])
def test_cube_patches_give_valid_closed_solid(m):
    patchset = lattice_patchset(m, half_size=1.5)
    report = solid_report(patches_to_solid(patchset))
    assert report["valid"] and report["closed"]
    assert report["shells"] == 1
    assert report["faces"] == len(patchset.patches) == 6 * m * m
    assert report["volume"] == pytest.approx(27.0, rel=1e-12)
    assert report["area"] == pytest.approx(54.0, rel=1e-12)


def test_divergence_volume_reference_is_exact_on_a_cube():
    assert divergence_volume(lattice_patchset(3, half_size=0.5)) == pytest.approx(1.0, rel=1e-12)


def test_curved_solid_volume_matches_independent_quadrature(curved):
    patchset, solid = curved
    report = solid_report(solid)
    assert report["valid"] and report["closed"] and report["faces"] == 24
    reference = divergence_volume(patchset)
    assert abs(report["volume"] - reference) / reference < 1e-3


def test_inward_patches_still_give_outward_solid(curved):
    patchset, solid = curved
    flipped = lattice_patchset(2, superellipsoid_map(exponent=4.0, radius=1.5))
    for patch in flipped.patches:
        patch.poles = patch.poles[::-1].copy()
    result = patches_to_solid(flipped)
    assert result.isValid()
    assert result.Volume == pytest.approx(solid.Volume, rel=1e-9)


def test_tessellation_is_watertight_outward_and_within_deflection(curved):
    _, solid = curved
    V, F = tessellate(solid, 1e-3)
    assert V.dtype == np.float64 and F.dtype == np.int64 and F.shape[1] == 3
    assert is_watertight_manifold(V, F)
    tri = V[F]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    # every triangle is within the 1e-3 deflection of the surface, so the volumes
    # differ by at most about deflection x area
    assert abs(volume - solid.Volume) <= 1e-3 * solid.Area


def test_step_round_trip_keeps_faces_validity_and_volume(curved, tmp_path):
    _, solid = curved
    path = write_step(solid, tmp_path / "out.step")
    assert path == str(tmp_path / "out.step")
    report = step_round_trip(solid, path)
    assert report["ok"], report
    shape = read_step(path)
    assert len(shape.Solids) == 1 and shape.isValid()
    assert len(shape.Faces) == 24
    assert abs(shape.Volume - solid.Volume) / solid.Volume < 1e-6


def test_atomic_write_overwrites_and_leaves_no_temp_files(curved, tmp_path):
    _, solid = curved
    target = tmp_path / "out.stp"
    target.write_text("old")
    write_step(solid, target)
    write_step(solid, target)
    assert os.listdir(tmp_path) == ["out.stp"]
    assert target.read_text().startswith("ISO-10303-21;")


def test_failed_write_keeps_old_file_and_removes_temp(tmp_path):
    class FailingShape:
        def isNull(self):
            return False

        def exportStep(self, path):
            with open(path, "w") as stream:
                stream.write("partial")
            raise Part.OCCError("simulated failure")

    target = tmp_path / "out.step"
    target.write_text("old")
    with pytest.raises(ExportError, match="failed to write STEP"):
        write_step(FailingShape(), target)
    assert os.listdir(tmp_path) == ["out.step"]
    assert target.read_text() == "old"


def test_write_refuses_to_overwrite_an_input(curved, tmp_path):
    _, solid = curved
    source = tmp_path / "in.step"
    source.write_text("input")
    alias = tmp_path / "link.step"
    alias.symlink_to(source)
    for target in (source, tmp_path / "." / "in.step", alias):
        with pytest.raises(StepPathError, match="refusing to overwrite the input"):
            write_step(solid, target, input_paths=[source])
    assert source.read_text() == "input"
    with pytest.raises(StepPathError, match="refusing"):
        write_step(solid, source, input_paths=str(source))
    with pytest.raises(StepPathError, match="exists"):
        write_step(solid, source, overwrite=False)


def test_write_path_errors_are_clear(curved, tmp_path):
    _, solid = curved
    with pytest.raises(StepPathError, match="does not exist"):
        write_step(solid, tmp_path / "missing" / "out.step")
    with pytest.raises(StepPathError, match="must end in .step or .stp"):
        write_step(solid, tmp_path / "out.txt")
    with pytest.raises(ExportError, match="null shape"):
        write_step(Part.Shape(), tmp_path / "out.step")
    assert os.listdir(tmp_path) == []


UNPRIVILEGED_UID = 65534
"""``nobody``: root passes every permission check, so as root the write is tried by a
forked child running as this user."""


def _write_step_refusal(solid, target):
    """The ``StepPathError`` message of ``write_step(solid, target)``, or ``""`` when it
    wrote the file; as root, in a forked child running as ``UNPRIVILEGED_UID``."""
    def attempt():
        try:
            write_step(solid, target)
        except StepPathError as error:
            return str(error)
        return ""

    if os.geteuid() != 0:
        return attempt()
    read_end, write_end = os.pipe()
    child = os.fork()
    if child == 0:
        code = 1
        try:
            os.close(read_end)
            os.setgid(UNPRIVILEGED_UID)
            os.setuid(UNPRIVILEGED_UID)
            os.write(write_end, attempt().encode())
            code = 0
        finally:
            os._exit(code)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as pipe:
        message = pipe.read().decode()
    _, status = os.waitpid(child, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, "the child failed"
    return message


def test_write_into_read_only_folder_is_refused(curved):
    _, solid = curved
    folder = tempfile.mkdtemp(prefix="polycube_ro_")  # in /tmp: reachable by any user
    try:
        if os.geteuid() == 0:
            os.chown(folder, UNPRIVILEGED_UID, UNPRIVILEGED_UID)
        os.chmod(folder, 0o500)
        message = _write_step_refusal(solid, os.path.join(folder, "out.step"))
        assert "not writable" in message, message
        assert os.listdir(folder) == []
        os.chmod(folder, 0o700)
        assert _write_step_refusal(solid, os.path.join(folder, "out.step")) == ""
        assert os.path.getsize(os.path.join(folder, "out.step")) > 1000
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_read_step_errors(tmp_path):
    with pytest.raises(StepPathError, match="no such file"):
        read_step(tmp_path / "nothing.step")
    garbage = tmp_path / "garbage.step"
    garbage.write_text("not a step file")
    with pytest.raises(PolycubeInputError, match="cannot read STEP"):
        read_step(garbage)


def test_boundary_gap_raises_export_error_naming_the_patch():
    patchset = lattice_patchset(2, superellipsoid_map(exponent=4.0, radius=1.5))
    patchset.patches[5].poles[-1, 1:-1, 2] += 1e-5
    with pytest.raises(ExportError) as info:
        patches_to_solid(patchset)
    message = str(info.value)
    assert "2 free (open) B-rep edges" in message
    assert "patch 5 side u=max" in message
    assert "max pole distance 1e-05" in message


def test_missing_patch_raises_export_error():
    patchset = lattice_patchset(2)
    del patchset.patches[7]
    with pytest.raises(ExportError, match="not closed; 4 free"):
        patches_to_solid(patchset)


def test_solid_is_built_from_shared_edges_without_sewing(curved):
    patchset, solid = curved
    built = make_solid(patchset)
    assert built.figures["construction"] == "shared_edges"
    assert len(built.topology.edge_curves) == len(solid.Edges) == 48
    assert built.figures["edges"] == 48 and built.figures["faces"] == 24
    # every B-rep edge is one shape shared by its two faces, not two coincident copies
    uses = {}
    for face in solid.Faces:
        for edge in face.Edges:
            uses[edge.hashCode()] = uses.get(edge.hashCode(), 0) + 1
    assert sorted(set(uses.values())) == [2] and len(uses) == 48
    assert built.figures["volume"] == pytest.approx(divergence_volume(patchset), rel=1e-12)


def test_broken_topology_falls_back_to_sewing_and_says_so(curved):
    from core.export.brep_topology import topology_from_sides

    patchset, solid = curved
    topology = topology_from_sides(patchset.patches)
    topology.use_reversed[3] = not topology.use_reversed[3]
    broken = PatchSet(patchset.patches, patchset.face_of_patch, {}, topology)
    built = make_solid(broken)
    assert built.figures["construction"] == "sewn" and built.topology is None
    assert "not used once in each direction" in built.figures["construction_note"]
    assert built.solid.isValid() and len(built.solid.Faces) == 24
    assert built.solid.Volume == pytest.approx(solid.Volume, rel=1e-9)


def test_sewn_solids_are_written_as_ap214_millimetres_too(curved, tmp_path):
    from core.export.brep_topology import topology_from_sides
    from polycube_wb.step_io import write_solid_step

    patchset, solid = curved
    topology = topology_from_sides(patchset.patches)
    topology.use_reversed[3] = not topology.use_reversed[3]
    broken = PatchSet(patchset.patches, patchset.face_of_patch, {}, topology)
    built = make_solid(broken)
    path = write_solid_step(built, broken, tmp_path / "sewn.step", name="lattice")
    text = open(path).read()
    assert "AUTOMOTIVE_DESIGN" in text and "SI_UNIT(.MILLI.,.METRE.)" in text
    assert "PRODUCT('lattice" in text
    assert read_step(path).Volume == pytest.approx(solid.Volume, rel=1e-9)


def test_two_separate_closed_pieces_raise_export_error():
    first, second = lattice_patchset(1), lattice_patchset(1)
    for patch in second.patches:
        patch.poles = patch.poles + 5.0
    patchset = PatchSet(first.patches + second.patches, np.arange(12, dtype=np.int64))
    with pytest.raises(ExportError, match="the patches form 2 separate pieces"):
        patches_to_solid(patchset)


def test_malformed_patches_raise_export_error_naming_the_patch():
    patchset = lattice_patchset(1)
    patchset.patches[3].u_mults = np.array([4, 2, 4])
    with pytest.raises(ExportError, match=r"patch 3, u direction: sum of multiplicities 10"):
        patches_to_solid(patchset)
    patchset = lattice_patchset(1)
    patchset.patches[2].poles[1, 1, 0] = np.nan
    with pytest.raises(ExportError, match="patch 2: 1 poles are not finite"):
        patches_to_solid(patchset)
    with pytest.raises(ExportError, match="no patches"):
        patches_to_solid(PatchSet([], np.zeros(0, dtype=np.int64)))


def test_mesh_conversion_round_trip_and_bad_input():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V2, F2 = mesh_to_arrays(arrays_to_mesh(V, F))
    assert np.array_equal(V2, V) and np.array_equal(F2, F)
    with pytest.raises(InvalidMeshError, match="outside") as info:
        arrays_to_mesh(V, F + 1)
    assert info.value.reason == "format" and info.value.count == 3
    with pytest.raises(InvalidMeshError, match="non-finite"):
        arrays_to_mesh(np.where(V == 1, np.inf, V), F)
    with pytest.raises(InvalidMeshError, match="repeat a vertex"):
        arrays_to_mesh(V, np.vstack([F, [[0, 0, 1]]]))
