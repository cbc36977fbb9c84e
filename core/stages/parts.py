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
    from core.segmentation.parts import parts_from_user, single_part, skeleton_segmentation

    mesh = intake.target
    if params.parts == "single":
        face_part = connected_face_components(mesh.faces).astype(np.int32)
        if face_part.max() == 0:
            face_part = single_part(mesh)
        return PartsResult(face_part, {"mode": "single", "parts": int(face_part.max()) + 1})
    if params.parts == "file":
        face_part = parts_from_user(mesh, read_parts_file(params.parts_file))
        return PartsResult(face_part, {"mode": "file", "file": params.parts_file,
                                       "parts": int(face_part.max()) + 1})
    result = skeleton_segmentation(mesh)
    return PartsResult(result.face_part, {"mode": "auto", **result.info})


def read_parts_file(path):
    """The user's part specification from a JSON file (see ``ReconstructionParams.parts_file``).

    Returns
    -------
    (m,) array for ``face_part``, else the ``groups`` or ``planes`` list as read.

    Raises
    ------
    ParameterError when the file cannot be read or holds not exactly one of the keys.
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
    return np.asarray(value) if kinds[0] == "face_part" else value
