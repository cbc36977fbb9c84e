# SPDX-License-Identifier: LGPL-2.1-or-later
"""Meshes and mesh files for the fuzz corpus, built here (no binary file is committed).

Shapes are ``(vertices (n, 3) float64, faces (m, 3) int64)`` pairs with outward
counter-clockwise faces unless a shape is broken on purpose; writers turn them into the
bytes of every format the intake reads, and the corrupters damage those bytes.
"""
import struct

import numpy as np
import trimesh

from core.subdivision import sample_cages


def box(center=(0.0, 0.0, 0.0), extents=(1.0, 1.0, 1.0)):
    mesh = trimesh.creation.box(extents=extents)
    return np.asarray(mesh.vertices) + np.asarray(center, dtype=float), np.asarray(mesh.faces)


def tetrahedron():
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return V, F


def sphere(subdivisions=2):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def concatenate(*shapes):
    """One soup of several shapes (vertex indices shifted, nothing merged)."""
    vertices, faces, offset = [], [], 0
    for V, F in shapes:
        vertices.append(V)
        faces.append(F + offset)
        offset += len(V)
    return np.concatenate(vertices), np.concatenate(faces)


def many_tetrahedra(count):
    """``count`` disjoint small tetrahedra on a grid: ``count`` components."""
    V, F = tetrahedron()
    side = int(np.ceil(count ** (1 / 3)))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)[:count]
    vertices = (V[None] * 0.5 + 2.0 * grid[:, None, :]).reshape(-1, 3)
    faces = (F[None] + 4 * np.arange(count)[:, None, None]).reshape(-1, 3)
    return vertices, faces


def crossed_box():
    """A box with one corner pushed through the opposite side: it intersects itself."""
    V, F = box()
    V = V.copy()
    V[int(np.argmax(V.sum(axis=1)))] = [-0.9, 0.3, 0.2]
    return V, F


def boxes_sharing_a_vertex():
    return concatenate(box(), box(center=(1.0, 1.0, 1.0)))


def boxes_sharing_an_edge():
    return concatenate(box(), box(center=(1.0, 1.0, 0.0)))


def box_with_fin():
    """A box with one extra triangle on an edge: three faces at that edge."""
    V, F = box()
    a, b = F[0][:2]
    V = np.vstack([V, (V[a] + V[b]) / 2 + [3.0, 3.0, 3.0]])
    return V, np.vstack([F, [[a, b, len(V) - 1]]])


def flat_square_both_sides():
    """Two triangles and the same two reversed: closed but of zero volume (all coplanar)."""
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    return V, np.vstack([F, F[:, ::-1]])


def collinear_soup():
    V = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]])
    return V, np.array([[0, 1, 2], [1, 2, 3], [0, 2, 3], [0, 1, 3]])


def mixed_winding_box():
    V, F = box()
    F = F.copy()
    F[::3] = F[::3, ::-1]
    return V, F


def inside_out(shape):
    V, F = shape
    return V, F[:, ::-1].copy()


def scaled(shape, factor):
    V, F = shape
    return V * factor, F


def with_vertex(shape, index, value):
    V, F = shape
    V = V.astype(np.float64).copy()
    V[index] = value
    return V, F


# --- writers: (vertices, faces) -> bytes --------------------------------------------------


def binary_stl(shape):
    V, F = shape
    tri = np.asarray(V, dtype="<f4")[F]
    records = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    records["v"] = tri
    return b"\0" * 80 + struct.pack("<I", len(F)) + records.tobytes()


def ascii_stl(shape):
    V, F = shape
    lines = ["solid fuzz"]
    for tri in np.asarray(V)[F]:
        lines += ["facet normal 0 0 0", " outer loop"]
        lines += ["  vertex %r %r %r" % tuple(map(float, p)) for p in tri]
        lines += [" endloop", "endfacet"]
    return ("\n".join(lines + ["endsolid fuzz"]) + "\n").encode()


def obj_text(shape):
    V, F = shape
    lines = ["v %r %r %r" % tuple(map(float, p)) for p in V]
    lines += ["f %d %d %d" % tuple(f + 1) for f in F]
    return ("\n".join(lines) + "\n").encode()


def off_text(shape):
    V, F = shape
    lines = ["OFF", f"{len(V)} {len(F)} 0"]
    lines += ["%r %r %r" % tuple(map(float, p)) for p in V]
    lines += ["3 %d %d %d" % tuple(f) for f in F]
    return ("\n".join(lines) + "\n").encode()


def ply_ascii(shape):
    V, F = shape
    header = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property float x",
              "property float y", "property float z", f"element face {len(F)}",
              "property list uchar int vertex_indices", "end_header"]
    body = ["%r %r %r" % tuple(map(float, p)) for p in V] + ["3 %d %d %d" % tuple(f) for f in F]
    return ("\n".join(header + body) + "\n").encode()


def ply_binary(shape):
    V, F = shape
    header = "\n".join(["ply", "format binary_little_endian 1.0", f"element vertex {len(V)}",
                        "property float x", "property float y", "property float z",
                        f"element face {len(F)}", "property list uchar int vertex_indices",
                        "end_header"]) + "\n"
    faces = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"], faces["i"] = 3, F
    return header.encode() + np.asarray(V, dtype="<f4").tobytes() + faces.tobytes()


WRITERS = {"stl": binary_stl, "ascii.stl": ascii_stl, "obj": obj_text, "off": off_text,
           "ply": ply_binary, "ascii.ply": ply_ascii}
"""Output kind -> writer; the file suffix is the part after the last dot."""


def cage_obj(vertices, faces):
    """Polygon OBJ text of a cage: ``faces`` is a list of corner-index lists (0-based)."""
    lines = ["v %r %r %r" % tuple(map(float, p)) for p in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces]
    return ("\n".join(lines) + "\n").encode()


def cage_lists(cage):
    """A PolyMesh as ``(vertices (n, 3), faces: list of corner-index lists)``."""
    fv, fo = np.asarray(cage.face_vertices), np.asarray(cage.face_offsets)
    return np.asarray(cage.vertices), [fv[a:b].tolist() for a, b in zip(fo[:-1], fo[1:])]


def cube_cage():
    """The unit cube cage as ``(vertices (8, 3), faces: list of 6 quads)``, outward."""
    return cage_lists(sample_cages.cube())


def spindle_torus_cage():
    """A torus cage whose tube is wider than its ring: its limit surface crosses itself."""
    return cage_lists(sample_cages.torus(major_radius=0.5, minor_radius=1.0))


def corrupt(data, seed, flips):
    """``data`` with ``flips`` random bytes after the first 84 replaced (seeded)."""
    rng = np.random.default_rng(seed)
    out = bytearray(data)
    where = rng.integers(min(84, len(out) - 1), len(out), size=flips)
    out_values = rng.integers(0, 256, size=flips, dtype=np.uint8)
    for position, value in zip(where.tolist(), out_values.tolist()):
        out[position] = value
    return bytes(out)
