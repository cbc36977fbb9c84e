# SPDX-License-Identifier: LGPL-2.1-or-later
"""Patches stage: the fitted cage's limit surface as bicubic B-spline patches (paper Sect. 2.4:
the limit of the subdivision surface; the B-spline form is ours, docs/DESIGN.md)."""
from core.types import PatchesResult


def run_patches(fit, params, progress):
    """One B-spline patch per quad of the fitted cage (graded at extraordinary vertices).

    Parameters
    ----------
    fit : core.types.FitResult.
    params : core.params.ReconstructionParams (unused: the grading depth is the
        exporter's default, ``core.params.EXPORT_DEPTH``).
    progress : core.progress.Progress; cancellable before the patches are built.

    Returns
    -------
    core.types.PatchesResult; the report is the patch set's figures (``PatchSet.info``).
    """
    from core.export.bspline import limit_surface_patches

    progress.check_cancel()
    patches = limit_surface_patches(fit.cage)
    return PatchesResult(patches, dict(patches.info))
