"""JSON Schemas (draft 2020-12) of the documents ``--json`` prints; the README shows them."""

from __future__ import annotations

_NUMBER = {"type": ["number", "null"]}
"""A number, or null where it is not finite (JSON has no NaN or ∞): an error that overflowed."""
_COUNT = {"type": "integer", "minimum": 0}
_STATS = {
    "type": "object",
    "required": ["rmse", "mean", "median", "max", "count"],
    "properties": {
        "rmse": _NUMBER,
        "mean": _NUMBER,
        "median": _NUMBER,
        "max": _NUMBER,
        "count": {"type": "integer"},
    },
}
_DRIFT = {
    "type": "object",
    "required": ["lengths", "segments", "translation_percent", "rotation_deg_per_100m"],
    "properties": {
        "lengths": {"type": "array", "items": {"type": "number"}},
        "segments": {"type": "integer", "minimum": 1},
        "translation_percent": _NUMBER,
        "rotation_deg_per_100m": _NUMBER,
    },
}
_PATH_OR_NULL = {"type": ["string", "null"]}
_SKIPPED_LINES = {
    "type": "array",
    "items": {
        "type": "object",
        "required": ["path", "reason", "count", "first_line"],
        "properties": {
            "path": {"type": "string"},
            "reason": {"type": "string"},
            "count": {"type": "integer", "minimum": 1},
            "first_line": {"type": "integer", "minimum": 1},
        },
    },
}
"""What ``--lenient`` reading skipped, by file and reason, most frequent first; empty if nothing."""

NOISE = {
    "type": "array",
    "items": {
        "type": "object",
        "required": ["kind", "count", "redundancy", "chi2_per_dof", "above_quantile"],
        "properties": {
            "kind": {"enum": ["odometry", "loop closures", "priors"]},
            "count": {"type": "integer", "minimum": 1},
            "redundancy": _NUMBER,
            "chi2_per_dof": {"type": ["number", "null"]},
            "above_quantile": _COUNT,
        },
    },
}
"""Noise consistency per class of measurement (``posegraph.robust.noise.NoiseClass``)."""

SUMMARY = {
    "type": "object",
    "required": [
        "method",
        "linear_solver",
        "initial_error",
        "final_error",
        "initial_chi2",
        "final_chi2",
        "iterations",
        "termination",
        "converged",
        "phase_times",
        "total_time",
        "num_variables",
        "reused",
        "initialization",
        "initialization_time",
        "history",
    ],
    "properties": {
        "method": {"enum": ["lm", "gn"]},
        "linear_solver": {"enum": ["cholmod", "scipy", "cg"]},
        "initial_error": _NUMBER,
        "final_error": _NUMBER,
        "initial_chi2": _NUMBER,
        "final_chi2": _NUMBER,
        "iterations": _COUNT,
        "termination": {"type": "string"},
        "converged": {"type": "boolean"},
        "phase_times": {
            "type": "object",
            "required": ["linearize", "assemble", "factorize", "solve", "other"],
            "additionalProperties": _NUMBER,
        },
        "total_time": _NUMBER,
        "num_variables": {"type": "integer"},
        "reused": {"type": "array", "items": {"type": "string"}},
        "initialization": {"type": "string"},
        "initialization_time": _NUMBER,
        "input_error": {"type": ["number", "null"]},
        "robust": {"type": ["string", "null"]},
        "rejected_edges": {"type": "array", "items": {"type": "integer"}},
        "rejected_priors": {"type": "array", "items": {"type": "integer"}},
        **dict.fromkeys(["edges_under_kernel", "priors_under_kernel"], _COUNT),
        "noise": NOISE,
        "calibration": {
            "type": ["object", "null"],
            "required": ["scales", "automatic", "solves"],
            "properties": {
                "scales": {"type": "object", "additionalProperties": _NUMBER},
                **dict.fromkeys(["solves", "consistent_rejections"], _COUNT),
                **dict.fromkeys(["automatic", "second_opinion"], {"type": "boolean"}),
            },
        },
        "history": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["iteration", "error", "damping", "step_norm", "accepted", "elapsed"],
                "properties": {
                    "iteration": {"type": "integer"},
                    "error": _NUMBER,
                    "damping": _NUMBER,
                    "step_norm": _NUMBER,
                    "accepted": {"type": "boolean"},
                    "elapsed": _NUMBER,
                    "stage": {"type": "string"},
                },
            },
        },
    },
}

ERROR = {
    "type": "object",
    "required": ["command", "error"],
    "properties": {
        "command": {"type": "string"},
        "error": {
            "type": "object",
            "required": ["kind", "exit_code", "message", "path", "line"],
            "properties": {
                "kind": {"enum": ["bad_input", "internal", "interrupted"]},
                "exit_code": {"enum": [1, 2, 3, 130]},
                "message": {"type": "string"},
                "path": _PATH_OR_NULL,
                "line": {"type": ["integer", "null"], "minimum": 1},
            },
        },
    },
}
"""What ``--json`` prints instead when a command stops on bad input, an internal error or
Ctrl-C (exit 1 when outputs were written first, else 130): ``message`` is the line on stderr;
``path`` and ``line`` name the file and line at fault."""

_READING = {
    "repaired_information": _COUNT,
    "rotation_information": {"enum": ["phi", "quaternion", None]},
}
"""How the information was read: the matrices that ``--repair-information`` changed, and the
weighting of SE3 and Sim3 rotation information (over φ as gtsam; over the quaternion's vector
as g2o, ``--g2o-rotation-information``; null for SE2)."""

CERTIFICATE = {
    "type": "object",
    "required": ["verdict", "objective", "smallest_eigenvalue", "tolerance", "certified",
                 "lower_bound", "rank", "gradient_norm", "time", "steps"],
    "properties": {
        "verdict": {"enum": ["certified", "not certified"]},
        "certified": {"type": "boolean"},
        "rank": {"type": "integer"},
        "steps": {"type": "array", "items": {"type": "object", "required": ["rank", "objective"]}},
        **{key: _NUMBER for key in ("objective", "smallest_eigenvalue", "tolerance", "time")},
    },
}  # fmt: skip
"""``posegraph.Certificate.as_dict``: SE-Sync's check of the estimate (``certify``)."""

SCHEMAS = {
    "certify": {
        "type": "object",
        "required": ["command", "input", "posegraph_error", "certificate"],
        "properties": {
            "command": {"const": "certify"},
            "output": _PATH_OR_NULL,
            "certificate": CERTIFICATE,
        },  # fmt: skip
    },
    "scale-drift": {
        "type": "object",
        "required": [
            "command",
            "input",
            "output",
            "plot",
            "convention",
            "nodes",
            "edges",
            "scale_range",
            "lifted_scale_information",
            "repaired_information",
            "rotation_information",
            "summary",
            "ate_before",
            "ate_after",
            "skipped_lines",
        ],
        "properties": {
            "command": {"const": "scale-drift"},
            "skipped_lines": _SKIPPED_LINES,
            "convention": {"enum": ["world_from_camera", "camera_from_world"]},
            "scale_range": {"type": "array", "items": _NUMBER, "minItems": 2, "maxItems": 2},
            "lifted_scale_information": {"type": ["number", "null"]},
            **_READING,
            "summary": SUMMARY,
            "ate_before": {"type": ["number", "null"]},
            "ate_after": {"type": ["number", "null"]},
        },
    },
    "optimize": {
        "type": "object",
        "required": [
            "command",
            "input",
            "output",
            "plot",
            "covariances",
            "group",
            "nodes",
            "edges",
            "lifted_scale_information",
            "repaired_information",
            "rotation_information",
            "summary",
            "skipped_lines",
        ],
        "properties": {
            "command": {"const": "optimize"},
            "skipped_lines": _SKIPPED_LINES,
            "input": {"type": "string"},
            "output": _PATH_OR_NULL,
            "plot": _PATH_OR_NULL,
            "covariances": _PATH_OR_NULL,
            "group": {"enum": ["SE2", "SE3", "Sim3"]},
            "nodes": {"type": "integer"},
            "edges": {"type": "integer"},
            "lifted_scale_information": {"type": ["number", "null"]},
            **_READING,
            "summary": SUMMARY,
            "certificate": CERTIFICATE,
        },
    },
    "info": {
        "type": "object",
        "required": [
            "command",
            "path",
            "file_format",
            "group",
            "tag_counts",
            "nodes",
            "edges",
            "loop_closures",
            "priors",
            "components",
            "gauge",
            "condition_numbers",
            "singular_information",
            "initial_error",
            "initial_chi2",
            "problems",
            "lifted_scale_information",
            "repaired_information",
            "rotation_information",
            "noise",
            "skipped_lines",
        ],
        "properties": {
            "certificate": {"anyOf": [CERTIFICATE, {"type": "null"}]},
            "command": {"const": "info"},
            "noise": NOISE,
            "skipped_lines": _SKIPPED_LINES,
            "file_format": {"enum": ["g2o", "toro"]},
            "tag_counts": {"type": "object", "additionalProperties": {"type": "integer"}},
            "components": {"type": "array", "items": {"type": "integer"}},
            "condition_numbers": {"type": "object", "additionalProperties": _NUMBER},
            "singular_information": _COUNT,
            "loop_closures": _COUNT,
            "lifted_scale_information": {"type": ["number", "null"]},
            **_READING,
            "problems": {
                "type": "array",
                "items": {
                    "type": "object",
                    "required": ["what", "suggestion"],
                    "properties": {"what": {"type": "string"}, "suggestion": {"type": "string"}},
                },
            },
        },
    },
    "convert": {
        "type": "object",
        "required": ["command", "input", "output", "format", "nodes", "edges", "skipped_lines"],
        "properties": {
            "command": {"const": "convert"},
            "skipped_lines": _SKIPPED_LINES,
            "format": {"enum": ["g2o", "toro", "tum", "kitti"]},
        },
    },
    "plot": {
        "type": "object",
        "required": ["command", "inputs", "output", "skipped_lines"],
        "properties": {
            "command": {"const": "plot"},
            "skipped_lines": _SKIPPED_LINES,
            "inputs": {"type": "array", "items": {"type": "string"}},
        },
    },
    "eval": {
        "type": "object",
        "required": [
            "command",
            "estimate",
            "ground_truth",
            "plot",
            "alignment",
            "scale",
            "matched_poses",
            "estimate_poses",
            "max_time_difference",
            "ate",
            "rpe_translation",
            "rpe_rotation_deg",
            "planar_ate_floor",
            "segment_lengths",
            "drift",
            "drift_by_length",
            "skipped_lines",
        ],
        "properties": {
            "command": {"const": "eval"},
            "skipped_lines": _SKIPPED_LINES,
            "alignment": {"enum": ["se3", "sim3", "none"]},
            "scale": _NUMBER,
            "matched_poses": {"type": "integer"},
            "estimate_poses": {"type": "integer"},
            "max_time_difference": _NUMBER,
            "ate": _STATS,
            "rpe_translation": _STATS,
            "rpe_rotation_deg": _STATS,
            "planar_ate_floor": _NUMBER,
            "segment_lengths": {"type": "array", "items": {"type": "number"}},
            "drift": {"oneOf": [_DRIFT, {"type": "null"}]},
            "drift_by_length": {"type": "array", "items": _DRIFT},
        },
    },
    "bench": {
        "type": "object",
        "required": ["command", "solver", "gtsam", "table"],
        "properties": {
            "command": {"const": "bench"},
            "solver": {"enum": ["lm", "dogleg"]},
            "gtsam": {"type": "boolean"},
            "table": {"type": "string"},
        },
    },
    "generate": {
        "type": "object",
        "required": ["command", "kind", "output", "truth", "nodes", "edges", "false_edges"],
        "properties": {
            "command": {"const": "generate"},
            "kind": {"enum": ["sphere", "grid", "manhattan", "monocular", "false-loops"]},
            "truth": {"type": ["string", "null"]},
            "nodes": {"type": "integer"},
            "edges": {"type": "integer"},
            "false_edges": {"type": "integer"},
        },
    },
    "datasets": {
        "type": "object",
        "required": ["command", "action", "graphs"],
        "properties": {
            "command": {"const": "datasets"},
            "action": {"enum": ["list", "download"]},
            "folder": {"type": "string"},
            "graphs": {
                "type": "array",
                "items": {
                    "type": "object",
                    "required": ["name", "path"],
                    "properties": {
                        "name": {"type": "string"},
                        "path": {"type": ["string", "null"]},
                        "downloaded": {"type": "boolean"},
                    },
                },
            },
        },
    },
}
