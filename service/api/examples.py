"""The examples of the OpenAPI document: one valid request per operation that takes a body, so that the
interactive documentation's "Try it out" sends a request the service accepts (without them Swagger UI builds
a body from the schema, and its made-up scene was a 422). Built from the model's own templates, so they stay
valid as the scene schema changes; ``tests/test_openapi_examples.py`` sends every one to the app.
"""

from __future__ import annotations

from typing import Any

__all__ = ["add_examples"]


def _bodies() -> dict[str, dict[str, dict[str, Any]]]:
    """Path -> OpenAPI ``examples`` (name -> {summary, value}) of its POST body."""
    from ...model import template
    from ...model.scene import Scene
    from ...model.spacar import write_dat
    from ...optim.pareto import example_spec as pareto_example

    leaf = template("leaf-spring", points=5, segments=4).model_dump(mode="json")
    guide = template("wire-guide-parallel").model_dump(mode="json")
    half = {**leaf, "stroke": {**leaf["stroke"], "start": 0.0}}  # SPACAR inputs run from the reference
    return {
        "/v1/scenes/export": {
            "leaf": {"summary": "the leaf spring as a SPACAR .dat model (stroke 0 to 45 deg)", "value": {"scene": half}}
        },
        "/v1/scenes/import": {
            "leaf": {
                "summary": "the leaf spring's SPACAR .dat model",
                "value": {"text": write_dat(Scene.model_validate(half)), "name": "leaf"},
            }
        },
        "/v1/state-space": {
            "leaf": {
                "summary": "the leaf spring at 30 deg: the tip's vertical force to its vertical position",
                "value": {"scene": leaf, "at_stroke": 30.0, "inputs": ["tip.fz"], "outputs": ["tip.z"]},
            }
        },
        "/v1/templates/{name}/scene": {
            "thickness": {"summary": "a thinner leaf, with a unit", "value": {"parameters": {"thickness": "0.3 mm"}}}
        },
        "/v1/frequency-curve": {
            "leaf": {
                "summary": "the leaf spring (4 segments, 5 stroke points), method auto",
                "value": {"scene": leaf, "method": "auto", "tolerance": 0.01},
            }
        },
        "/v1/diagnosis": {
            "guide": {"summary": "the wire guide (parallel): exact constraint, kinematic", "value": {"scene": guide}}
        },
        "/v1/modes": {
            "leaf": {"summary": "the leaf spring's modes at 30 deg", "value": {"scene": leaf, "at_stroke": 30.0}}
        },
        "/v1/optimisations": {
            "pivot": {
                "summary": "a small cross-spring pivot problem (one start, 5 samples)",
                "value": {
                    "families": [
                        {
                            "template": "cross-spring-pivot",
                            "fixed": {"segments": 4},
                            "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]},
                        }
                    ],
                    "starts": 1,
                    "samples": 5,
                    "verify_points": 31,
                },
            }
        },
        "/v1/pareto-fronts": {
            "pivot": {"summary": "the small front of GET /v1/pareto-fronts/example", "value": pareto_example()}
        },
        "/v1/topology-searches": {
            "two": {
                "summary": "two topologies, one start each",
                "value": {"topologies": ["R:+-", "R:++"], "segments": 4, "samples": 5, "starts": 1},
            }
        },
    }


#: path parameter -> an example value
_PARAMETERS = {"name": "leaf-spring"}


def add_examples(doc: dict[str, Any]) -> None:
    """Put the request examples into the OpenAPI document ``doc`` (in place)."""
    bodies = _bodies()
    for path, item in doc.get("paths", {}).items():
        for method, op in item.items():
            for p in op.get("parameters", []):
                if p.get("in") == "path" and p["name"] in _PARAMETERS:
                    p["example"] = _PARAMETERS[p["name"]]
            content = op.get("requestBody", {}).get("content", {}).get("application/json")
            if method == "post" and content is not None and path in bodies:
                content["examples"] = bodies[path]
