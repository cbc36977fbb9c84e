# SPDX-License-Identifier: LGPL-2.1-or-later
"""The README's picture: the bundled cantilever as target, labeling, cage and STEP solid.

Usage: ``.venv/bin/python benchmarks/readme_figure.py [OUT.png]`` (default
``docs/images/pipeline.png``). Runs ``reconstruct`` on ``examples/to_simp_cantilever.stl`` in a
temporary folder, reads the STEP solid back with FreeCAD and draws four panels from one
viewpoint with matplotlib (no GUI needed): the target mesh, its polycube labeling, the fitted
Catmull-Clark cage and the solid with its B-spline patch boundaries.
"""
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection  # noqa: E402

from core.mesh_io import read_triangle_soup  # noqa: E402
from core.polymesh_io import read_polymesh  # noqa: E402
from core.segmentation.labels_file import LABEL_COLOURS, read_labels_ply  # noqa: E402
from render import plt, shaded, view_direction  # noqa: E402

TARGET = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
VIEW = (22.0, -122.0)
"""(elevation, azimuth) in degrees of the one viewpoint of every panel."""
GREY = np.array([0.78, 0.80, 0.84])
PATCH_SHADES = ((0.55, 0.70, 0.90), (0.66, 0.79, 0.95), (0.47, 0.62, 0.84))
TESSELLATION = 0.05
"""Linear deflection (mm) of the solid's triangulation for drawing."""


def _normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]


def _panel(ax, V, F, rgb, title, lines=None):
    """Faces ``F`` of ``V`` facing the viewer, coloured ``rgb`` ((3,) or (m, 3)) and shaded,
    with ``lines`` ((k, 2, 3) segments, optional) drawn over them."""
    eye = view_direction(*VIEW)
    normals = _normals(V, F)
    front = normals @ eye > 0.0
    colours = shaded(np.broadcast_to(rgb, (len(F), 3))[front], normals[front], eye)
    ax.add_collection3d(Poly3DCollection(V[F][front], facecolors=colours, edgecolors="none",
                                         linewidths=0.0, antialiased=False, zorder=1))
    if lines is not None:
        ax.add_collection3d(Line3DCollection(lines, colors="#303030", linewidths=0.45,
                                             zorder=2))
    ax.set_title(title, fontsize=10)


def _frame(axes, V):
    lo, hi = V.min(axis=0), V.max(axis=0)
    for ax in axes:
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(tuple(hi - lo), zoom=1.1)
        ax.set_proj_type("ortho")
        ax.view_init(elev=VIEW[0], azim=VIEW[1])
        ax.set_axis_off()


def _cage_panel(ax, path):
    """The cage's faces (fan-triangulated) with the edges of the faces facing the viewer."""
    cage = read_polymesh(path)
    V = np.asarray(cage.vertices)
    eye = view_direction(*VIEW)
    tris, edges = [], set()
    for face in cage.faces():
        face = [int(v) for v in face]
        fan = [(face[0], face[i], face[i + 1]) for i in range(1, len(face) - 1)]
        tris += fan
        if (_normals(V, np.array(fan)).sum(axis=0) @ eye) > 0.0:
            edges |= {tuple(sorted((a, b))) for a, b in zip(face, face[1:] + face[:1])}
    _panel(ax, V, np.array(tris), GREY, f"fitted cage ({cage.n_faces} faces)",
           V[np.array(sorted(edges))])


def _solid_panel(ax, step):
    import FreeCAD  # noqa: F401  (must precede Part)
    import Part

    shape = Part.read(step)
    vertices, faces, colours = [], [], []
    for k, face in enumerate(shape.Faces):  # every patch its own shade, so the patches show
        points, triangles = face.tessellate(TESSELLATION)
        faces.append(np.array(triangles, dtype=np.int64).reshape(-1, 3) + sum(map(len, vertices)))
        vertices.append(np.array([[p.x, p.y, p.z] for p in points]))
        colours += [PATCH_SHADES[k % len(PATCH_SHADES)]] * len(triangles)
    _panel(ax, np.concatenate(vertices), np.concatenate(faces), np.array(colours),
           f"STEP solid ({len(shape.Faces)} B-spline patches)")


def main(out):
    with tempfile.TemporaryDirectory() as work:
        step, base, labels = (os.path.join(work, name) for name in
                              ("solid.step", "cage.obj", "labels.ply"))
        subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", TARGET, "-o", step,
                        "--base-mesh", base, "--labels", labels], cwd=REPO, check=True,
                       stdout=subprocess.DEVNULL)
        V, F = read_triangle_soup(TARGET)
        V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
        fig = plt.figure(figsize=(12.0, 3.1), dpi=100)
        axes = [fig.add_subplot(1, 4, k + 1, projection="3d", computed_zorder=False)
                for k in range(4)]
        _panel(axes[0], V, F, GREY, f"target: SIMP result ({len(F):,} triangles)")
        labelled = read_labels_ply(labels)
        rgb = LABEL_COLOURS.astype(np.float64)[labelled["label"]] / 255.0
        eye = view_direction(*VIEW)
        normals = _normals(labelled["V"], labelled["F"])
        front = normals @ eye > 0.0
        axes[1].add_collection3d(Poly3DCollection(
            labelled["V"][labelled["F"]][front], facecolors=shaded(rgb[front], normals[front], eye),
            edgecolors="none", linewidths=0.0, antialiased=False))
        axes[1].set_title("polycube labeling", fontsize=10)
        _cage_panel(axes[2], base)
        _solid_panel(axes[3], step)
        _frame(axes, V)
        fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.92, wspace=0.0)
        os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        fig.savefig(out, dpi=100)
        plt.close(fig)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(REPO, "docs", "images", "pipeline.png"))
