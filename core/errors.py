# SPDX-License-Identifier: LGPL-2.1-or-later
"""Error types raised by the core pipeline.

Every error a user can cause (bad file, bad mesh, bad parameter) derives from
``PolycubeInputError`` so the CLI can map it to exit code 2; everything else is an
internal failure (exit code 1).
"""


OTHER_PARTS = "other parts (--parts auto, or your own with --parts file)"
"""What a user can change when a labeling cannot be laid out; worded so that it also holds
when the run already used ``--parts auto``."""

class PolycubeError(Exception):
    """Base class of every error raised on purpose by this project."""


class PolycubeInputError(PolycubeError, ValueError):
    """The user's input (file, mesh or parameter) is unusable; the message says why."""


class InvalidMeshError(PolycubeInputError):
    """A mesh failed validation.

    Attributes
    ----------
    reason : str
        Machine-readable kind: ``empty``, ``unreadable``, ``format``, ``open``,
        ``non_manifold``, ``orientation``, ``degenerate_faces``, ``duplicate_faces``,
        ``non_finite``, ``self_intersecting``, ``multiple_components``,
        ``coordinate_range``, ``unused_vertices``, ``not_quads``, ``crease_not_edge``.
    count : int
        How many offending items were found.
    examples : list
        A few offending indices (faces, edges or vertices, per ``reason``).
    """

    def __init__(self, message, reason, count=0, examples=()):
        super().__init__(message)
        self.reason = reason
        self.count = int(count)
        self.examples = list(examples)


class ParameterError(PolycubeInputError):
    """A stage parameter is out of range or inconsistent."""


class FaceLimitError(ParameterError):
    """The base mesh needs more faces than the user's own limit (``max_base_faces``) allows.

    Not a labeling failure: the labeling is usable, the user asked for fewer faces than its
    layout needs; the message says how many and what to change.
    """


class LabelingError(PolycubeError):
    """Polycube labeling could not produce a usable result."""


class ExportError(PolycubeError):
    """B-spline or B-rep export failed (e.g. the shell does not close)."""


class StepPathError(ExportError, PolycubeInputError):
    """A STEP path is unusable (missing folder, not writable, wrong suffix, is an input)."""


class InternalError(PolycubeError, RuntimeError):
    """An invariant of an algorithm does not hold (a bug, not the user's input); the message
    names the invariant."""


class Cancelled(PolycubeError):
    """The user cancelled a long-running stage."""
