# SPDX-License-Identifier: LGPL-2.1-or-later
"""Feature networks of the dev meshes: machined lines or a voxel staircase.

Usage::

    .venv/bin/python benchmarks/staircase_bench.py [--meshes DIR]

Per dev mesh: its triangles, the edges of its closed feature network
(:func:`core.quadmesh.creases.closed_network` of
:func:`core.quadmesh.creases.feature_edges`), the share of the network's vertices that are
corners (:func:`core.quadmesh.decimation.feature_decimation.corner_vertices`), the share of its
edges in chains of at most three edges between corners, and whether the corner share exceeds
:data:`STAIRCASE_CORNER_SHARE`: a criterion that tells a raw marching-cubes result's voxel staircase
(zig-zag lines that turn or branch every one or two edges) from a machined part's feature lines
(which turn only at their ends). Writes ``benchmarks/STAIRCASE_RESULTS.md``.

The paired decimation does not use it. Skipping the creased ladder for such a staircase was
measured end to end (``benchmarks/TO_RESULTS.md``, the rows labelled "variant, not kept"):
the base-mesh stage of the raw marching-cubes dev mesh is about three times faster, but the
feature-preserving decimation there stops short at a larger cage whose limit surface crosses
itself much less than the smooth ladder's cage within the budget rule, and the fit of the
smooth cage took longer than the time saved.
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
RESULTS_MD = os.path.join(HERE, "STAIRCASE_RESULTS.md")
STAIRCASE_CORNER_SHARE = 0.25
"""A network with a larger share of corners among its vertices is taken for a staircase."""


def chain_sizes(features, corner):
    """(k,) int: edges of the chain (between corners) each feature edge belongs to."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    k = len(features)
    ends = np.concatenate([np.stack([features[:, 0], np.arange(k)], 1),
                           np.stack([features[:, 1], np.arange(k)], 1)])
    ends = ends[~corner[ends[:, 0]]]
    ends = ends[np.argsort(ends[:, 0], kind="stable")]
    joined = ends[:, 1].reshape(-1, 2)  # every line vertex joins its two edges
    graph = scipy.sparse.coo_matrix((np.ones(len(joined)), (joined[:, 0], joined[:, 1])),
                                    shape=(k, k))
    _, label = connected_components(graph, directed=False)
    return np.bincount(label)[label]


def measure(path):
    """One row of the table for the mesh at ``path``."""
    import trimesh

    from core.quadmesh.creases import closed_network, feature_edges
    from core.quadmesh.decimation.feature_decimation import corner_vertices

    mesh = trimesh.load(path, process=True)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    network = closed_network(feature_edges(vertices, faces), len(vertices))
    row = {"mesh": os.path.basename(path), "triangles": len(faces),
           "network": 0 if network is None else len(network)}
    if network is not None:
        corner = corner_vertices(vertices, network)
        row["corner_share"] = float(corner[np.unique(network)].mean())
        row["short_chains"] = float((chain_sizes(network, corner) <= 3).mean())
        row["staircase"] = row["corner_share"] > STAIRCASE_CORNER_SHARE
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES, help="folder of the dev meshes")
    args = parser.parse_args(argv)
    names = sorted(n for n in os.listdir(args.meshes) if n.endswith((".stl", ".obj")))
    lines = ["# Feature networks: machined lines or a voxel staircase", "",
             "Written by `benchmarks/staircase_bench.py`. `network`: edges of the closed network "
             "of feature edges (dihedral angle above the crease angle); `corners`: share of its "
             "vertices that are corners (junctions, or turns sharper than the turn angle); "
             "`short chains`: share of its edges in chains of at most 3 edges between corners; "
             f"`staircase`: corners above {STAIRCASE_CORNER_SHARE} of its vertices (a voxel "
             "staircase's zig-zags, not machined lines).", "",
             "| mesh | triangles | network | corners | short chains | staircase |",
             "|---|---|---|---|---|---|"]
    for name in names:
        row = measure(os.path.join(args.meshes, name))
        if row["network"]:
            lines.append(f"| {row['mesh']} | {row['triangles']} | {row['network']} | "
                         f"{row['corner_share']:.3f} | {row['short_chains']:.2f} | "
                         f"{'yes' if row['staircase'] else 'no'} |")
        else:
            lines.append(f"| {row['mesh']} | {row['triangles']} | 0 | - | - | - |")
        print(lines[-1], flush=True)
    with open(RESULTS_MD, "w") as handle:
        handle.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
