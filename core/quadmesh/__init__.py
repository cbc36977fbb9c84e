# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh of a labelled target (paper Sect. 2.3).

:mod:`.base_mesh` chooses the route: the polycube layout (:mod:`.polycube`) or, where none
can be built, the paired decimation of the target (:mod:`.decimation`). The modules at this
level serve both routes: the orientation and self-crossing checks of a cage's limit surface,
its repair (:mod:`.limit_interpolation`, :mod:`.local_repair`) and the target's sharp feature
network (:mod:`.creases`, also used by the fit).
"""
from core.quadmesh.base_mesh import build_base_mesh

__all__ = ["build_base_mesh"]
