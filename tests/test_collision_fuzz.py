"""The closed-loop collision fuzz (tests/collision_fuzz.py), a few runs per controller:
random crossing targets on sda10f_dual with a trocar on each arm. No pair penetrates, no
pair comes closer than d_s - 0.5 mm, every command is finite and inside the joint box;
the 2,000-run figures are in docs/results.md (``python -m tests.collision_fuzz``)."""

from __future__ import annotations

import pytest

from collision_fuzz import fuzz

RUNS, STEPS = 6, 600

#: the optimisers whose steps in a sliver are now solved (deterministic: their failures
#: depend on their iteration caps alone): daqp's "infeasible" and its proximal cycling,
#: proxqp's caps (971 of these 3,600 steps before its second solve with
#: PROXQP_CAPPED_RHO); osqp's stages at its cap with the adaptive rho, solved again with a
#: fixed one (OSQP_CAPPED_SETTINGS: 0 of these 3,600 steps fail)
SLIVER_SOLVED = ("qp:daqp", "qp:proxqp", "qp:osqp")


@pytest.mark.parametrize("spec", ["cjm", "cjm:python", "qp:daqp", "qp:proxqp", "qp:osqp",
                                  "mink:daqp"])
def test_no_pair_comes_closer_than_the_safety_distance(spec):
    result = fuzz(spec, RUNS, STEPS, seed=7)
    assert result.steps == RUNS * STEPS and result.non_finite == 0
    assert result.box_violations == 0
    assert result.penetrations == 0
    assert result.below_safety == 0, (result.minimum_distance, result.worst_run)
    assert result.minimum_distance >= 0.0045
    if spec in SLIVER_SOLVED:
        # where the collision rows meet the box beside the trocars' rows in a sliver daqp
        # calls infeasible, the stages run again under the rows held at the least-residual
        # command's values, and its proximal stages converge with zero_tol below eta_prox:
        # at most 0.1 % of steps fail (daqp failed 1,427 of 40,000 steps as infeasible, then
        # 297 at its iteration cap, on 100 runs of seed 0 before; 0 now)
        assert result.statuses.get("failed", 0) <= 1e-3 * result.steps, result.failures
