"""The linearised input-output model at a stroke point (issue 28, item 6; model.linear)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.errors import SceneError
from flexopt.model.io import scene_from_dict
from flexopt.model.linear import frequency_response, state_space
from flexopt.model.statics import walk
from flexopt.model.templates import template

E, W, T, L = 210e9, 0.04, 0.0005, 0.1
EI = E * W * T**3 / 12


def test_single_leaf_static_gain_is_the_clamped_guided_compliance():
    """The seed leaf with its tip rotation held by the drive (locked) at stroke 0, tip force along z to tip
    displacement along z: L^3 / (12 EI) (clamped-guided beam; cubic elements give a tip load's deflection
    exactly, so 1e-9 with all modes kept); the velocity output has no static gain."""
    ss = state_space(template("leaf-spring", segments=10), 0.0, ["tip.fz"], ["tip.z", "tip.vz"])
    G = ss.static_gain()
    assert G[0, 0] == pytest.approx(L**3 / (12 * EI), rel=1e-9)
    assert abs(G[1, 0]) <= 1e-12 * G[0, 0]


def test_poles_are_the_curves_frequencies():
    """The poles' magnitudes are the natural frequencies of the exact curve at that stroke (an independent
    solve of the same eigen problem): 1e-9; their damping ratio is the one asked."""
    sc = template("leaf-spring", segments=10)
    ss = state_space(sc, 30.0, ["tip.fz"], ["tip.z"], damping=0.02)
    c = Analysis(sc).frequency_curve(np.array([30.0]), mesh_error=False)
    poles = np.linalg.eigvals(ss.A)
    up = poles[poles.imag > 0]
    hz = np.sort(np.abs(up)) / (2 * np.pi)
    np.testing.assert_allclose(hz[:6], np.sort(c.modes_hz[0]), rtol=1e-9)
    np.testing.assert_allclose(-up.real / np.abs(up), 0.02, rtol=1e-9)


def _split_leaf() -> dict:
    base = template("leaf-spring", segments=5).model_dump(mode="json")
    leaf = base["elements"][0]
    base["nodes"].append({"name": "mid", "position": [0.05, 0, 0]})
    base["elements"] = [{**leaf, "name": "a", "nodes": ["root", "mid"]}, {**leaf, "name": "b", "nodes": ["mid", "tip"]}]
    return base


def _static_compliance(base: dict, at: float, h: float = 1e-3) -> float:
    """d(mid.z)/d(F_z at mid) by a static load case at stroke ``at`` (dead loads, model.loads): central
    difference of two equilibria (finite differences in tests only)."""

    def z(F: float) -> float:
        an = Analysis(scene_from_dict({**base, "loads": [{"node": "mid", "force": [0, 0, F]}]}))
        got: list = []
        walk(an.system, np.linspace(0, np.radians(at), 9)[1:] if at else np.array([0.0]), an.options, got.append)
        s = an.structure
        i = s.node_names.index("mid")
        m = s.node_master[i]
        return float((got[-1].state.X[m] + got[-1].state.R[m] @ s.node_offset[i])[2])

    return (z(h) - z(-h)) / (2 * h)


@pytest.mark.parametrize("at", [0.0, 30.0])
def test_static_gain_is_the_compliance_of_a_static_load_case(at):
    """Static gain from the modes (all kept) against a static load case at that stroke, solved independently
    (continuation with a dead force at the leaf's middle, central difference over +-1 mN: truncation ~1e-12).
    Out of the plane of the drive the two agree to 1e-8. (In the plane, at a nonzero stroke, the model uses the
    symmetric tangent stiffness of the eigen analysis, without the antisymmetric chart term -1/2 skew(g) of the
    driven node under its drive moment, which a static solve includes: 5e-4 on the seed leaf at 30 deg; the
    README says so.)"""
    base = _split_leaf()
    ss = state_space(scene_from_dict(base), at, ["mid.fz"], ["mid.z"])
    assert ss.static_gain()[0, 0] == pytest.approx(_static_compliance(base, at), rel=1e-8)


def test_frequency_response_low_frequency_is_the_static_gain_and_bad_names_are_refused():
    ss = state_space(template("leaf-spring", segments=4), 0.0, ["tip.fz"], ["tip.z"])
    mag, ph = frequency_response(ss, np.array([1e-3, 1e6]))
    assert mag[0, 0, 0] == pytest.approx(ss.static_gain()[0, 0], rel=1e-9) and abs(ph[0, 0, 0]) < 1e-3
    assert mag[1, 0, 0] < 1e-6 * mag[0, 0, 0]  # far above every mode: mass-dominated, -40 dB/decade
    with pytest.raises(SceneError, match="unknown node or body 'tipp'"):
        state_space(template("leaf-spring", segments=4), 0.0, ["tipp.fz"], ["tip.z"])
    with pytest.raises(SceneError, match="NAME.COMPONENT"):
        state_space(template("leaf-spring", segments=4), 0.0, ["tip.force"], ["tip.z"])


def test_cli_and_http(capsys):
    import asyncio

    import httpx
    from flexopt.service.api.app import create_app
    from flexopt.service.cli.main import main

    assert (
        main(
            [
                "statespace",
                "--template",
                "leaf-spring",
                "--set",
                "segments=4",
                "--input",
                "tip.fz",
                "--output",
                "tip.z",
                "--bode",
                "1:100:3",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["static_gain"][0][0] == pytest.approx(L**3 / (12 * EI), rel=1e-9) and len(out["bode"]["magnitude"]) == 3

    scene = template("leaf-spring", segments=4).model_dump(mode="json")

    async def run():
        app = create_app()
        # the lifespan starts the runtime (worker pool) the route runs the model in
        async with (
            app.router.lifespan_context(app),
            httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://127.0.0.1") as c,
        ):
            return await c.post("/v1/state-space", json={"scene": scene, "inputs": ["tip.fz"], "outputs": ["tip.z"]})

    r = asyncio.run(run())
    assert r.status_code == 200, r.text
    assert r.json()["static_gain"][0][0] == pytest.approx(L**3 / (12 * EI), rel=1e-9)
