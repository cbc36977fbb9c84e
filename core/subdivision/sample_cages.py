# SPDX-License-Identifier: LGPL-2.1-or-later
"""Small closed base meshes (subdivision cages) for tests, benchmarks and demos.

Every cage is a :class:`core.types.PolyMesh` with faces counter-clockwise seen from
outside.
"""
import numpy as np

from core.types import PolyMesh


def cube(size=1.0):
    """Axis-aligned cube ``[0, size]^3``: 8 vertices of valence 3, 6 quads."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64) * size
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4],
             [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return PolyMesh.from_faces(v, faces)


def torus(n_major=8, n_minor=6, major_radius=2.0, minor_radius=0.8):
    """Genus-1 quad torus: an ``n_major x n_minor`` grid, every vertex of valence 4."""
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    phi = 2 * np.pi * i / n_major
    theta = 2 * np.pi * j / n_minor
    ring = major_radius + minor_radius * np.cos(theta)
    v = np.stack([ring * np.cos(phi), ring * np.sin(phi), minor_radius * np.sin(theta)],
                 axis=-1).reshape(-1, 3)
    idx = lambda a, b: (a % n_major) * n_minor + (b % n_minor)  # noqa: E731
    faces = np.stack([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)],
                     axis=-1).reshape(-1, 4)
    return PolyMesh(v, faces.reshape(-1).astype(np.int64),
                    np.arange(0, 4 * len(faces) + 1, 4, dtype=np.int64))


def mixed_prism(radius=1.0, height=1.5):
    """Hexagonal prism with triangle-fan caps: tris and quads, valences 3, 4, 5 and 6.

    The top cap is a fan of 6 triangles (centre valence 6); the bottom cap is 4
    triangles and one quad around its centre (centre valence 5), which leaves one
    bottom rim vertex of valence 3.
    """
    ang = 2 * np.pi * np.arange(6) / 6
    rim = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(6)], axis=1)
    bottom = rim
    top = rim + [0, 0, height]
    v = np.vstack([bottom, top, [[0, 0, 0]], [[0, 0, height]]])
    cb, ct = 12, 13
    faces = [[k, (k + 1) % 6, 6 + (k + 1) % 6, 6 + k] for k in range(6)]
    faces += [[ct, 6 + k, 6 + (k + 1) % 6] for k in range(6)]
    faces += [[cb, (k + 1) % 6, k] for k in range(4)]
    faces += [[cb, 0, 5, 4]]
    return PolyMesh.from_faces(v, faces)


def pentagonal_prism(radius=1.0, height=1.0):
    """Prism over a regular pentagon: two pentagon caps (n-gons) and five quads."""
    ang = 2 * np.pi * np.arange(5) / 5
    rim = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(5)], axis=1)
    v = np.vstack([rim, rim + [0, 0, height]])
    faces = [[k, (k + 1) % 5, 5 + (k + 1) % 5, 5 + k] for k in range(5)]
    faces += [[4, 3, 2, 1, 0], [5, 6, 7, 8, 9]]
    return PolyMesh.from_faces(v, faces)


def voxel_cage(occupied, size=1.0):
    """Quad boundary of a union of unit voxels.

    Parameters
    ----------
    occupied : (a, b, c) bool array; the voxels must meet only face to face
        (no edge- or vertex-only contacts) so the boundary is 2-manifold.
    size : float, voxel edge length.

    Returns
    -------
    PolyMesh with quads oriented outward.
    """
    occ = np.pad(np.asarray(occupied, dtype=bool), 1)
    quads = []
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    for axis in range(3):
        for sign in (1, -1):
            nb = np.roll(occ, -sign, axis=axis)
            cells = np.argwhere(occ & ~nb)
            if not len(cells):
                continue
            u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
            corners = np.repeat(cells[:, None, :], 4, axis=1).astype(np.int64)
            corners[:, :, u_ax] += unit[:, 0]
            corners[:, :, v_ax] += unit[:, 1]
            if sign > 0:
                corners[:, :, axis] += 1
            else:
                corners = corners[:, ::-1]
            quads.append(corners)
    corners = np.concatenate(quads).reshape(-1, 3)
    uniq, inv = np.unique(corners, axis=0, return_inverse=True)
    fv = inv.reshape(-1).astype(np.int64)
    return PolyMesh((uniq - 1).astype(np.float64) * size, fv,
                    np.arange(0, len(fv) + 1, 4, dtype=np.int64))


def genus3_block(size=1.0):
    """A 7 x 3 x 1 voxel slab with three square holes: a genus-3 quad cage."""
    occ = np.ones((7, 3, 1), dtype=bool)
    occ[1, 1, 0] = occ[3, 1, 0] = occ[5, 1, 0] = False
    return voxel_cage(occ, size)


def grid_sphere(n=4):
    """Cube whose faces are ``n x n`` quad grids projected halfway to a sphere.

    8 valence-3 vertices, everything else valence 4: a scalable all-quad cage with
    ``6 n^2`` faces for benchmarks.
    """
    box = voxel_cage(np.ones((n, n, n), dtype=bool), size=2.0 / n)
    v = box.vertices - 1.0
    r = np.linalg.norm(v, axis=1, keepdims=True)
    v = 0.5 * v + 0.5 * np.sqrt(3.0) * 0.8 * v / r
    return PolyMesh(v, box.face_vertices, box.face_offsets)
