# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quadric-error decimations of one target to any number of triangles.

QSlim (Garland & Heckbert, "Surface simplification using quadric error metrics", SIGGRAPH 1997;
libigl's ``igl.qslim``) collapses edges in quadric-error order and refuses collapses that would
change the topology. Its quadrics are those of the mesh it is given, which matters twice:

- decimated again, a coarse result gives more even triangles, and the paired cages of them fit
  SIMP results closer than when each budget is decimated from the target. So budgets up to
  ``coarse_triangles`` start from one coarse decimation, as the budget ladder of the pairing always
  did;
- but a coarse result has lost the small features: QSlim of a coarse result of a machined
  part folds stepped holes into their walls, where QSlim of the target does not. Larger budgets
  therefore start from the target, or for large targets
  from one fine decimation of it (:data:`SOURCE_TRIANGLES`), which keeps each one quick.

The coarse decimation of a very large target (:data:`REDUCE_ABOVE`) starts from a reduction by
shortest-edge collapses: QSlim of the whole target costs twice as much. Larger budgets keep
QSlim's fine decimation, whose quadrics keep thin members.
"""
import numpy as np

from core.errors import InvalidMeshError
from core.mesh_topology import connected_face_components, genus_of

SOURCE_TRIANGLES = 20000
"""Targets with more triangles are decimated to this many once, when a decimation larger than
the coarse one is first asked for; those then start from it, which makes each further
decimation several times faster on a fine target, and its results no more tangled than QSlim
of the target itself."""
REDUCE_ABOVE = 100000
"""The coarse decimation of targets with more triangles starts from their reduction to
:data:`SOURCE_TRIANGLES` by shortest-edge collapses (``igl.decimate``: a collapsed edge becomes
its midpoint; collapses that would change the topology are refused). On a very fine target
this is much faster than QSlim of the whole target, and its paired cage, a little larger,
follows the target closer. Smaller targets keep QSlim's own quadrics (there the reduction
needed more budgets of the ladder), and so do the larger budgets: from the reduction, the
cages of a thin-walled SIMP result kept crossing themselves where those from QSlim's fine
decimation did not."""


class Decimation:
    """QSlim of one closed, outward 2-manifold target to any triangle count.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 the target.
    coarse_triangles : int or None: counts up to this start from the decimation to this many
        triangles (module docstring), larger ones from the target (None: all from the target).

    Raises
    ------
    InvalidMeshError (from :meth:`triangles` and here) when a decimation changed the genus:
    both decimations refuse such collapses, so this means a defect in the input the intake did
    not catch.
    """

    def __init__(self, vertices, faces, coarse_triangles=None):
        self._target = (np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
        self._components = int(connected_face_components(self._target[1]).max()) + 1
        self._genus = genus_of(len(self._target[0]), self._target[1], self._components)
        self._results = {}
        self._fine = None
        self._coarse = None
        if coarse_triangles is not None and coarse_triangles < len(self._target[1]):
            start = self._target
            if len(self._target[1]) > REDUCE_ABOVE:
                import igl

                start = self._checked(*igl.decimate(*self._target, SOURCE_TRIANGLES)[:2])
            self._coarse = self._qslim(*start, coarse_triangles)

    @property
    def fine_source(self):
        """``(vertices, faces)`` the decimations larger than the coarse one start from: the
        target, or its decimation to :data:`SOURCE_TRIANGLES` (made on first use)."""
        if self._fine is None:
            self._fine = (self._qslim(*self._target, SOURCE_TRIANGLES)
                          if len(self._target[1]) > SOURCE_TRIANGLES else self._target)
        return self._fine

    def triangles(self, count):
        """The decimation to at most ``count`` triangles (all of them if there are fewer).

        Returns ``(vertices, faces)``: (n', 3) float64 and (m', 3) int64, closed, outward, the
        target's genus. The same count gives the same (cached) arrays.
        """
        count = int(count)
        if self._coarse is not None and count <= len(self._coarse[1]):
            source = self._coarse
        elif count >= len(self._target[1]):
            return self._target
        else:
            source = self.fine_source
        if count >= len(source[1]):
            return source
        if count not in self._results:
            self._results[count] = self._qslim(*source, count)
        return self._results[count]

    def _qslim(self, vertices, faces, count):
        import igl

        vertices, faces, _, _ = igl.qslim(vertices, faces, count)
        return self._checked(vertices, faces)

    def _checked(self, vertices, faces):
        """``(vertices, faces)`` as float64 and int64 arrays, their genus checked."""
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        if genus_of(len(vertices), faces, self._components) != self._genus:
            raise InvalidMeshError("the decimated target changed its genus; the input surface "
                                   "is not a clean 2-manifold")
        return vertices, faces
