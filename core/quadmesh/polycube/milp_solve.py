# SPDX-License-Identifier: LGPL-2.1-or-later
"""The mixed-integer programs of the base-mesh stage, solved so that one input gives one result.

HiGHS (``scipy.optimize.milp``) is deterministic for fixed options, but a wall-clock limit is
not: on a loaded machine it stops the search earlier and hands back another incumbent. The
programs here are therefore bounded by a node limit (``NODE_LIMIT``, the same answer whatever
the load). HiGHS 1.2 (Debian's scipy 1.10) has no deterministic bound on the work of its root
node, so a wall-clock limit stays only as a guard against a hang (``HANG_GUARD_SECONDS``); a
program that reaches it raises :class:`MilpTimeLimitError` instead of using a load-dependent
incumbent. The programs met in practice close within a few nodes, the side-length
quantization's at its root (its linear relaxation is integral,
:mod:`core.quadmesh.polycube.quantize`),
far from both limits (``benchmarks/BASEMESH_SPEED_RESULTS.md``).

The base mesh's searches solve many programs more than once: the side-direction program of a
chart's neighbourhood is the same for every candidate relabelling that leaves the neighbourhood
alone, and proving one infeasible can take HiGHS thousands of nodes. Since HiGHS gives the same
answer to the same program, answers are kept by the program's content (every array of it, its
options and the limits) and a program met again gets a copy of its first answer.
"""
import copy
import hashlib
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
from scipy.optimize import milp

from core.errors import LabelingError, OTHER_PARTS

NODE_LIMIT = 5000
"""Branch-and-bound nodes HiGHS may explore (the programs met in practice close within a few)."""
HANG_GUARD_SECONDS = 600.0
"""Wall-clock seconds after which a program is abandoned (an error, never another answer)."""
TIME_LIMIT_MESSAGE = "Time limit reached"
"""Start of scipy's message when HiGHS stopped on ``HANG_GUARD_SECONDS``."""
ANSWERS_KEPT = 4096
"""Answers kept for programs met again (the least recently used go first)."""

_ANSWERS = OrderedDict()
"""Program digest -> scipy.optimize.OptimizeResult, at most ``ANSWERS_KEPT``."""
_VERDICTS = OrderedDict()
"""Digest of a program's feasible set -> OptimizeResult that decided it (optimal or
infeasible), at most ``ANSWERS_KEPT``."""
DECIDED = (0, 2)
"""``scipy.optimize.milp`` statuses that decide feasibility: optimal, infeasible."""


class MilpTimeLimitError(LabelingError):
    """A base-mesh program reached the wall-clock hang guard (its answer would depend on load)."""


def solve_milp(what, cost, integrality, bounds, constraints, mip_rel_gap=None,
               node_limit=NODE_LIMIT):
    """``scipy.optimize.milp`` with the deterministic limits of this module.

    Parameters
    ----------
    what : str, names the program in the error message (e.g. "the side-length quantization").
    cost, integrality, bounds, constraints : as ``scipy.optimize.milp``.
    mip_rel_gap : float or None, relative optimality gap accepted (HiGHS's default when None).
    node_limit : int, branch-and-bound nodes HiGHS may explore (a deterministic bound).

    Returns
    -------
    scipy.optimize.OptimizeResult; ``x`` is None when no solution was found (infeasible, or
    none within ``node_limit`` nodes; ``status`` and ``message`` say which: 0 optimal, 1 a
    limit reached, 2 infeasible).

    Raises
    ------
    MilpTimeLimitError when HiGHS stopped on the hang guard.
    """
    options = {"node_limit": int(node_limit), "time_limit": HANG_GUARD_SECONDS}
    if mip_rel_gap is not None:
        options["mip_rel_gap"] = mip_rel_gap
    key = program_digest(cost, integrality, bounds, constraints, options)
    if key in _ANSWERS:
        _ANSWERS.move_to_end(key)
        return copy.deepcopy(_ANSWERS[key])
    result = milp(cost, integrality=integrality, bounds=bounds, constraints=constraints,
                  options=options)
    if str(result.message).startswith(TIME_LIMIT_MESSAGE):
        raise MilpTimeLimitError(
            f"{what} did not finish within {HANG_GUARD_SECONDS:g} s ({len(cost)} variables); "
            f"its answer would depend on the machine's load, so none is used: try {OTHER_PARTS} "
            "or --base-mesh-method decimation")
    _ANSWERS[key] = copy.deepcopy(result)
    while len(_ANSWERS) > ANSWERS_KEPT:
        _ANSWERS.popitem(last=False)
    return result


def solve_feasibility(what, cost, integrality, bounds, constraints, node_limit=NODE_LIMIT):
    """:func:`solve_milp` for a caller that reads only whether the program has a solution.

    Whether a program has a solution does not depend on its costs. The search programs of
    the base mesh meet many programs that differ from one solved before in their costs
    only (a relabelling elsewhere moved the measured extents of a few sides), and proving
    one of them infeasible can take seconds. So a program whose feasible set (integrality,
    bounds, constraints and limits) was decided before, found optimal or infeasible, gets
    that answer; one that reached a limit decided nothing and is solved as it is.

    Parameters and returns as :func:`solve_milp`; ``status`` and ``message`` are those of
    the program, ``x`` (where not None) a solution of it that may not be the cheapest.
    """
    options = {"node_limit": int(node_limit), "time_limit": HANG_GUARD_SECONDS}
    key = program_digest(np.zeros(len(cost)), integrality, bounds, constraints, options)
    if key in _VERDICTS:
        _VERDICTS.move_to_end(key)
        return copy.deepcopy(_VERDICTS[key])
    result = solve_milp(what, cost, integrality, bounds, constraints, node_limit=node_limit)
    if result.status in DECIDED:
        _VERDICTS[key] = copy.deepcopy(result)
        while len(_VERDICTS) > ANSWERS_KEPT:
            _VERDICTS.popitem(last=False)
    return result


def program_digest(cost, integrality, bounds, constraints, options):
    """A digest (str) of a program's content: equal programs, equal digests.

    Every array is hashed with its shape and its float64 (or int64 index) bytes; sparse
    constraint matrices in canonical CSR form, so two ways of building one matrix agree.
    """
    digest = hashlib.blake2b(digest_size=20)

    def add(values):
        array = np.ascontiguousarray(np.asarray(values, dtype=np.float64))
        digest.update(repr(array.shape).encode())
        digest.update(array.tobytes())

    add(cost)
    add(integrality)
    add(bounds.lb)
    add(bounds.ub)
    for constraint in constraints:
        matrix = constraint.A
        if sp.issparse(matrix):
            matrix = sp.csr_matrix(matrix, dtype=np.float64, copy=True)
            matrix.sum_duplicates()
            matrix.sort_indices()
            digest.update(repr(matrix.shape).encode())
            for part in (matrix.indptr, matrix.indices):
                digest.update(np.ascontiguousarray(part, dtype=np.int64).tobytes())
            add(matrix.data)
        else:
            add(matrix)
        add(constraint.lb)
        add(constraint.ub)
    digest.update(repr(sorted(options.items())).encode())
    return digest.hexdigest()
