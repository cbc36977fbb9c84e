# SPDX-License-Identifier: LGPL-2.1-or-later
"""Test cages; the builders live in core.subdivision.sample_cages so benchmarks share them."""
from core.subdivision.sample_cages import (  # noqa: F401
    cube, genus3_block, grid_sphere, mixed_prism, pentagonal_prism, torus, voxel_cage)

ALL = {
    "cube": cube,
    "torus": torus,
    "mixed_prism": mixed_prism,
    "pentagonal_prism": pentagonal_prism,
    "genus3_block": genus3_block,
}
