"""A corpus of malformed graph files, each with the line and the words its error must name.

Shared by the reader tests and the command-line tests.
"""

from __future__ import annotations

V0 = "VERTEX_SE2 0 0 0 0\n"
V1 = "VERTEX_SE2 1 1 0 0\n"
INFO2 = "1 0 0 1 0 1"
Q = "0 0 0 1"
INFO3 = " ".join("1" if c == r else "0" for r in range(6) for c in range(r, 6))
SE3_V0 = f"VERTEX_SE3:QUAT 0 0 0 0 {Q}\n"
SE3_V1 = f"VERTEX_SE3:QUAT 1 1 0 0 {Q}\n"

# (name, file content or None for a missing file, line or None, words the message must contain)
MALFORMED = [
    (
        "vertex-too-few-numbers",
        "VERTEX_SE2 0 0 0\n",
        1,
        "expected 4 numbers after the tag, found 3",
    ),
    (
        "edge-too-many-numbers",
        V0 + V1 + f"EDGE_SE2 0 1 1 0 0 {INFO2} 7\n",
        3,
        "expected 11 numbers",
    ),
    ("non-numeric-value", "VERTEX_SE2 0 0 zero 0\n", 1, "'zero' is not a number"),
    (
        "nan-value",
        SE3_V0 + SE3_V1 + f"EDGE_SE3:QUAT 0 1 nan 0 0 {Q} {INFO3}\n",
        3,
        "NaN or infinite",
    ),
    ("infinite-value", "VERTEX_SE2 0 inf 0 0\n", 1, "NaN or infinite"),
    (
        "information-not-positive-semi-definite",
        V0 + V1 + "EDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1\n",
        3,
        "not positive semi-definite (λ_min = -1)",
    ),
    (
        "information-all-zero",
        V0 + V1 + "EDGE_SE2 0 1 1 0 0 0 0 0 0 0 0\n",
        3,
        "information matrix is zero (it would weigh nothing)",
    ),
    (
        "edge-to-unknown-vertex",
        V0 + V1 + f"EDGE_SE2 0 7 1 0 0 {INFO2}\n",
        3,
        "refers to node 7, which has no vertex line",
    ),
    (
        "duplicate-vertex-id",
        V0 + V1 + "VERTEX_SE2 1 5 5 0\n",
        3,
        "vertex 1 is defined again (first on line 2)",
    ),
    (
        "zero-norm-vertex-quaternion",
        "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n",
        1,
        "quaternion has zero norm",
    ),
    (
        "zero-norm-edge-quaternion",
        SE3_V0 + SE3_V1 + f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 0 {INFO3}\n",
        3,
        "quaternion has zero norm",
    ),
    (
        "quaternion-norm-overflows",
        "VERTEX_SE3:QUAT 0 0 0 0 1e200 0 0 1\n",
        1,
        "quaternion's norm overflows",
    ),
    (
        "sim3-log-scale-overflows",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 0 0 0 1e20 1 1 0 0\n",
        1,
        "a number is out of range: the line's pose or information overflows",
    ),
    (
        "sim3-log-scale-underflows",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 0 0 0 -1e20 1 1 0 0\n",
        1,
        "a number is out of range",
    ),
    (
        "edge-translation-squares-overflow",
        V0 + V1 + f"EDGE_SE2 0 1 1e200 0 0 {INFO2}\n",
        3,
        "EDGE_SE2: a number is out of range: the edge's translation weighed by its information "
        "overflows (Ad(Z⁻¹)ᵀ Ω Ad(Z⁻¹) at node 0)",
    ),
    (
        "se3-edge-translation-near-largest-double",
        SE3_V0 + SE3_V1 + f"EDGE_SE3:QUAT 0 1 0 0 1e308 {Q} {INFO3}\n",
        3,
        "the edge's translation weighed by its information overflows",
    ),
    ("empty-file", "", None, "holds no vertices or edges"),
    ("only-comments", "# nothing here\n\n   \n", None, "holds no vertices or edges"),
    ("missing-file", None, None, "no such file"),
    ("unknown-tag", V0 + "VERTEX_XYZ 1 0 0 0\n", 2, "unknown tag 'VERTEX_XYZ'"),
    ("landmark-tag", V0 + "VERTEX_XY 1 2 3\n", 2, "landmark tag 'VERTEX_XY': posegraph optimises"),
    ("fractional-id", "VERTEX_SE2 1.5 0 0 0\n", 1, "node ids must be whole numbers"),
    ("negative-id", "VERTEX_SE2 -3 0 0 0\n", 1, "node ids must be whole numbers"),
    ("id-beyond-int64", "VERTEX_SE2 9223372036854775808 0 0 0\n", 1, "from 0 to 2⁶³ − 1"),
    ("mixed-groups", V0 + SE3_V1, 2, "mixes SE3 and SE2 lines"),
    ("self-loop", V0 + f"EDGE_SE2 0 0 1 0 0 {INFO2}\n", 2, "edge from node 0 to itself"),
    ("fix-unknown-node", V0 + V1 + "FIX 9\n", 3, "refers to node 9"),
    (
        "sim3-edge-wrong-count",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1\nEDGE_SIM3:EXPMAP 0 1 " + " ".join(["0"] * 34) + "\n",
        2,
        "expected 38 or 37 numbers",
    ),
    (
        "sim3-mixed-dialects",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1\nVERTEX_SIM3:EXPMAP 1 0 0 0 0 0 0 0 1 1 0 0\n",
        2,
        "two dialects",
    ),
    ("only-fix-lines", "FIX 0\n", 1, "only FIX lines"),
    (
        "se3-prior-offset-undefined",
        SE3_V0 + SE3_V1 + f"EDGE_SE3_PRIOR 0 2 0 0 0 0 0 0 1 {INFO3}\n",
        3,
        "offset parameter 2 is not defined by a PARAMS_SE3OFFSET line",
    ),
    (
        "se3-offset-defined-twice",
        "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1\nPARAMS_SE3OFFSET 0 1 0 0 0 0 0 1\n" + SE3_V0,
        2,
        "PARAMS_SE3OFFSET 0 is defined again (first on line 1)",
    ),
    ("equiv-unknown-node", "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEQUIV 0 4\n", 3, "refers to node 4"),
    (
        "toro-information-not-positive-semi-definite",
        "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 -1 0 0\n",
        3,
        "not positive semi-definite",
    ),
    (
        "edge2-information-in-g2o-order",
        "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 4 1 0.5 9 2 16\n",
        3,
        "read it with --edge2-order g2o",
    ),
    (
        "edge-without-information",
        "VERTEX3 0 0 0 0 0 0 0\nVERTEX3 1 1 0 0 0 0 0\nEDGE3 0 1 1 0 0 0 0 0\n",
        3,
        "the line has no information matrix (--identity-information",
    ),
    ("not-text", b"\x89PNG\r\n\x1a\n\x00\xff\xfe", None, "is not a text file"),
    (
        "sim3-negative-scale",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1\nVERTEX_SIM3:EXPMAP 1 0 0 0 1 0 0 0 -2\n",
        2,
        "VERTEX_SIM3:EXPMAP: the line's pose is not an element of Sim3 (its matrix has "
        "determinant -0.125)",
    ),
    (
        "sim3-scale-whose-inverse-has-determinant-zero",
        "VERTEX_SIM3:EXPMAP 0 0 0 0 1 0 0 0 1\nVERTEX_SIM3:EXPMAP 1 0 0 0 1 0 0 0 1e120\n",
        2,
        "is not an element of Sim3 (its matrix has determinant 0)",
    ),
    (
        "tum-trajectory-given-as-a-graph",
        "0.0 1 2 3 0 0 0 1\n0.1 1 2 3 0 0 0 1\n",
        1,
        "unknown tag '0.0': a line of numbers, as in a TUM or KITTI trajectory, not a g2o",
    ),
]
