# SPDX-License-Identifier: LGPL-2.1-or-later
"""The polycube route of the base mesh (paper Sect. 2.3): the charts, sides and corners of a
labeling, their directions and integer lengths, the unit squares of every chart polygon as
quads, placed on the target. :mod:`core.quadmesh.base_mesh` chains these modules."""
