# SPDX-License-Identifier: LGPL-2.1-or-later
"""The compiled bicubic B-spline points (core/subdivision/patch_sums.py)."""
import numpy as np

from core.subdivision.limit import bspline_weights
from core.subdivision.patch_sums import bspline_patch_points


def test_patch_points_are_the_tensor_product_sums_of_their_nets():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(40, 3)) * 100.0
    nets = rng.integers(0, 40, (7, 16))
    net = rng.integers(0, 7, 300)
    u, v = rng.random(300), rng.random(300)
    u[:3], v[3:6] = 0.0, 1.0
    got = bspline_patch_points(u, v, nets, net, points)
    weights = (bspline_weights(u)[:, :, None] * bspline_weights(v)[:, None, :]).reshape(-1, 16)
    expected = np.einsum("pi,pik->pk", weights, points[nets[net]])
    assert np.abs(got - expected).max() < 1e-9 * np.abs(points).max()


def test_a_net_of_one_point_gives_that_point_and_no_points_give_none():
    points = np.array([[1.5, -2.0, 7.25], [0.0, 0.0, 0.0]])
    nets = np.zeros((1, 16), dtype=np.int64)
    u = np.linspace(0.0, 1.0, 11)
    got = bspline_patch_points(u, u[::-1], nets, np.zeros(11, dtype=np.int64), points)
    assert np.abs(got - points[0]).max() < 1e-12 * 8.0  # the weights sum to one
    assert bspline_patch_points(np.zeros(0), np.zeros(0), nets, np.zeros(0, dtype=np.int64),
                                points).shape == (0, 3)
