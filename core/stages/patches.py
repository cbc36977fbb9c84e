# SPDX-License-Identifier: LGPL-2.1-or-later
"""Patches stage: the fitted cage's limit surface as bicubic B-spline patches (paper Sect. 2.4:
the limit of the subdivision surface; the B-spline form is ours, docs/DESIGN.md)."""
from core.errors import ExportError
from core.types import PatchesResult


def run_patches(fit, params, progress):
    """One B-spline patch per quad of the fitted cage: graded at extraordinary vertices
    (``params.export == "exact"``, grading depth ``core.params.EXPORT_DEPTH``) or the light
    G1 patches (``"g1"``, :mod:`core.export.g1_patches`).

    Parameters
    ----------
    fit : core.types.FitResult.
    params : core.params.ReconstructionParams; ``export`` chooses the surface form, ``faces``
        one face per quad or per block of quads (g1 only).
    progress : core.progress.Progress; cancellable before the patches are built.

    Returns
    -------
    core.types.PatchesResult; the report is the patch set's figures (``PatchSet.info``).

    Raises
    ------
    ExportError
        The fitted cage's limit surface crosses itself (the check ``subd-to-step`` makes,
        ``core.subdivision.limit_crossings.export_limit_crossings``): no solid is built of it;
        or ``export`` is ``g1`` and its G1 conditions cannot be met.
    """
    from core.export.bspline import limit_surface_patches
    from core.export.g1_patches import g1_surface_patches
    from core.subdivision.limit_crossings import export_limit_crossings

    progress.check_cancel()
    crossings = export_limit_crossings(fit.cage)
    if crossings.count:
        cage = fit.cage_self_intersections
        why = (f"; the unfitted base mesh's limit surface already crosses itself ({cage} "
               f"pairs at the fit's level {fit.levels})" if cage else "")
        raise ExportError(f"the fitted cage: {crossings.message()}{why}")
    if params.export == "g1":
        patches = g1_surface_patches(fit.cage, faces=params.faces)
    else:
        patches = limit_surface_patches(fit.cage)
    return PatchesResult(patches, dict(patches.info))
