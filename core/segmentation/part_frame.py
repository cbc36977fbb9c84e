# SPDX-License-Identifier: LGPL-2.1-or-later
"""A part's own frame: PCA (paper Sect. 2.2, Eq. 1), surface moments and normal alignment.

A frame is a (3, 3) float64 array whose rows are the local x, y, z axes in world
coordinates: orthonormal and right-handed (``det == +1``).

PCA (Eq. 1) gives the axes as eigenvectors of a covariance sorted from the smallest to
the largest eigenvalue. Sign convention (deterministic, independent of vertex order):
x and y are flipped so that their world component of largest magnitude is positive
(the first such component on ties); z = x cross y.

Two point sets are offered for parts:

- ``"area"`` (default): the exact area-weighted covariance of the surface (integral of
  ``p p^T`` over the triangles). It does not depend on how densely a region is meshed.
- ``"vertices"``: Eq. 1 literally, the covariance of the part's vertices.

Where PCA leaves a rotation free (two eigenvalues within ``degenerate_tol`` of each
other, e.g. a square bar or a cube), the free rotation is fixed by aligning the axes to
the face normals (closed-form minimum of the area-weighted cubic energy
``sum A (n.u)^2 (n.v)^2`` over the free angle); ``align_degenerate=False`` keeps plain PCA.

The frame choice (:mod:`core.segmentation.frame_choice`) and the automatic parts build on these
pieces; the blend of the part frames at interfaces is :mod:`core.segmentation.frames`.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from core.errors import ParameterError
from core.geometry import face_cross

DEFAULT_DEGENERATE_TOL = 0.1
FRAME_MODES = ("area", "vertices")

def orient_frame(axes):
    """Sign convention for rows x, y of (3, 3) ``axes``; z = x cross y."""
    out = np.array(axes, dtype=np.float64)
    for k in (0, 1):
        a = out[k]
        mag = np.abs(a)
        if a[int(np.argmax(mag > mag.max() - 1e-12))] < 0:
            out[k] = -a
    x, y = out[0], out[1]
    z = np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])
    out[2] = z / np.sqrt(z @ z)
    return out


def frame_from_covariance(cov):
    """PCA frame of a (3, 3) symmetric covariance.

    Returns
    -------
    frame : (3, 3) float64, rows x, y, z = eigenvectors for eigenvalues sorted ascending,
        oriented by the module's sign convention (right-handed).
    eigenvalues : (3,) float64 ascending.
    """
    cov = np.asarray(cov, dtype=np.float64)
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    return orient_frame(vecs.T), vals


def pca_frame(points, weights=None):
    """PCA frame of a point set (Eq. 1).

    Parameters
    ----------
    points : (k, 3) float64, k >= 1.
    weights : (k,) float64 non-negative, optional; uniform (Eq. 1) when omitted.

    Returns
    -------
    (3, 3) float64, rows x, y, z (smallest to largest variance), right-handed.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ParameterError(f"points must be a non-empty (k, 3) array, got shape {points.shape}")
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(points),) or (w < 0).any() or w.sum() <= 0:
        raise ParameterError("weights must be (k,) non-negative with a positive sum")
    mean = (w[:, None] * points).sum(axis=0) / w.sum()
    d = points - mean
    cov = (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0) / w.sum()
    return frame_from_covariance(cov)[0]


# ----------------------------------------------------------------------------------------
# additive surface moments (used for frames of parts and of unions of parts)

@dataclass
class SurfaceMoments:
    """Additive moments of a set of triangles.

    area : float, total area.
    first : (3,) integral of p dA.
    second : (3, 3) integral of p p^T dA.
    normal4 : (3, 3, 3, 3) sum over faces of area * n (x) n (x) n (x) n (unit normals).
    """

    area: float
    first: np.ndarray
    second: np.ndarray
    normal4: np.ndarray

    def __add__(self, other):
        return SurfaceMoments(self.area + other.area, self.first + other.first,
                              self.second + other.second, self.normal4 + other.normal4)

    def covariance(self):
        """(3, 3) area-weighted covariance of the surface."""
        mean = self.first / self.area
        return self.second / self.area - np.outer(mean, mean)


def face_geometry(vertices, faces):
    """Per-face area (m,), unit normal (m, 3) and second moment (m, 3, 3) about the origin."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    cross = face_cross(vertices, faces)
    dbl = np.linalg.norm(cross, axis=1)
    area = 0.5 * dbl
    normal = cross / np.where(dbl > 0, dbl, 1.0)[:, None]
    s = tri.sum(axis=1)
    second = (area / 12.0)[:, None, None] * (np.einsum("fki,fkj->fij", tri, tri)
                                             + s[:, :, None] * s[:, None, :])
    return area, normal, second


def group_moments(vertices, faces, group, n_groups, chunk=20000):
    """List of :class:`SurfaceMoments`, one per group of faces.

    group : (m,) int64 in [0, n_groups).
    """
    faces = np.asarray(faces, dtype=np.int64)
    group = np.asarray(group, dtype=np.int64)
    area_sum = np.zeros(n_groups)
    first = np.zeros((n_groups, 3))
    second = np.zeros((n_groups, 9))
    normal4 = np.zeros((n_groups, 81))
    for start in range(0, len(faces), chunk):
        sl = slice(start, start + chunk)
        area, normal, sec = face_geometry(vertices, faces[sl])
        centroid = np.asarray(vertices, dtype=np.float64)[faces[sl]].mean(axis=1)
        g = group[sl]
        ind = sp.csr_matrix((np.ones(len(g)), (g, np.arange(len(g)))), shape=(n_groups, len(g)))
        area_sum += ind @ area
        first += ind @ (area[:, None] * centroid)
        second += ind @ sec.reshape(-1, 9)
        n2 = normal[:, :, None] * normal[:, None, :]
        n4 = (n2[:, :, :, None, None] * n2[:, None, None, :, :]).reshape(-1, 81)
        normal4 += ind @ (area[:, None] * n4)
    return [SurfaceMoments(area_sum[g], first[g], second[g].reshape(3, 3),
                           normal4[g].reshape(3, 3, 3, 3)) for g in range(n_groups)]


def cubic_energy(normal4, frame):
    """Area-weighted cubic misalignment ``sum A (1 - sum_k (n.a_k)^4) / 2`` of normals.

    Zero when every normal is along an axis of ``frame``; ``normal4`` is a
    (3, 3, 3, 3) normal moment (see :class:`SurfaceMoments`).
    """
    t = normal4.reshape(9, 9)
    area = t[np.ix_([0, 4, 8], [0, 4, 8])].sum()
    sq = (np.asarray(frame)[:, :, None] * np.asarray(frame)[:, None, :]).reshape(3, 9)
    fourth = ((sq @ t) * sq).sum()
    return 0.5 * (area - fourth)


def _quartic(normal4, a, b, c, d):
    """Contraction ``sum T_ijkl a_i b_j c_k d_l`` of a (3, 3, 3, 3) moment."""
    left = np.outer(a, b).ravel()
    right = np.outer(c, d).ravel()
    return float(left @ normal4.reshape(9, 9) @ right)


def align_about(frame, axis, normal4):
    """Rotate ``frame`` about its row ``axis`` to minimise the cubic energy (closed form)."""
    i, j = [k for k in range(3) if k != axis]
    y, z = frame[i], frame[j]

    def m(p):
        return _quartic(normal4, *([y] * p + [z] * (4 - p)))

    m40, m31, m22, m13, m04 = m(4), m(3), m(2), m(1), m(0)
    alpha2 = 0.25 * (m04 - 2.0 * m22 + m40)
    beta2 = m22
    alphabeta = 0.5 * (m13 - m31)
    rc, rs = 0.5 * (beta2 - alpha2), alphabeta
    scale = abs(m40) + abs(m04) + abs(m22) + 1e-300
    if np.hypot(rc, rs) < 1e-9 * scale:
        return frame
    theta = (np.arctan2(rs, rc) + np.pi) / 4.0
    c, s = np.cos(theta), np.sin(theta)
    out = frame.copy()
    out[i] = c * y + s * z
    out[j] = -s * y + c * z
    return out


def align_degenerate_axes(frame, eigenvalues, normal4, tol=DEFAULT_DEGENERATE_TOL):
    """Fix the rotation PCA leaves free using the face normals.

    Parameters
    ----------
    frame : (3, 3) PCA frame (rows x, y, z, eigenvalues ascending).
    eigenvalues : (3,) ascending.
    normal4 : (3, 3, 3, 3) normal moment of the faces.
    tol : relative eigenvalue gap below which two axes count as degenerate.

    Returns
    -------
    (3, 3) float64 right-handed frame (rows keep their PCA order where PCA decides it).
    """
    lam = np.maximum(np.asarray(eigenvalues, dtype=np.float64), 0.0)
    top = max(lam[2], 1e-300)
    low_pair = (lam[1] - lam[0]) <= tol * max(lam[1], 1e-300)
    high_pair = (lam[2] - lam[1]) <= tol * top
    out = np.array(frame, dtype=np.float64)
    if low_pair and high_pair:
        for _ in range(3):
            for axis in range(3):
                out = align_about(out, axis, normal4)
    elif high_pair:
        out = align_about(out, 0, normal4)
    elif low_pair:
        out = align_about(out, 2, normal4)
    return orient_frame(out)


def frame_from_moments(moments, align_degenerate=True, tol=DEFAULT_DEGENERATE_TOL):
    """Part frame from :class:`SurfaceMoments` (area mode, see module docstring)."""
    frame, vals = frame_from_covariance(moments.covariance())
    if align_degenerate:
        frame = align_degenerate_axes(frame, vals, moments.normal4, tol)
    return frame


def part_frames(vertices, faces, face_part, mode="area", align_degenerate=True,
                tol=DEFAULT_DEGENERATE_TOL, moments=None):
    """PCA frame of every part.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64.
    face_part : (m,) int, parts 0 .. P-1, each non-empty.
    mode : ``"area"`` (default) or ``"vertices"`` (Eq. 1 literally), see module docstring.
    moments : optional list of P :class:`SurfaceMoments` of the parts (:func:`group_moments`),
        computed when omitted.

    Returns
    -------
    (P, 3, 3) float64 frames (rows x, y, z).
    """
    if mode not in FRAME_MODES:
        raise ParameterError(f"frame mode must be one of {FRAME_MODES}, got {mode!r}")
    face_part = np.asarray(face_part, dtype=np.int64)
    n_parts = int(face_part.max()) + 1
    if moments is None:
        moments = group_moments(vertices, faces, face_part, n_parts)
    frames = np.empty((n_parts, 3, 3))
    verts = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    for p in range(n_parts):
        if mode == "area":
            frame, vals = frame_from_covariance(moments[p].covariance())
        else:
            pts = verts[np.unique(faces[face_part == p])]
            frame, vals = frame_from_covariance(np.cov(pts.T, bias=False))
        if align_degenerate:
            frame = align_degenerate_axes(frame, vals, moments[p].normal4, tol)
        frames[p] = frame
    return frames
