"""JSON Schemas of the log's topics: any MCAP reader can decode and check every message."""

from typing import Any

VEC = {"type": "array", "items": {"type": "number"}}
CONTACT = {"type": "array", "items": {"type": "string"}, "minItems": 2, "maxItems": 2}
POSE_PROPERTIES: dict[str, Any] = {
    "xyz": {**VEC, "minItems": 3, "maxItems": 3},
    "quat_xyzw": {**VEC, "minItems": 4, "maxItems": 4},
}
POSE = {"type": "object", "properties": POSE_PROPERTIES, "required": ["xyz", "quat_xyzw"]}
ROTATION = {
    "type": "array",
    "items": {**VEC, "minItems": 3, "maxItems": 3},
    "minItems": 3,
    "maxItems": 3,
}
SETPOINT = {  # a motion's G_d: the pose and its rotation matrix exactly as simulated
    "type": "object",
    "properties": {**POSE_PROPERTIES, "rotation": ROTATION},
    "required": ["xyz", "quat_xyzw", "rotation"],
}
PARTICLE = {
    "type": "object",
    "properties": {
        "X_WM": POSE,
        "contacts": {"type": "array", "items": CONTACT},
        "q": {**VEC, "minItems": 7, "maxItems": 7},  # arm joints [rad]; absent in older logs
        "stopped": {"type": "string"},  # why its arm stopped (a joint at its limit)
        # environment pieces the arm or hand (not the part) touches; absent when none
        "arm_touches": {"type": "array", "items": {"type": "string"}},
    },
    "required": ["X_WM", "contacts"],
}
MOTION = {
    "type": "object",
    "properties": {
        "K": {
            "type": "array",
            "items": {**VEC, "minItems": 6, "maxItems": 6},
            "minItems": 6,
            "maxItems": 6,
        },
        "G_d": SETPOINT,
        "timeout_s": {"type": "number"},
    },
    "required": ["K", "G_d", "timeout_s"],
}


def _object(properties: dict[str, Any], title: str) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
        "required": sorted(properties),
    }


TOPICS: dict[str, dict[str, Any]] = {
    "/metadata": _object(
        {
            "task": {
                "type": "object",
                "properties": {"name": {"type": "string"}},
                "required": ["name"],
            },
            "planner": {"type": "string"},
            "parameters": {"type": "object"},
            "seed": {"type": "integer"},
            "versions": {"type": "object"},
            "host": {"type": "string"},
        },
        "bilba.Metadata",
    ),
    "/schedule": _object(
        {"attempt": {"type": "integer"}, "schedule": {"type": "array", "items": CONTACT}},
        "bilba.Schedule",
    ),
    "/pruned": _object(
        {"edge": {"type": "array", "items": CONTACT}, "reason": {"type": "string"}}, "bilba.Pruned"
    ),
    "/transition": _object(
        {
            "index": {"type": "integer"},
            "contact_sought": CONTACT,
            "motion": MOTION,
            "before": {"type": "array", "items": PARTICLE},
            "after": {"type": "array", "items": PARTICLE},
            "score": {"type": "number"},
            "count": {"type": "integer"},
            "accepted": {"type": "boolean"},
        },
        "bilba.Transition",
    ),
    "/gp_round": _object(
        {
            "contact_sought": CONTACT,
            "training_size": {"type": "integer"},
            "predicted_best": {"type": "number"},
            "simulated_best": {"type": "number"},
        },
        "bilba.GPRound",
    ),
    "/verify": _object(
        {
            "particles": {"type": "integer"},
            "held": {"type": "object", "additionalProperties": {"type": "number"}},
            "passed": {"type": "boolean"},
            "plan": {"type": "integer"},
        },
        "bilba.Verify",
    ),
    "/restart": _object(
        {
            "points": {"type": "integer"},
            "particles": {"type": "integer"},
            "reason": {"type": "string"},
        },
        "bilba.Restart",
    ),
    "/resume": _object(
        {"contact": {"type": "string"}, "motions": {"type": "integer"}},
        "bilba.Resume",
    ),
    "/plan": {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "bilba.Plan",
        "type": "object",
        "required": ["format", "version", "motions"],
    },
    "/outcome": _object(
        {
            "success": {"type": "boolean"},
            "reason": {"type": "string"},
            "planning_time_s": {"type": "number"},
            "rollouts": {"type": "integer"},
            "verified": {"type": ["boolean", "null"]},
        },
        "bilba.Outcome",
    ),
}
