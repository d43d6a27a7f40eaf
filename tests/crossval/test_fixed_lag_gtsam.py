"""The fixed-lag Smoother against gtsam's BatchFixedLagSmoother on the same streams (one pose per
call, both run to a relative decrease of 1e-14): after every call, the estimates of the poses
in the window agree within 1e-6 (entries of the pose matrices). gtsam's loop can stall a little
short of the window's minimum (no λ lowers its error), which is why the tolerance is not
tighter; posegraph's window estimate equals a batch solve of the same model (test_fixed_lag)."""

from __future__ import annotations

import pytest
from posegraph_datasets.generators import visual_odometry

from posegraph.lie import SE2, SE3

pytest.importorskip("gtsam")
from posegraph.benchmarks.fixed_lag import lockstep  # noqa: E402

TOLERANCE = 1e-6


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_fixed_lag_smoother_equals_gtsams_batch_fixed_lag_smoother(group):
    stream, _ = visual_odometry(group, poses=60, reach=8, seed=1)
    differences = lockstep(stream, lag=8).differences
    assert len(differences) == 60
    assert max(max(pair) for pair in differences) < TOLERANCE
