# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quality checks of a result mesh against a target mesh (no FreeCAD).

- watertight, 2-manifold and consistently oriented (manifold3d and trimesh);
- containment: volumes of (result - target) and (target - result) from manifold3d
  booleans, as fractions of the target volume;
- two-sided surface distances: exact point-to-triangle distances from area-weighted
  samples (plus all vertices for the maxima) of one surface to the other, from one
  compiled :class:`core.target_surface.TargetSurface` per surface.

trimesh, manifold3d and libigl are imported only when a check needs them, so this module
imports in a Python that lacks them; a missing one gives an ImportError with an install
hint.
"""
import numpy as np

from core.errors import InvalidMeshError, ParameterError
from core.geometry import sample_surface, validate_triangles
from core.optional_imports import optional_module

def manifold_report(V, F):
    """Watertightness and manifoldness figures of a triangle mesh.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int

    Returns
    -------
    dict
        ``edges_watertight`` (bool, trimesh: every edge has exactly two faces),
        ``winding_consistent`` (bool, trimesh), ``manifold_status`` (str, manifold3d
        ``Error`` name, ``"NoError"`` when the mesh is an oriented closed 2-manifold),
        ``volume`` (float, signed, manifold3d; 0 when not a manifold) and ``genus``
        (int, None when not a manifold).
    """
    trimesh = optional_module("trimesh")
    V, F = validate_triangles(V, F)
    mesh = trimesh.Trimesh(V, F, process=False)
    solid = _to_manifold(V, F)
    status = solid.status().name
    return {
        "edges_watertight": bool(mesh.is_watertight),
        "winding_consistent": bool(mesh.is_winding_consistent),
        "manifold_status": status,
        "volume": float(solid.volume()),
        "genus": int(solid.genus()) if status == "NoError" else None,
    }


def is_watertight_manifold(V, F):
    """True if a triangle mesh is closed, 2-manifold and consistently oriented.

    Both trimesh (every edge shared by exactly two faces, consistent winding) and
    manifold3d (``Manifold(Mesh64(V, F)).status() == NoError`` and not empty) must agree.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int

    Raises
    ------
    InvalidMeshError
        The arrays are malformed (see ``validate_triangles``).
    ImportError
        manifold3d is not installed (the message says how to install it).
    """
    report = manifold_report(V, F)
    return (report["edges_watertight"] and report["winding_consistent"]
            and report["manifold_status"] == "NoError" and report["volume"] != 0)


def containment(result_V, result_F, target_V, target_F):
    """How much of the result lies outside the target and how much of the target it misses.

    Parameters
    ----------
    result_V, target_V : (n, 3) float
    result_F, target_F : (m, 3) int
        Closed, outward-oriented 2-manifold triangle meshes.

    Returns
    -------
    dict
        ``target_volume``, ``result_volume``, ``outside_volume`` = vol(result - target),
        ``uncovered_volume`` = vol(target - result) (model units cubed), and
        ``outside_volume_fraction``, ``uncovered_volume_fraction``: those two divided by
        the target volume.

    Raises
    ------
    InvalidMeshError
        A mesh is not a closed oriented 2-manifold (``non_manifold``) or encloses a
        negative or zero volume (``orientation``); the message names which mesh.
    ImportError
        manifold3d is not installed.
    """
    result = _checked_manifold(result_V, result_F, "result")
    target = _target_manifold(target_V, target_F)
    target_volume = float(target.volume())
    result_volume = float(result.volume())
    # one boolean: vol(A - B) = vol(A) - vol(A n B) for both differences
    common = float((result ^ target).volume())
    outside = max(result_volume - common, 0.0)
    uncovered = max(target_volume - common, 0.0)
    return {
        "target_volume": target_volume,
        "result_volume": result_volume,
        "outside_volume": outside,
        "uncovered_volume": uncovered,
        "outside_volume_fraction": outside / target_volume,
        "uncovered_volume_fraction": uncovered / target_volume,
    }


def surface_distances(result_V, result_F, target_V, target_F, samples=20000, seed=0,
                      resolution=1e-4):
    """Two-sided distances between two triangle surfaces, as fractions of the target size.

    Parameters
    ----------
    result_V, target_V : (n, 3) float
    result_F, target_F : (m, 3) int
    samples : int
        Area-weighted random points drawn on each surface (deterministic for a seed).
    seed : int
    resolution : float > 0
        Fraction of ``bbox_diagonal``: the maxima are found to within it.

    Returns
    -------
    dict
        ``result_to_target_mean`` / ``_max``: distance from points of the result to the
        target surface; ``target_to_result_mean`` / ``_max`` the other way; ``hausdorff``
        the larger maximum. All divided by ``bbox_diagonal``, the target's bounding-box
        diagonal (model units, also returned). Means are area-weighted averages over
        the random samples. Maxima are searched over every triangle, not samples
        (:func:`core.farthest.farthest_pieces`; also over the samples and vertices): the
        true one-sided Hausdorff distance lies between ``..._max`` and ``..._max_bound``,
        at most ``resolution`` apart. Random samples and vertices alone can miss the
        farthest point of a finely tessellated solid; the search over every triangle does
        not.
    """
    from core.target_surface import TargetSurface

    samples = int(samples)
    if samples < 1:
        raise ParameterError(f"samples must be a positive integer, got {samples}")
    result_V, result_F = validate_triangles(result_V, result_F, "result")
    target_V, target_F = validate_triangles(target_V, target_F, "target")
    diagonal = float(np.linalg.norm(target_V.max(axis=0) - target_V.min(axis=0)))
    if not diagonal > 0:
        raise InvalidMeshError("target: all vertices coincide (zero bounding box)",
                               "degenerate_faces")
    rng = np.random.default_rng(seed)
    result_points = sample_surface(result_V, result_F, samples, rng)
    target_points = sample_surface(target_V, target_F, samples, rng)
    target_surface = TargetSurface(target_V, target_F)
    result_surface = TargetSurface(result_V, result_F, "result")
    to_target = target_surface.nearest(np.vstack([result_points, result_V]))
    to_result = result_surface.nearest(np.vstack([target_points, target_V]))
    forward, forward_vertices = np.split(to_target.distance / diagonal, [samples])
    backward, backward_vertices = np.split(to_result.distance / diagonal, [samples])
    forward_far, backward_far = largest_distances(result_surface, target_surface,
                                                  resolution * diagonal)
    report = {
        "result_to_target_mean": float(forward.mean()),
        "result_to_target_max": float(max(forward.max(), forward_vertices.max(),
                                          forward_far.distance.max() / diagonal)),
        "result_to_target_max_bound": forward_far.largest_bound / diagonal,
        "target_to_result_mean": float(backward.mean()),
        "target_to_result_max": float(max(backward.max(), backward_vertices.max(),
                                          backward_far.distance.max() / diagonal)),
        "target_to_result_max_bound": backward_far.largest_bound / diagonal,
        "bbox_diagonal": diagonal,
        "samples": samples,
        "method": "exact point-to-triangle distance (compiled box tree, float64 closest "
                  "point on the triangle found): means at area-weighted samples, maxima "
                  "over every triangle to within the resolution",
        "resolution": float(resolution),
    }
    report["hausdorff"] = max(report["result_to_target_max"], report["target_to_result_max"])
    return report


def largest_distances(result_surface, target_surface, resolution):
    """The largest distance from the result to the target and from the target to the result,
    searched over every triangle of each (:func:`core.farthest.farthest_pieces`).

    Parameters
    ----------
    result_surface, target_surface : TargetSurface
    resolution : float > 0, model units: each largest distance is found to within it.

    Returns
    -------
    (forward, backward) : FarthestPieces of the result's triangles against the target and of
        the target's against the result (``distance.max()`` the largest distance found,
        ``largest_bound`` one no point exceeds).
    """
    from core.farthest import farthest_pieces

    forward = farthest_pieces(result_surface.vertices, result_surface.faces, target_surface,
                              np.inf, resolution)
    backward = farthest_pieces(target_surface.vertices, target_surface.faces, result_surface,
                               np.inf, resolution)
    return forward, backward


def point_surface_distance(points, V, F):
    """Exact Euclidean distance from each point to a triangle mesh.

    Parameters
    ----------
    points : (p, 3) float
    V : (n, 3) float64
    F : (m, 3) int64

    Returns
    -------
    (p,) float64, model units (closest points from :class:`core.target_surface.TargetSurface`).
    """
    from core.target_surface import TargetSurface

    return TargetSurface(V, F).nearest(points).distance


def _to_manifold(V, F):
    """``manifold3d.Manifold`` of validated float64 / int64 arrays (double precision)."""
    manifold3d = optional_module("manifold3d")
    mesh = manifold3d.Mesh64(np.ascontiguousarray(V, dtype=np.float64),
                             np.ascontiguousarray(F, dtype=np.uint64))
    return manifold3d.Manifold(mesh)


_LAST_TARGET = []
"""``[(key, Manifold)]``: the last target :func:`_target_manifold` made (a fit measures the
containment of every fit it makes against one target)."""


def _target_manifold(V, F):
    """:func:`_checked_manifold` of the target ``V``, ``F``, made again only when their bytes
    differ from the last target's (a Manifold is immutable)."""
    import hashlib

    V = np.ascontiguousarray(V)
    F = np.ascontiguousarray(F)
    digest = hashlib.blake2b(V.tobytes(), digest_size=32)
    digest.update(F.tobytes())
    key = (V.shape, V.dtype.str, F.shape, F.dtype.str, digest.digest())
    if not _LAST_TARGET or _LAST_TARGET[0][0] != key:
        _LAST_TARGET[:] = [(key, _checked_manifold(V, F, "target"))]
    return _LAST_TARGET[0][1]


def _checked_manifold(V, F, name):
    """Manifold of a mesh that must be a closed, outward-oriented 2-manifold."""
    V, F = validate_triangles(V, F, name)
    solid = _to_manifold(V, F)
    status = solid.status().name
    if status != "NoError" or solid.is_empty():
        raise InvalidMeshError(f"{name}: not a closed oriented 2-manifold (manifold3d: {status})",
                               "non_manifold")
    volume = solid.volume()
    if not volume > 0:
        raise InvalidMeshError(f"{name}: encloses volume {volume:.6g}; faces must be oriented "
                               "outward", "orientation")
    return solid
