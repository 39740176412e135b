"""The Python client against every method on every template, through a real server (issue 26, item 1).

The README's client example crashed: ``Client.frequency_curve(scene, method="auto")`` (and ``hermite`` on the
leaf and the pivot) raised a pydantic ValidationError, because the server put strings (``auto_method``,
``mirrored``) in ``solver`` where the client's schema allowed only numbers; the client tests used only
``exact`` and ``fd1``. Every (template, method) pair here goes through the client's own validation.

Kept fast: the coarsest mesh (2 segments per member where the template has the parameter), 5 stroke points,
and the shortest stroke that still has a stroke-0 sample and points on both sides of it.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from flexopt.model import TEMPLATES, template_parameters  # noqa: E402
from flexopt.service.api.settings import Settings  # noqa: E402
from flexopt.service.client import Client, InvalidInput  # noqa: E402
from flexopt.service.schemas import METHODS, FrequencyCurveOut  # noqa: E402

from .test_service import _Server  # noqa: E402


def _coarse(name: str) -> dict[str, object]:
    params = template_parameters(name)
    out: dict[str, object] = {"points": 5}
    if "segments" in params:
        out["segments"] = 2
    if "stroke" in params:  # a quarter of the default stroke (deg, or m for the guides)
        out["stroke"] = params["stroke"] / 4
    return out


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    settings = Settings(
        data_dir=tmp_path_factory.mktemp("data"), executor="thread", max_concurrent=1, request_timeout=300, cache_size=0
    )
    with _Server(settings) as server, Client(server.url, timeout=300) as c:
        yield c


#: the methods every scene with a stroke gets a curve from (the Taylor and reduced-order methods lock the drive
#: in their eigen analysis and refuse, by a 422 naming the method and the alternatives, a scene that frees it)
ALWAYS = ("exact", "hermite", "auto")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TEMPLATES))
def test_every_method_on_every_template_through_the_client(client: Client, name: str) -> None:
    scene = client.template_scene(name, **_coarse(name))
    for method in METHODS:
        if scene.get("stroke") is None:  # a scene for the diagnosis only (truss12): one line naming the field
            with pytest.raises(InvalidInput) as err:
                client.frequency_curve(scene, method=method)
            assert "has no stroke" in err.value.detail and err.value.errors[0].loc[-1] == "stroke", err.value
            continue
        try:
            curve = client.frequency_curve(scene, method=method, tolerance=0.01)
        except InvalidInput as exc:
            assert method not in ALWAYS and f"method '{method}'" in exc.detail and "use method" in exc.detail, (
                name,
                method,
                exc,
            )
            continue
        assert isinstance(curve, FrequencyCurveOut), (name, method)
        assert curve.method == method or method == "auto", (name, method, curve.method)
        assert len(curve.stroke) == len(curve.parasitic_hz) == len(curve.modes_hz), (name, method)
