# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit stage (paper Sect. 2.5): shape optimisation of the base mesh against the target."""
from core.fitting.fit import fit_base_mesh
from core.target_surface import TargetSurface

__all__ = ["TargetSurface", "fit_base_mesh"]
