"""cvxopt's bundled OpenBLAS gets the kernels that the CPU's instruction sets allow, chosen
before it loads, and the environment is left as it was."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from posegraph.problem.cvxopt_import import core_type

pytest.importorskip("cvxopt")
pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="reads the loaded libraries from /proc/self/maps"
)

PROBE = """
import ctypes, json, os
from posegraph.problem.cvxopt_import import _cpu_features, core_type, import_cholmod
import_cholmod()
paths = sorted({line.split()[-1] for line in open("/proc/self/maps") if "libopenblas" in line})
names = []
for path in paths:
    corename = getattr(ctypes.CDLL(path), "openblas_get_corename", None)
    if corename is not None:
        corename.restype = ctypes.c_char_p
        names.append(corename().decode())
print(json.dumps({
    "expected": core_type(_cpu_features()),
    "cores": names,
    "variable": os.environ.get("OPENBLAS_CORETYPE"),
}))
"""


def _probe(environment: dict[str, str]) -> dict:
    """Import CHOLMOD in a fresh process: the kernels of each OpenBLAS loaded by name, what
    ``core_type`` expects here, and OPENBLAS_CORETYPE afterwards."""
    run = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, env=environment, check=True
    )
    return json.loads(run.stdout)


@pytest.mark.parametrize(
    "features, expected",
    [
        ({"FMA3": True, "AVX2": True, "AVX512_SKX": True}, "SkylakeX"),
        ({"FMA3": True, "AVX2": True, "AVX512_SKX": False}, "Haswell"),
        ({"FMA3": False, "AVX2": True}, None),
        ({"FMA3": True, "AVX2": False}, None),
        ({}, None),
    ],
)
def test_core_type_is_the_best_kernel_the_instruction_sets_allow(features, expected):
    assert core_type(features) == expected


def test_cvxopt_openblas_runs_the_chosen_kernels_and_the_environment_is_restored():
    environment = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    probed = _probe(environment)
    if not probed["cores"]:
        pytest.skip("no OpenBLAS loaded by the name libopenblas (cvxopt without its own)")
    if probed["expected"] is None:
        pytest.skip("this CPU has neither AVX2 with FMA3 nor AVX-512: OpenBLAS chooses")
    assert probed["cores"] == [probed["expected"]]
    assert probed["variable"] is None


def test_a_users_choice_of_kernels_stands():
    environment = {**os.environ, "OPENBLAS_CORETYPE": "Prescott"}
    probed = _probe(environment)
    if not probed["cores"]:
        pytest.skip("no OpenBLAS loaded by the name libopenblas (cvxopt without its own)")
    assert probed["cores"] == ["Prescott"]
    assert probed["variable"] == "Prescott"
