# SPDX-License-Identifier: LGPL-2.1-or-later
"""Wireframe of a deformed polycube and its straightening (paper Sect. 2.3, Fig. 4b-c).

The wireframe has a node at every corner (vertex with three or more chart-separating edges,
``charts.extract_layout``) and an edge along every chart boundary between two corners. A boundary
between charts with label axes ``a != b`` must run along the third axis ``c = 3 - a - b``: all its
vertices must have coordinate ``a`` equal to the plane of the axis-``a`` chart and coordinate ``b``
equal to the plane of the axis-``b`` chart. :func:`straighten_wireframe` sets those coordinates.
After :func:`core.polycube.deform.polycube_deformation` the charts are exactly planar, so this is
a no-op up to rounding; the deviation it reports measures that.

All positions are in part-frame coordinates (``PolycubeDeformation.local``). Boundaries between
two parts, or between charts with parallel labels (an invalid labeling), have no axis (-1) and
are left alone.
"""
from dataclasses import dataclass

import numpy as np

from core.errors import ParameterError
from core.segmentation.charts import boundary_chains, build_topology, extract_layout


@dataclass
class Wireframe:
    """Corners and boundary chains of a labelling.

    corners : (q,) int64 corner vertex indices, ascending.
    edges : (w, 2) int64 end vertices (mesh indices) of each boundary; equal for closed loops.
    chains : list of (len_i,) int64 vertex chains (first == last for closed loops).
    closed : (w,) bool boundaries that are loops without a corner.
    charts : (w, 2) int64 the two charts of each boundary.
    axis : (w,) int64 axis (0..2) each boundary must run along, -1 if undefined.
    """

    corners: np.ndarray
    edges: np.ndarray
    chains: list
    closed: np.ndarray
    charts: np.ndarray
    axis: np.ndarray


def extract_wireframe(F, face_part, face_label, n_vertices=None):
    """Wireframe of a labelling (topology only, no positions).

    Parameters
    ----------
    F : (m, 3) int faces.
    face_part, face_label : (m,) int part and label 0..5 of each face.
    n_vertices : int, optional number of vertices.

    Returns
    -------
    wireframe : Wireframe
    layout : ChartLayout the wireframe was built from.
    """
    F = np.asarray(F, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    face_label = np.asarray(face_label, dtype=np.int64)
    if face_part.shape != (len(F),) or face_label.shape != (len(F),):
        raise ParameterError(f"face_part and face_label must be ({len(F)},), got "
                             f"{face_part.shape} and {face_label.shape}")
    topology = build_topology(F, n_vertices)
    layout = extract_layout(topology, face_part, face_label)
    chains = boundary_chains(topology, layout)
    charts = layout.boundary_charts
    ax = layout.chart_label[charts] // 2
    same_part = layout.chart_part[charts[:, 0]] == layout.chart_part[charts[:, 1]]
    axis = np.where(same_part & (ax[:, 0] != ax[:, 1]), 3 - ax[:, 0] - ax[:, 1], -1)
    edges = np.array([[c[0][0], c[0][-1]] for c in chains], dtype=np.int64).reshape(-1, 2)
    closed = np.array([c[2] for c in chains], dtype=bool)
    return Wireframe(layout.corners, edges, [c[0] for c in chains], closed, charts, axis), layout


def straighten_wireframe(local, wireframe, layout, chart_plane):
    """Put every boundary chain on the line where its two chart planes meet.

    Parameters
    ----------
    local : (n, 3) float64 positions in part-frame coordinates.
    wireframe : Wireframe from :func:`extract_wireframe`; ``layout`` the ChartLayout returned
        with it.
    chart_plane : (c,) float64 plane coordinate of each chart along its label axis.

    Returns
    -------
    positions : (n, 3) float64 straightened copy of ``local``.
    deviation : (w,) float64 largest coordinate change on each boundary (0 where axis is -1).
    extent : (w,) float64 signed length of each open boundary along its axis (end - start);
        zero or sign changes between boundaries of one chart indicate a collapsed wireframe.
    """
    out = np.array(local, dtype=np.float64, copy=True)
    w = len(wireframe.chains)
    deviation = np.zeros(w)
    extent = np.zeros(w)
    label_axis = layout.chart_label // 2
    for i, chain in enumerate(wireframe.chains):
        if wireframe.axis[i] < 0:
            continue
        for chart in wireframe.charts[i]:
            k = label_axis[chart]
            deviation[i] = max(deviation[i], float(np.abs(out[chain, k] - chart_plane[chart]).max()))
            out[chain, k] = chart_plane[chart]
        extent[i] = out[chain[-1], wireframe.axis[i]] - out[chain[0], wireframe.axis[i]]
    return out, deviation, extent
