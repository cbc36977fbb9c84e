# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch thumbnail: the solid over the target, coloured by its distance to the target.

One orthographic view (matplotlib Agg, no GUI): the target's triangles in translucent grey
and the solid's tessellation coloured from white (on the target) to red (the largest
distance), with the scale in millimetres beside it. Both are drawn as one collection so
mplot3d's depth sort orders them together.
"""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from core.geometry import unit_face_normals  # noqa: E402

VIEW = (25.0, 35.0)
"""(elevation, azimuth) in degrees."""
SIZE = (4.0, 3.0)
DPI = 80
TESSELLATION = 2e-3
"""Tessellation tolerance of the solid, a fraction of the target's bounding-box diagonal."""
TARGET_RGBA = (0.55, 0.55, 0.55, 0.18)


def render_solid_thumbnail(path, target_path, step_path, units="mm"):
    """Write the PNG thumbnail (about 320 x 240 pixels) of a batch result; returns its path.

    Parameters
    ----------
    path : str, PNG to write (through a temporary file and a rename).
    target_path : the target mesh file; its coordinates are in ``units`` (scaled to mm).
    step_path : the result STEP file (millimetres).
    units : key of ``core.params.UNIT_TO_MM``.
    """
    import FreeCAD  # noqa: F401  (before Part, see CONTRIBUTING)

    from core.mesh_io import read_triangle_soup
    from core.params import UNIT_TO_MM
    from core.quality import point_surface_distance
    from polycube_wb.brep import tessellate
    from polycube_wb.step_io import read_step

    target_V, target_F = read_triangle_soup(target_path)
    target_V = np.asarray(target_V, dtype=np.float64) * UNIT_TO_MM[units]
    target_F = np.asarray(target_F, dtype=np.int64)
    diagonal = float(np.linalg.norm(target_V.max(axis=0) - target_V.min(axis=0)))
    solid = read_step(step_path).Solids[0]
    V, F = tessellate(solid, TESSELLATION * diagonal)
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    distance = point_surface_distance(V, target_V, target_F)[F].mean(axis=1)
    scale = max(float(distance.max()), 1e-12)
    cmap = plt.get_cmap("Reds")
    solid_rgba = cmap(0.05 + 0.95 * distance / scale)
    eye = _view_direction(*VIEW)
    normals = unit_face_normals(V, F)
    solid_rgba[:, :3] *= (0.45 + 0.55 * np.abs(normals @ eye))[:, None]
    triangles = np.concatenate([target_V[target_F], V[F]])
    colours = np.concatenate([np.tile(TARGET_RGBA, (len(target_F), 1)), solid_rgba])
    fig = plt.figure(figsize=SIZE, dpi=DPI)
    ax = fig.add_axes((0.0, 0.0, 0.8, 1.0), projection="3d")
    ax.add_collection3d(Poly3DCollection(triangles, facecolors=colours, edgecolors="none",
                                         linewidths=0.0, antialiased=False))
    lo, hi = target_V.min(axis=0), target_V.max(axis=0)
    extent = np.maximum(hi - lo, 1e-3 * (hi - lo).max())
    ax.set_xlim(lo[0], lo[0] + extent[0])
    ax.set_ylim(lo[1], lo[1] + extent[1])
    ax.set_zlim(lo[2], lo[2] + extent[2])
    ax.set_box_aspect(tuple(extent))
    ax.set_proj_type("ortho")
    ax.view_init(elev=VIEW[0], azim=VIEW[1])
    ax.set_axis_off()
    bar = fig.add_axes((0.83, 0.12, 0.04, 0.76))
    mappable = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0.0, scale))
    fig.colorbar(mappable, cax=bar).set_label("distance to target (mm)", fontsize=7)
    bar.tick_params(labelsize=6)
    return _save_atomic(fig, path)


def _save_atomic(fig, path):
    import os

    from core.output_files import atomic_output

    try:
        with atomic_output(path, (), "thumbnail") as temporary:
            fig.savefig(temporary, dpi=DPI, format="png")
    finally:
        plt.close(fig)
    return os.path.abspath(os.fspath(path))


def _view_direction(elev, azim):
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
