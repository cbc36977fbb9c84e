# SPDX-License-Identifier: LGPL-2.1-or-later
"""PNG renderings of per-face labels and parts (matplotlib mplot3d, no GUI needed).

Each image shows the mesh from two opposite viewpoints side by side (orthographic). Faces are
flat coloured and shaded by the angle between their normal and the viewing direction
(headlight), so the shape stays readable. Faces turned away from the viewer are culled (the
mesh is closed and outward oriented), and the rest are drawn back to front by mplot3d's depth
sort; culling keeps the two sides of thin plates from showing through each other.
"""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from core.segmentation.labels_file import LABEL_COLOURS  # noqa: E402

LABEL_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
VIEWS = ((25.0, 35.0), (-25.0, 215.0))
"""(elevation, azimuth) in degrees of the two views."""
FIGSIZE = (8.0, 4.6)
DPI = 100


def part_colours(n_parts):
    """(n_parts, 3) float RGB in [0, 1]: tab10 / tab20 colours, cycled past 20 parts."""
    cmap = plt.get_cmap("tab10" if n_parts <= 10 else "tab20")
    k = cmap.N
    return np.array([cmap(i % k)[:3] for i in range(n_parts)])


def view_direction(elev, azim):
    """(3,) unit vector from the scene towards an mplot3d camera at (elev, azim) degrees."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def shaded(face_rgb, normals, eye):
    """(m, 3) float RGB: ``face_rgb`` darkened by the headlight term ``0.3 + 0.7 |n . eye|``."""
    light = 0.3 + 0.7 * np.abs(normals @ eye)
    return np.clip(face_rgb * light[:, None], 0.0, 1.0)


def _unit_normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    length = np.linalg.norm(n, axis=1)
    return n / np.where(length > 0, length, 1.0)[:, None]


def render_faces(path, V, F, face_rgb, title, legend=None):
    """Write a PNG of a triangle mesh with one colour per face, seen from two sides.

    Parameters
    ----------
    path : str, output PNG (about 800 x 460 pixels).
    V : (n, 3) float64 vertices.
    F : (m, 3) int faces.
    face_rgb : (m, 3) float RGB in [0, 1] of each face.
    title : str, figure title.
    legend : list of (label, rgb) pairs, optional, drawn below the views.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    normals = _unit_normals(V, F)
    triangles = V[F]
    lo, hi = V.min(axis=0), V.max(axis=0)
    extent = np.maximum(hi - lo, 1e-3 * (hi - lo).max())
    fig = plt.figure(figsize=FIGSIZE, dpi=DPI)
    for k, (elev, azim) in enumerate(VIEWS):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        eye = view_direction(elev, azim)
        front = normals @ eye > 0.0
        colours = shaded(face_rgb[front], normals[front], eye)
        ax.add_collection3d(Poly3DCollection(triangles[front], facecolors=colours,
                                             edgecolors="none",
                                             linewidths=0.0, antialiased=False))
        ax.set_xlim(lo[0], lo[0] + extent[0])
        ax.set_ylim(lo[1], lo[1] + extent[1])
        ax.set_zlim(lo[2], lo[2] + extent[2])
        ax.set_box_aspect(tuple(extent), zoom=1.0)
        ax.set_proj_type("ortho")
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
        ax.set_title(f"elev {elev:g}, azim {azim:g}", fontsize=8)
    fig.suptitle(title, fontsize=10)
    if legend:
        handles = [Patch(facecolor=rgb, label=name) for name, rgb in legend]
        fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 10), fontsize=7,
                   frameon=False)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.07 if legend else 0.0, top=0.9, wspace=0.0)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def render_labels(path, V, F, face_label, title):
    """PNG of the labeling, faces coloured by ``labels_file.LABEL_COLOURS`` (labels 0..5)."""
    rgb = LABEL_COLOURS.astype(np.float64) / 255.0
    legend = [(f"{name} (of the face's frame)" if i == 0 else name, rgb[i])
              for i, name in enumerate(LABEL_NAMES)]
    render_faces(path, V, F, rgb[np.asarray(face_label, dtype=np.int64)], title, legend)


def render_parts(path, V, F, face_part, title):
    """PNG of the part segmentation, one distinct colour per part."""
    face_part = np.asarray(face_part, dtype=np.int64)
    n_parts = int(face_part.max()) + 1
    colours = part_colours(n_parts)
    legend = [(f"part {p}", colours[p]) for p in range(min(n_parts, 20))]
    render_faces(path, V, F, colours[face_part], title, legend)
