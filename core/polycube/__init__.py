# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polycube deformation of a labelled mesh and its wireframe (paper Sect. 2.3)."""
from core.polycube.deform import PartPolycube, PolycubeDeformation, polycube_deformation
from core.polycube.wireframe import Wireframe, extract_wireframe, straighten_wireframe

__all__ = ["PartPolycube", "PolycubeDeformation", "polycube_deformation", "Wireframe",
           "extract_wireframe", "straighten_wireframe"]
