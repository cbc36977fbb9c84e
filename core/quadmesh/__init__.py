# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh of a labelled target (paper Sect. 2.3; see :mod:`.base_mesh`)."""
from core.quadmesh.base_mesh import build_base_mesh

__all__ = ["build_base_mesh"]
