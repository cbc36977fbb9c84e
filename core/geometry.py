# SPDX-License-Identifier: LGPL-2.1-or-later
"""Small geometric helpers shared by several stages."""
import numpy as np


def radius_classes(radius, max_classes=12):
    """Group triangles by bounding radius in halving classes for k-d tree searches.

    Class ``k`` holds radii in ``(r_max / 2^(k+1), r_max / 2^k]``; the last class takes
    everything smaller. Searching each class with its own largest radius keeps a few large
    triangles from widening the search for all.

    Parameters
    ----------
    radius : (t,) float64 bounding radius of each triangle (model units).
    max_classes : int, at most this many classes.

    Returns
    -------
    list of (k_i,) int64 index arrays, together a partition of ``range(t)``.
    """
    r_max = radius.max()
    if not r_max > 0:
        return [np.arange(len(radius))]
    level = np.floor(-np.log2(np.maximum(radius, np.finfo(float).tiny) / r_max))
    level = np.minimum(level, max_classes - 1).astype(np.int64)
    return [np.flatnonzero(level == value) for value in np.unique(level)]
