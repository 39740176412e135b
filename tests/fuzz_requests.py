"""A structural and semantic mutation fuzzer's request generator over every POST route of the service (issue 29).

Starts from the OpenAPI document's examples (one valid body per POST route, ``service.api.examples``) and the
built-in templates' scenes as they come (``truss12``'s stroke null included), and mutates them: numbers
replaced by extreme finite values, signs, zeros and subnormals; keys dropped or added; values replaced by the
wrong type; nesting hundreds of levels deep; node names that exist nowhere; lists repeated. Every scene is
distinct (a thickness or length scaled by the request's number), so no response is a cache hit.

Used by ``tests/test_service_fuzz.py`` (bounded in time) and by ``bench/bench_soak.py --fuzz`` (thousands of
requests against a real server while its memory is sampled).
"""

from __future__ import annotations

import copy
import random
from collections.abc import Iterator
from typing import Any

__all__ = ["EXTREMES", "Request", "bases", "mutated"]

#: extreme but finite numbers, signs, zeros and subnormals
EXTREMES = (1e308, -1e308, 1e-308, 5e-324, 1e-300, 1e-103, 1e15, -1e15, 1e-15, 0.0, -1.0, 1e6, 3.0)

#: (method, path, JSON body, headers)
Request = tuple[str, str, Any, dict[str, str]]

#: routes whose body carries a scene under "scene"
SCENE_ROUTES = ("/v1/frequency-curve", "/v1/modes", "/v1/diagnosis", "/v1/state-space", "/v1/scenes/export")


def bases(get: Any, post: Any) -> tuple[dict[str, Any], dict[str, dict]]:
    """The valid bodies to mutate: ``(path -> body)`` from the OpenAPI examples, and ``(name -> scene)`` of every
    template as the server gives it. ``get(path)`` and ``post(path)`` return decoded JSON (an HTTP client's)."""
    doc = get("/openapi.json")
    bodies: dict[str, Any] = {}
    for path, item in doc["paths"].items():
        op = item.get("post")
        content = (op or {}).get("requestBody", {}).get("content", {}).get("application/json")
        if content and content.get("examples"):
            bodies[path.replace("{name}", "leaf-spring")] = next(iter(content["examples"].values()))["value"]
    names = [t["name"] for t in get("/v1/templates")]
    return bodies, {n: post(f"/v1/templates/{n}/scene") for n in names}


def _numbers(doc: object, path: tuple = ()) -> list[tuple]:
    if isinstance(doc, dict):
        return [p for k, v in doc.items() for p in _numbers(v, (*path, k))]
    if isinstance(doc, list):
        return [p for i, v in enumerate(doc) for p in _numbers(v, (*path, i))]
    return [path] if isinstance(doc, (int, float)) and not isinstance(doc, bool) else []


def _containers(doc: object, path: tuple = ()) -> list[tuple]:
    out: list[tuple] = []
    if isinstance(doc, dict):
        out.append(path)
        for k, v in doc.items():
            out += _containers(v, (*path, k))
    elif isinstance(doc, list):
        out.append(path)
        for i, v in enumerate(doc):
            out += _containers(v, (*path, i))
    return out


def _at(doc: Any, path: tuple) -> Any:
    for k in path:
        doc = doc[k]
    return doc


def _deep(depth: int) -> object:
    out: object = []
    for _ in range(depth):
        out = [out]
    return out


def _distinct(scene: dict, i: int) -> None:
    """Scale the first section's thickness (or the first beam's length) by a factor unique to request ``i``."""
    for e in scene.get("elements", []):
        if isinstance(e, dict) and isinstance(e.get("section"), dict):
            for k in ("thickness", "diameter", "width"):
                if isinstance(e["section"].get(k), float):
                    e["section"][k] *= 1 + 1e-6 * i
                    return


def _mutate(body: Any, rng: random.Random) -> Any:
    """One random structural or semantic mutation of ``body`` (a deep copy)."""
    body = copy.deepcopy(body)
    kind = rng.choice(("number", "number", "number", "drop", "add", "type", "deep", "names", "repeat"))
    if kind == "number":
        nums = _numbers(body)
        for path in rng.sample(nums, k=min(len(nums), rng.choice((1, 1, 2)))):
            d = _at(body, path[:-1])
            d[path[-1]] = rng.choice(EXTREMES) if isinstance(d[path[-1]], float) else rng.choice((0, -1, 10**6, 2**63))
        return body
    conts = [p for p in _containers(body) if _at(body, p)]
    if not conts:
        return body
    where = rng.choice(conts)
    c = _at(body, where)
    key = rng.choice(list(c)) if isinstance(c, dict) else rng.randrange(len(c))
    if kind == "drop":
        del c[key]
    elif kind == "add":
        if isinstance(c, dict):
            c[f"{key}x" if isinstance(key, str) else "extra"] = rng.choice((1, "x", None, [], {}))
        else:
            c.append(copy.deepcopy(c[key]))
    elif kind == "type":
        c[key] = rng.choice(("text", None, [], {}, True, -1, [1, 2, 3], {"a": 1}))
    elif kind == "deep":
        c[key] = _deep(rng.choice((50, 255, 300)))
    elif kind == "names":
        if isinstance(body, dict) and isinstance(body.get("scene"), dict):
            for e in body["scene"].get("elements", []):
                if isinstance(e, dict) and isinstance(e.get("nodes"), list):
                    e["nodes"] = [f"{n}{rng.randrange(100)}" if isinstance(n, str) else n for n in e["nodes"]]
        else:
            c[key] = f"unknown{rng.randrange(1000)}"
    elif kind == "repeat":
        if isinstance(c, list):
            c.extend(copy.deepcopy(c) * rng.choice((1, 3)))
    return body


def mutated(
    bodies: dict[str, Any], scenes: dict[str, dict], methods: list[str], seed: int = 29, jobs: bool = True
) -> Iterator[Request]:
    """An endless stream of requests: each POST route's example, and each template's scene on the scene routes
    with every method and media type, each mutated (a tenth are sent unmutated: valid, distinct scenes).
    ``jobs`` False leaves out the job submissions (optimisations, topology searches, Pareto fronts)."""
    rng = random.Random(seed)
    job_paths = ("/v1/optimisations", "/v1/topology-searches", "/v1/pareto-fronts")
    paths = [p for p in bodies if jobs or p not in job_paths]
    i = 0
    while True:
        i += 1
        if rng.random() < 0.5 and scenes:  # a template's scene on a scene route
            name = rng.choice(sorted(scenes))
            scene = copy.deepcopy(scenes[name])
            if isinstance(scene.get("stroke"), dict):
                scene["stroke"]["points"] = rng.choice((2, 3, 5))
            _distinct(scene, i)
            path = rng.choice(SCENE_ROUTES[:3])
            body: dict[str, Any] = {"scene": scene}
            headers = {}
            if path == "/v1/frequency-curve":
                body["method"] = rng.choice(methods)
                if rng.random() < 0.3:
                    body["shapes"] = True
                headers["Accept"] = rng.choice(("application/json", "application/json", "text/csv", "image/png"))
        else:
            path = rng.choice(paths)
            body = copy.deepcopy(bodies[path])
            if isinstance(body, dict) and isinstance(body.get("scene"), dict):
                _distinct(body["scene"], i)
            headers = {}
        yield "POST", path, (body if rng.random() < 0.1 else _mutate(body, rng)), headers
