"""The CJM step's tolerances, in one place (docs/design.md section 16).

The Python step reads them from here; the compiled step receives them when it is built
(:class:`StepTolerances`, a field of :class:`controllers.cjm.step_setup.StepSetup`), so
the two backends take their decisions against the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..base import EQUALITY_TOLERANCE, TWIST_TOLERANCE
from ..numerics import RANK_TOLERANCE

#: A barrier row is violated when the solution undercuts it by more than this (m/s),
#: times ``1 + |a| . |qd|`` (the rounding of the product grows with the command).
BARRIER_TOLERANCE = 1e-12

#: Below this ratio of the smallest to the largest LU pivot of a square ``J_a``, ``F_a``
#: can no longer take every twist at a sane joint speed (``J_a^-1`` would amplify by more
#: than about its inverse), and the analytical form hands over to the general null-space
#: form, which holds the rows exactly and damps instead.
PRE_CHAIN_PIVOT_RATIO = 1e-2

#: The same hand-over for a redundant pre-chain, on the smallest singular value of
#: ``J_a`` (m/s or rad/s per rad/s).
PRE_CHAIN_MIN_SINGULAR_VALUE = 1e-2

#: The LU fast path for a square ``Jbar`` needs the certified lower bound on its smallest
#: singular value to be at least this as well as the damping threshold, so the SVD path
#: keeps every nearly rank-deficient case (it drops singular values below 1e-10).
FAST_PATH_MIN_SIGMA = 1e-6

#: ``rcond`` of the least-squares step towards the posture within ``null(Jbar)`` of a
#: wide analytical ``Jbar`` (NumPy's ``lstsq``).
LEAST_SQUARES_RCOND = 1e-10

#: A least-squares solution of the rows with a residual above this (m/s) means the
#: constraints conflict.
CONFLICT_RESIDUAL = 1e-9

#: The rows count as held over the free joints of a saturated step up to this residual (m/s).
ROWS_TOLERANCE = 1e-9

#: ``bound - base`` within this of 0, relative to ``1 + |bound| + max |base|``, counts as
#: 0: the base at the bound up to rounding (a solve's error is about ``eps cond`` of its
#: largest entry; 1e-10 is the rank cut's ``cond`` of 1e10 times eps, as in
#: :func:`controllers.linalg.nullspace`); so does an entry of the direction below this
#: times its largest.
AT_BOUND = 1e-10

#: Relative margin of the box the saturation tests its iterates against, and below which
#: a bound under the velocity limit is a position bound.
BOX_MARGIN = 1e-12

#: A direction entry at most this (rad/s) is a joint the task does not move.
STILL_DIRECTION = 1e-12

#: With acceleration limits a held joint is released when its reduced gradient points
#: into its box by more than this, relative to ``1 + max |gradient|`` (docs/design.md 9.1).
RELEASE_TOLERANCE = 1e-9

#: The paper's ``1/a`` structure matrix is undefined where ``a = |p|`` is below this (m).
PAPER_FORM_MIN_A = 1e-6


@dataclass(frozen=True)
class StepTolerances:
    """Every tolerance and threshold a CJM step decides with (the constants of this module)."""

    equality: float = EQUALITY_TOLERANCE
    twist: float = TWIST_TOLERANCE
    barrier: float = BARRIER_TOLERANCE
    rank: float = RANK_TOLERANCE
    pre_chain_pivot_ratio: float = PRE_CHAIN_PIVOT_RATIO
    pre_chain_min_singular_value: float = PRE_CHAIN_MIN_SINGULAR_VALUE
    fast_path_min_sigma: float = FAST_PATH_MIN_SIGMA
    least_squares_rcond: float = LEAST_SQUARES_RCOND
    conflict_residual: float = CONFLICT_RESIDUAL
    rows: float = ROWS_TOLERANCE
    at_bound: float = AT_BOUND
    box_margin: float = BOX_MARGIN
    still_direction: float = STILL_DIRECTION
    release_tolerance: float = RELEASE_TOLERANCE
