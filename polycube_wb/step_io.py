# SPDX-License-Identifier: LGPL-2.1-or-later
"""STEP files (AP214, millimetres, named product): atomic write, read, round-trip check.

FreeCAD 0.20.2's ``Part.read`` picks the reader from the file extension, so STEP files
must end in ``.step`` or ``.stp`` (any case); the temporary file written next to the
target gets a ``.step`` suffix for the same reason.
"""
import os

import FreeCAD  # noqa: F401  (importing Part before FreeCAD segfaults in 0.20.2)
import Part

from core.errors import ExportError, ParameterError, PolycubeInputError, StepPathError
from core.output_files import atomic_output, check_output_path, write_text_atomic

STEP_SUFFIXES = (".step", ".stp")


def write_step(shape, path, input_paths=(), overwrite=True, name=None):
    """Write ``shape`` to an AP214 STEP file (millimetres) atomically, with OpenCascade.

    The file is written to a temporary file in the target folder, flushed to disk, then
    moved over ``path`` with ``os.replace``; on any failure the temporary file is removed
    and an existing ``path`` is left untouched.

    Parameters
    ----------
    shape : Part.Shape
        Non-null shape to export (units: model units, written as millimetres).
    path : str or os.PathLike
        Target file, ending in ``.step`` or ``.stp``.
    input_paths : iterable of str or os.PathLike
        Files the result was computed from; writing over any of them is refused.
    overwrite : bool
        If False, an existing ``path`` is an error.
    name : str or None
        Product name; default the file name without its suffix.

    Returns
    -------
    str
        Absolute path of the written file.

    Raises
    ------
    StepPathError
        Wrong suffix, folder missing or not writable, ``path`` is a folder, an input
        file or (with ``overwrite=False``) exists.
    ExportError
        The shape is null or OpenCascade fails to write it.
    """
    target, input_paths = _checked_target(path, input_paths, overwrite)
    if shape is None or shape.isNull():
        raise ExportError("cannot write a null shape to STEP")
    for key, value in (("write.step.schema", "AP214IS"), ("write.step.unit", "MM"),
                       ("write.step.product.name", _product_name(target, name))):
        Part.setStaticValue(key, value)
    with atomic_output(target, input_paths, "STEP file") as temp:
        try:
            shape.exportStep(temp)
        except Part.OCCError as exc:
            raise ExportError(f"OpenCascade failed to write STEP for {target}: {exc}") from exc
        if os.path.getsize(temp) == 0:
            raise ExportError(f"OpenCascade wrote an empty STEP file for {target}")
    return target


def write_solid_step(built, patchset, path, input_paths=(), overwrite=True, name=None,
                     ahead=None):
    """Write a solid from :func:`polycube_wb.brep.make_solid` to an AP214 STEP file.

    A solid built from shared edges is written directly from its patches and topology
    (``core.export.step_file``: the same vertices, edges and faces, millimetres, the
    product ``name``), atomically; a sewn solid goes through :func:`write_step`.

    Parameters
    ----------
    built : polycube_wb.brep.BuiltSolid
    patchset : core.types.PatchSet the solid was built from.
    path, input_paths, overwrite, name : as in :func:`write_step`.
    ahead : None, or the :func:`step_text_ahead` of ``patchset`` and ``name``: its text is
        written where it is the one this function would make (the solid was built from the
        patch set's shared edges, oriented alike), else it is ended and the text made here.

    Returns
    -------
    str, absolute path of the written file.
    """
    if built.topology is None:
        if ahead is not None:
            ahead.cancel()
        return write_step(built.solid, path, input_paths, overwrite, name)
    from core.export.step_file import step_text
    from core.tolerances import BREP_MM

    target, inputs = _checked_target(path, input_paths, overwrite)
    product = _product_name(target, name)
    text = None
    if ahead is not None:
        made = ahead.result() if built.topology is patchset.topology else None
        ahead.cancel()
        if made is not None and made[:2] == (built.reverse, product):
            text = made[2]
    if text is None:
        text = step_text(patchset.patches, built.topology, product, BREP_MM, built.reverse,
                         light=_light(patchset))
    try:
        write_text_atomic(target, text, inputs, "STEP file")
    except ParameterError as exc:
        raise StepPathError(str(exc)) from exc
    return target


def step_text_ahead(patchset, name):
    """The STEP text of the solid :func:`polycube_wb.brep.make_solid` builds from the shared
    edges of ``patchset`` (its ``topology``, not None), with the product ``name`` (a
    non-empty str), made ahead on another core (:class:`core.forked.Ahead`) while the solid is
    built and checked; for the ``ahead`` of :func:`write_solid_step`."""
    from core.forked import Ahead

    return Ahead(_shared_edge_step_text, patchset.patches, patchset.topology, str(name),
                 _light(patchset))


def _light(patchset):
    """Whether the STEP text of ``patchset`` is written light (``core.export.step_file``):
    the G1 export, which departs from the limit surface far more than the rounding."""
    return patchset.info.get("export") == "g1"


def _shared_edge_step_text(patches, topology, name, light):
    """``(reverse, name, text)``: the orientation ``make_solid`` gives the solid (the sign of
    the patches' enclosed volume) and the STEP text of that solid."""
    from core.export.bspline_tessellation import enclosed_volume
    from core.export.step_file import step_text
    from core.tolerances import BREP_MM

    reverse = bool(enclosed_volume(patches) < 0)
    return reverse, name, step_text(patches, topology, name, BREP_MM, reverse, light=light)


def _checked_target(path, input_paths, overwrite):
    """(absolute STEP target path, tuple of inputs), or StepPathError (suffix, folder,
    input, overwrite)."""
    target = _step_path(path)
    if isinstance(input_paths, (str, bytes, os.PathLike)):
        input_paths = (input_paths,)
    try:
        check_output_path(target, input_paths, "STEP file")
    except ParameterError as exc:
        raise StepPathError(str(exc)) from exc
    if os.path.exists(target) and not overwrite:
        raise StepPathError(f"{target} exists and overwrite=False")
    return target, tuple(input_paths)


def _product_name(target, name):
    """The product name: ``name``, else the file name without its suffix."""
    if name:
        return str(name)
    return os.path.splitext(os.path.basename(target))[0]


def read_step(path):
    """Read a STEP file into a Part shape.

    Parameters
    ----------
    path : str or os.PathLike
        Existing file ending in ``.step`` or ``.stp``.

    Returns
    -------
    Part.Shape
        A ``Solid`` for a one-solid file, otherwise a ``Compound``.

    Raises
    ------
    StepPathError
        Wrong suffix, or the file does not exist or is not readable.
    PolycubeInputError
        The file is not valid STEP or contains no shape.
    """
    source = _step_path(path)
    if not os.path.isfile(source):
        raise StepPathError(f"cannot read {source}: no such file")
    if not os.access(source, os.R_OK):
        raise StepPathError(f"cannot read {source}: not readable")
    try:
        shape = Part.read(source)
    except (RuntimeError, OSError) as exc:
        raise PolycubeInputError(f"cannot read STEP file {source}: {exc}") from exc
    if shape.isNull():
        raise PolycubeInputError(f"STEP file {source} contains no shape")
    return shape


def step_round_trip(shape, path, rel_volume_tol=1e-6):
    """Compare a shape with what a STEP file holds (faces, validity, volume).

    Parameters
    ----------
    shape : Part.Shape
        The shape that was written.
    path : str or os.PathLike
        The STEP file to read back.
    rel_volume_tol : float
        Allowed ``|V_read - V_written| / |V_written|``.

    Returns
    -------
    dict
        ``faces_written``, ``faces_read``, ``solids_read`` (int), ``valid_read`` (bool),
        ``volume_written``, ``volume_read``, ``volume_rel_error`` (float) and ``ok``
        (bool: same face count, one valid solid per written solid, volume within
        ``rel_volume_tol``).
    """
    read = read_step(path)
    written_volume = float(shape.Volume)
    read_volume = float(read.Volume)
    scale = abs(written_volume) if written_volume else 1.0
    rel_error = abs(read_volume - written_volume) / scale
    report = {
        "faces_written": len(shape.Faces),
        "faces_read": len(read.Faces),
        "solids_written": len(shape.Solids),
        "solids_read": len(read.Solids),
        "valid_read": bool(read.isValid()),
        "volume_written": written_volume,
        "volume_read": read_volume,
        "volume_rel_error": rel_error,
    }
    report["ok"] = (report["faces_read"] == report["faces_written"]
                    and report["solids_read"] == report["solids_written"]
                    and report["valid_read"] and rel_error <= rel_volume_tol)
    return report


def _step_path(path):
    """Absolute path with a STEP suffix, or StepPathError."""
    text = os.path.abspath(os.fspath(path))
    if not text.lower().endswith(STEP_SUFFIXES):
        raise StepPathError(f"STEP file name must end in .step or .stp, got {text}")
    return text

