# SPDX-License-Identifier: LGPL-2.1-or-later
"""Factories of the parametric stage objects (``make_*``): each adds one FeaturePython object
with its links and properties to a document, not yet recomputed
(:func:`polycube_wb.api.operations.recompute`)."""
import os

from polycube_wb.stage_jobs import read_target_file
from polycube_wb.view_hook import attach_view_provider


_STAGE_OBJECTS = {
    # kind: (FreeCAD type, proxy module, proxy class)
    "Target": ("Mesh::FeaturePython", "polycube_wb.objects.target", "TargetProxy"),
    "Segmentation": ("Mesh::FeaturePython", "polycube_wb.objects.segmentation",
                     "SegmentationProxy"),
    "BaseMesh": ("Part::FeaturePython", "polycube_wb.objects.base_mesh", "BaseMeshProxy"),
    "Fit": ("Part::FeaturePython", "polycube_wb.objects.fit", "FitProxy"),
    "Solid": ("Part::FeaturePython", "polycube_wb.objects.solid", "SolidProxy"),
    "Deviation": ("Mesh::FeaturePython", "polycube_wb.objects.deviation", "DeviationProxy"),
}


def _make(doc, kind, name, links, properties):
    """Add a stage object of ``kind`` with its links and properties set; returns it."""
    import importlib

    from core.errors import ParameterError

    type_name, module, cls = _STAGE_OBJECTS[kind]
    obj = doc.addObject(type_name, name)
    getattr(importlib.import_module(module), cls)(obj)
    for prop, value in links.items():
        setattr(obj, prop, value)
    for prop, value in properties.items():
        if prop not in obj.PropertiesList:
            known = ", ".join(sorted(obj.PropertiesList))
            doc.removeObject(obj.Name)
            raise ParameterError(f"{kind} has no property {prop!r}; its properties: {known}")
        setattr(obj, prop, value)
    attach_view_provider(obj, kind)
    return obj


def make_target(doc, source, name="Target", components="largest",
                check_self_intersections=True, repair=True):
    """Add a Target object holding a validated mesh (embedded in the document).

    Parameters
    ----------
    doc : App.Document
    source : path of a mesh file (STL, OBJ, PLY, OFF), a ``core.types.TriMesh``, or a
        ``Mesh::Feature`` (e.g. the plain target of a document made by an older version;
        its placement is applied).
    components, check_self_intersections, repair : as in ``core.validate.validate_target``
        (the command line's intake: the target holds the repaired mesh).

    Returns
    -------
    Mesh::FeaturePython, not yet recomputed (``doc.recompute()`` or :func:`recompute`).

    Raises
    ------
    InvalidMeshError
        The file cannot be read or the mesh is not a valid closed solid; nothing is added.
    """
    from core.types import TriMesh
    from core.validate import validate_target
    from polycube_wb.convert import arrays_to_mesh, mesh_to_arrays

    options = {"components": components, "check_self_intersections": check_self_intersections,
               "repair": repair}
    source_file, binary = "", None
    if isinstance(source, TriMesh):
        mesh, _ = validate_target(source.vertices, source.faces, name=name, **options)
    elif hasattr(source, "Mesh"):
        source_file = getattr(source, "PolycubeSource", "") or getattr(source, "SourceFile", "")
        mesh, _ = validate_target(*mesh_to_arrays(source.Mesh), name=source_file or name,
                                  **options)
    else:
        source_file = os.path.abspath(os.fspath(source))
        read = _READ_AHEAD.pop(_read_ahead_key(source_file, **options), None)
        if read is None:
            mesh = read_target_file(source_file, **options)
        else:
            mesh, binary = read.mesh, read.binary
    obj = _make(doc, "Target", name, {}, {"CheckSelfIntersections": check_self_intersections})
    obj.Mesh = arrays_to_mesh(mesh.vertices, mesh.faces, binary)
    obj.SourceFile = source_file
    return obj


_READ_AHEAD = {}
"""At most one ``polycube_wb.mesh_binary.MeshWithBinary`` read by :func:`read_ahead_target`,
by :func:`_read_ahead_key`."""


def read_ahead_target(path, components="largest", check_self_intersections=True, repair=True,
                      mesh=None, binary=None):
    """Read and validate a mesh file for the next :func:`make_target` of the same file.

    The GUI reads a file in its stage process (:func:`read_target_file`) and hands the mesh
    here as ``mesh``, with FreeCAD's binary mesh file of it written there as ``binary``
    (``polycube_wb.mesh_binary.binary_mesh``; FreeCAD's process then only reads it), then
    calls ``make_target`` (through the Python console, which shows the line to replay), which
    takes this mesh instead of reading the file again. A file changed since is read again.

    Raises
    ------
    InvalidMeshError
        As :func:`read_target_file` (when ``mesh`` is None).
    """
    from polycube_wb.mesh_binary import MeshWithBinary

    path = os.path.abspath(os.fspath(path))
    if mesh is None:
        mesh, binary = read_target_file(path, components, check_self_intersections, repair), None
    _READ_AHEAD.clear()
    _READ_AHEAD[_read_ahead_key(path, components, check_self_intersections, repair)] = \
        MeshWithBinary(mesh, binary)


def _read_ahead_key(path, components, check_self_intersections, repair):
    """What identifies a read: the file (its size and change time, None when it cannot be
    looked at) and the options."""
    try:
        info = os.stat(path)
    except OSError:
        return (path, None, components, bool(check_self_intersections), bool(repair))
    return (path, (info.st_size, info.st_mtime_ns), components, bool(check_self_intersections),
            bool(repair))


def make_segmentation(doc, target, name="Segmentation", **properties):
    """Add a Segmentation (parts, frames, HBECVT labeling) of ``target``.

    ``properties``: ``PartMode`` (``single``/``auto``), ``BlendFactor``, ``Lambda``,
    ``Penalty``, ``MaxSweeps``, ``Repair``, ``ColourBy``; defaults are the preferences,
    else the paper's values.
    """
    return _make(doc, "Segmentation", name, {"Target": target}, properties)


def make_base_mesh(doc, segmentation, name="BaseMesh", **properties):
    """Add a BaseMesh (polycube and coarse quad cage) built from ``segmentation``.

    ``properties``: ``TargetFaces``, ``MaxBaseFaces``.
    """
    return _make(doc, "BaseMesh", name, {"Segmentation": segmentation}, properties)


def make_fit(doc, cage, name="Fit", **properties):
    """Add a Fit of the cage object ``cage`` (a BaseMesh or a Fit) to its target.

    ``properties``: ``Iterations``, ``SubdivisionLevels``, ``Mode`` (``inside`` /
    ``nearest``), ``AutoMinThickness``, ``MinThickness`` (mm).
    """
    return _make(doc, "Fit", name, {"BaseMesh": cage}, properties)


def make_solid(doc, cage, name="Solid", **properties):
    """Add a Solid: the limit surface of the cage object ``cage`` as B-spline faces.

    ``properties``: ``Depth`` (grading at extraordinary vertices).
    """
    return _make(doc, "Solid", name, {"Cage": cage}, properties)


def make_deviation(doc, solid, target, name="Deviation", **properties):
    """Add a Deviation colour map (and check figures) of ``solid`` against ``target``.

    ``properties``: ``Tolerance`` (tessellation, fraction of the diagonal), ``Scale``.
    """
    return _make(doc, "Deviation", name, {"Solid": solid, "Target": target}, properties)
