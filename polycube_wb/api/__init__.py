# SPDX-License-Identifier: LGPL-2.1-or-later
"""Scripting API: the same operations as the CLI, as functions for FreeCADCmd scripts.

One namespace for four roles (``from polycube_wb import api; api.make_target(...)``):

- :mod:`.headless`: files in, files and a report out (``reconstruct_to_step``,
  ``subd_to_solid``, ``check``);
- :mod:`.factories`: the parametric stage objects (``make_target`` ... ``make_deviation``);
- :mod:`.operations`: what scripts and the GUI do with a document of stage objects (find,
  chain, edit, recompute as one undo step, describe);
- :mod:`.plain_document`: the non-parametric way to fill a document (``reconstruct``,
  ``import_subd_cage``, ``export_step``).

Functions that build solids import FreeCAD themselves, so ``import polycube_wb.api``
works in any Python; call them where ``import FreeCAD`` works (freecadcmd, the GUI,
or the project's .venv).
"""
from polycube_wb.api.factories import (make_base_mesh, make_deviation, make_fit,
                                       make_segmentation, make_solid, make_target,
                                       read_ahead_target)
from polycube_wb.api.headless import check, reconstruct_to_step, subd_to_solid
from polycube_wb.api.operations import (STAGE_ORDER, RecomputeOutcome, describe, find_stage,
                                        is_reusable, make_chain, move_cage_vertices, recompute,
                                        run_in_transaction, stage_kind, upstream_objects)
from polycube_wb.api.plain_document import export_step, import_subd_cage, reconstruct
from polycube_wb.stage_jobs import read_target_file

__all__ = ["STAGE_ORDER", "RecomputeOutcome", "check", "describe", "export_step", "find_stage",
           "import_subd_cage", "is_reusable", "make_base_mesh", "make_chain", "make_deviation",
           "make_fit", "make_segmentation", "make_solid", "make_target", "move_cage_vertices",
           "read_ahead_target", "read_target_file", "recompute", "reconstruct",
           "reconstruct_to_step", "run_in_transaction", "stage_kind", "subd_to_solid",
           "upstream_objects"]
