# SPDX-License-Identifier: LGPL-2.1-or-later
"""Untangling of an embedded polycube layout (core.quadmesh.polycube.relax): the energy's
derivative, its barrier against folding, and folded quads of a cube cage unfolded with every
vertex kept on its face."""
import numpy as np
import pytest

from core.polymesh_checks import check_polymesh
from core.quadmesh.orientation import face_centre_operators
from core.quadmesh.polycube.relax import (corner_jacobians, folded_corners, quad_frames,
                                          untangle_on_target, untangling_energy)
from core.types import PolyMesh

pytestmark = pytest.mark.unit

N = 3
"""Quads along every edge of the cube cage."""


def cube_cage():
    """Closed quad cage of the unit cube, ``N`` x ``N`` quads per face, and (f, 3) the outward
    axis normal of every quad."""
    index, vertices, quads, normals = {}, [], [], []

    def vertex(point):
        key = tuple(np.round(point, 9))
        if key not in index:
            index[key] = len(vertices)
            vertices.append(point)
        return index[key]

    for axis in range(3):
        for side in (0.0, 1.0):
            u, v = [a for a in range(3) if a != axis]
            normal = np.zeros(3)
            normal[axis] = 1.0 if side else -1.0
            for i in range(N):
                for j in range(N):
                    corners = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        point = np.zeros(3)
                        point[axis], point[u], point[v] = side, (i + di) / N, (j + dj) / N
                        corners.append(point)
                    area = np.cross(corners[1] - corners[0], corners[3] - corners[0])
                    order = [0, 1, 2, 3] if area @ normal > 0 else [0, 3, 2, 1]
                    quads.append([vertex(corners[k]) for k in order])
                    normals.append(normal)
    quads = np.asarray(quads, dtype=np.int64)
    mesh = PolyMesh(np.asarray(vertices, dtype=np.float64), quads.reshape(-1),
                    np.arange(0, 4 * len(quads) + 1, 4, dtype=np.int64))
    return mesh, np.asarray(normals)


class OnCube:
    """Where the cage's vertices may move: a vertex inside a face within that face's plane
    (clipped to the face), a vertex on an edge of the cube nowhere."""

    def __init__(self, mesh, quad_normals):
        points = mesh.vertices
        on_bound = (np.isclose(points, 0.0) | np.isclose(points, 1.0))
        self.free = on_bound.sum(axis=1) == 1
        self.axis = np.argmax(on_bound, axis=1)
        self.quad_normals = quad_normals

    def project(self, positions, moved):
        out = np.array(positions)
        inside = np.clip(moved, 0.0, 1.0)
        rows = np.flatnonzero(self.free)
        keep = positions[rows, self.axis[rows]]
        out[rows] = inside[rows]
        out[rows, self.axis[rows]] = keep
        return out

    def directions(self, positions):
        out = np.zeros((len(positions), 2, 3))
        for row in np.flatnonzero(self.free):
            out[row] = np.eye(3)[[a for a in range(3) if a != self.axis[row]]]
        return out

    def normals(self, positions, quads):
        return self.quad_normals


def test_the_energy_derivative_matches_finite_differences():
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(6, 4, 2, 2))
    for eps in (1.0, 0.05):
        _, grad = untangling_energy(jac, eps)
        step = 1e-6
        numeric = np.zeros_like(jac)
        for idx in np.ndindex(jac.shape):
            up, down = jac.copy(), jac.copy()
            up[idx] += step
            down[idx] -= step
            numeric[idx] = (untangling_energy(up, eps)[0]
                            - untangling_energy(down, eps)[0]) / (2 * step)
        assert np.allclose(numeric, grad, rtol=1e-4, atol=1e-4 * np.abs(grad).max())


def test_a_folded_corner_costs_more_the_smaller_eps():
    square = np.eye(2)[None]
    mirrored = np.diag([1.0, -1.0])[None]
    assert untangling_energy(square, 1e-3)[0] == pytest.approx(2.0, rel=1e-2)
    costs = [untangling_energy(mirrored, eps)[0] for eps in (1.0, 0.1, 0.01)]
    assert costs[0] < costs[1] < costs[2] and costs[2] > 1e3


def folded_cube_cage():
    """The cube cage with a vertex inside its top face pushed past its diagonal neighbour, so
    its quads fold: (mesh, quad_normals, where, quads, frames, folded positions, the pushed
    vertex)."""
    mesh, quad_normals = cube_cage()
    where = OnCube(mesh, quad_normals)
    quads = mesh.face_vertices.reshape(-1, 4)
    frames = quad_frames(quad_normals)
    top = np.flatnonzero(np.isclose(mesh.vertices[:, 2], 1.0) & where.free)
    corner = top[np.argmin(mesh.vertices[top, 0] + mesh.vertices[top, 1])]
    folded_positions = mesh.vertices.copy()
    folded_positions[corner, :2] = [0.9, 0.9]
    return mesh, quad_normals, where, quads, frames, folded_positions, corner


def test_folded_quads_of_a_cube_cage_are_unfolded_on_their_faces():
    mesh, quad_normals, where, quads, frames, folded_positions, corner = folded_cube_cage()
    assert folded_corners(folded_positions, quads, frames).any()

    positions = untangle_on_target(folded_positions, mesh, np.full(len(quads), 1.0 / N), where)
    assert not folded_corners(positions, quads, frames).any()
    # on the cube: the moved vertices stayed in their faces' planes and inside them
    rows = np.flatnonzero(where.free)
    assert np.allclose(positions[rows, where.axis[rows]],
                       mesh.vertices[rows, where.axis[rows]])
    assert (positions >= -1e-12).all() and (positions <= 1 + 1e-12).all()
    # every limit normal at a face centre faces out
    untangled = PolyMesh(positions, mesh.face_vertices, mesh.face_offsets)
    check_polymesh(untangled)
    _, tangent_u, tangent_v = face_centre_operators(untangled)
    limit_normal = np.cross(tangent_u @ positions, tangent_v @ positions)
    assert (np.einsum("fk,fk->f", limit_normal, quad_normals) > 0).all()


def test_untangling_near_the_fold_leaves_the_far_vertices_where_they_were():
    mesh, quad_normals, where, quads, frames, folded_positions, corner = folded_cube_cage()
    # off the top face: the bottom face's inner vertices are more than two rings away
    bottom = np.flatnonzero(np.isclose(mesh.vertices[:, 2], 0.0) & where.free)
    disturbed = folded_positions.copy()
    disturbed[bottom, :2] += 0.05  # uneven there, but not folded
    positions = untangle_on_target(disturbed, mesh, np.full(len(quads), 1.0 / N), where,
                                   rings=2)
    assert not folded_corners(positions, quads, frames).any()
    assert np.array_equal(positions[bottom], disturbed[bottom])
    assert not np.array_equal(positions[corner], disturbed[corner])


def test_jacobians_of_a_unit_square_are_the_identity():
    points = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], dtype=np.float64)
    frames = quad_frames(np.array([[0.0, 0.0, 1.0]]))
    jac = corner_jacobians(points, np.array([[0, 1, 2, 3]]), frames, np.array([2.0]))
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    assert np.allclose(det, 1.0)
    assert np.allclose(np.einsum("...ij,...ij->...", jac, jac), 2.0)
