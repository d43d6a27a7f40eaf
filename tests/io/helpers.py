"""Files and helpers shared by the reader's and the writer's tests."""

from __future__ import annotations

import numpy as np

from posegraph.graph import PoseGraph


def assert_same_graph(a: PoseGraph, b: PoseGraph, atol: float = 0.0) -> None:
    assert a.group is b.group
    np.testing.assert_array_equal(a.node_ids, b.node_ids)
    np.testing.assert_allclose(a.values.as_matrix(), b.values.as_matrix(), atol=atol, rtol=0)
    for x, y in ((a.edges, b.edges), (a.priors, b.priors)):
        np.testing.assert_array_equal(a.node_ids[x.i], b.node_ids[y.i])
        np.testing.assert_array_equal(a.node_ids[x.j], b.node_ids[y.j])
        np.testing.assert_allclose(
            x.measurements.as_matrix(), y.measurements.as_matrix(), atol=atol, rtol=0
        )
        np.testing.assert_allclose(x.information, y.information, rtol=1e-15, atol=atol)
    np.testing.assert_array_equal(a.fixed, b.fixed)
    np.testing.assert_array_equal(a.equivalences, b.equivalences)
