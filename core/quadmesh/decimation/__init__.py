# SPDX-License-Identifier: LGPL-2.1-or-later
"""The decimation route of the base mesh, used where no polycube layout can be built: the
target decimated to triangles (quadric, feature-preserving or fold-free), evened out and
paired into quads (:mod:`.paired_decimation`). It needs no labeling."""
