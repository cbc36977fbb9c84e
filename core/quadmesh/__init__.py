# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh from the polycube (paper Sect. 2.3, Fig. 4d)."""
from core.quadmesh.polycube_quads import base_mesh_from_polycube, mesh_statistics, polymesh_volume

__all__ = ["base_mesh_from_polycube", "mesh_statistics", "polymesh_volume"]
