# SPDX-License-Identifier: LGPL-2.1-or-later
"""Parts stage: split the target into parts, each labelled in its own frame (paper Sect. 2.1)."""
import json

import numpy as np

from core.errors import ParameterError
from core.types import PartsResult


def run_parts(intake, params, progress):
    """The part of every face: one part, the user's parts, or automatic skeleton parts.

    Parameters
    ----------
    intake : core.types.IntakeResult.
    params : core.params.ReconstructionParams (``parts``, ``parts_file``).
    progress : core.progress.Progress.

    Returns
    -------
    core.types.PartsResult; with ``parts="single"`` every connected component (kept with
    ``components="all"``) is its own part.
    """
    from core.mesh_topology import connected_face_components
    from core.segmentation.parts import single_part
    from core.segmentation.skeleton_parts import skeleton_segmentation

    mesh = intake.surface
    if params.parts == "single":
        face_part = connected_face_components(mesh.faces).astype(np.int32)
        if face_part.max() == 0:
            face_part = single_part(mesh)
        return PartsResult(face_part, {"mode": "single", "parts": int(face_part.max()) + 1})
    if params.parts == "file":
        face_part = parts_from_file(mesh, params.parts_file)
        return PartsResult(face_part, {"mode": "file", "file": params.parts_file,
                                       "parts": int(face_part.max()) + 1})
    result = skeleton_segmentation(mesh)
    return PartsResult(result.face_part, {"mode": "auto", **result.info})


def read_parts_file(path):
    """The user's part specification from a JSON file (see ``ReconstructionParams.parts_file``).

    Returns
    -------
    ``(kind, value)``: ``kind`` is the file's one key, ``face_part``, ``groups`` or
    ``planes``; ``value`` its (m,) array or list.

    Raises
    ------
    ParameterError when the file cannot be read, holds not exactly one of the keys, or a
    ``groups`` / ``planes`` value that is not a list.
    """
    try:
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"cannot read the parts file {path}: {exc}") from exc
    kinds = [key for key in ("face_part", "groups", "planes") if isinstance(data, dict) and key in data]
    if len(kinds) != 1:
        raise ParameterError(f"the parts file {path} must hold exactly one of the keys "
                             "'face_part', 'groups' or 'planes'")
    value = data[kinds[0]]
    if kinds[0] != "face_part" and not isinstance(value, list):
        raise ParameterError(f"the parts file {path}: '{kinds[0]}' must be a list, got {value!r}")
    return kinds[0], np.asarray(value) if kinds[0] == "face_part" else value


def parts_from_file(mesh, path):
    """(m,) int32 face_part of ``mesh`` from the parts file ``path``; a ParameterError names
    the file."""
    from core.segmentation.parts import parts_from_face_groups, parts_from_planes, validate_face_part

    kind, value = read_parts_file(path)
    build = {"face_part": validate_face_part, "groups": parts_from_face_groups,
             "planes": parts_from_planes}[kind]
    try:
        return build(mesh, value)
    except ParameterError as exc:
        raise ParameterError(f"the parts file {path}: {exc}") from None
