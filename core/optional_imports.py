# SPDX-License-Identifier: LGPL-2.1-or-later
"""Imports of optional third-party packages that need care inside FreeCAD.

FreeCAD 0.20.2 ships an unrelated module named ``lazy_loader`` in its ``Ext`` folder,
which comes before ``AdditionalPythonPackages`` on ``sys.path``; scikit-image needs the
PyPI ``lazy_loader``. While scikit-image is first imported, the PyPI package is put in
``sys.modules``; afterwards ``sys.modules`` is restored, so FreeCAD's own module still
loads for FreeCAD (scikit-image keeps its reference to the PyPI one).
"""
import importlib
import importlib.util
import sys

INSTALL_HINT = (
    "the {name} package is needed by the reconstruction; install it into the Python "
    "that runs this code with `python -m pip install {name}` (for the FreeCAD GUI: "
    "`python -m pip install --target <UserAppData>/AdditionalPythonPackages {name}`, where "
    "<UserAppData> is FreeCAD.getUserAppDataDir())")


def optional_module(name, package=None):
    """Import module ``name`` or raise ImportError with an install hint.

    ``package`` is the PyPI name to install when it differs from the module's top-level
    name (``igl`` comes from ``libigl``).
    """
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise ImportError(INSTALL_HINT.format(name=package or name.split(".")[0])) from exc


def import_skeletonize():
    """Return ``skimage.morphology.skeletonize``; ImportError with an install hint if missing."""
    previous = sys.modules.get("lazy_loader")
    swapped = "skimage" not in sys.modules
    try:
        if swapped:
            sys.modules["lazy_loader"] = _pypi_lazy_loader()
        from skimage.morphology import skeletonize
    except ImportError as exc:
        raise ImportError(
            "automatic parts need scikit-image (3-D thinning): run the project's "
            "'make setup', or 'pip install --target <FreeCAD user data>/AdditionalPythonPackages "
            "--no-deps scikit-image lazy_loader networkx', or give the parts by hand") from exc
    finally:
        if swapped and previous is not None:
            sys.modules["lazy_loader"] = previous
        elif swapped:
            del sys.modules["lazy_loader"]
    return skeletonize


def _pypi_lazy_loader():
    """Load the PyPI ``lazy_loader`` package from wherever its distribution is installed."""
    from importlib import metadata

    try:
        init = metadata.distribution("lazy_loader").locate_file("lazy_loader/__init__.py")
    except metadata.PackageNotFoundError as exc:
        raise ImportError("the PyPI package lazy_loader (needed by scikit-image) is not installed") from exc
    spec = importlib.util.spec_from_file_location("lazy_loader", str(init))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
