"""Shapes: deflected configurations and mode shapes (model.shapes), their CLI, HTTP and VTK forms, and the plots.

References: the circular arc of a leaf under a pure end moment (shared/PHYSICS.md, "Pure bending by an end
moment M: a circular arc"), the clamped-free torsion frequency (tests/references.py), and the model's own mass
matrix for the normalisation, rebuilt independently of model.shapes from the JSON.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from flexopt.model import Analysis, template
from flexopt.model.shapes import shapes_along, shapes_at
from flexopt.service import plots
from flexopt.service.cli.main import main

from tests import references as ref
from tests.helpers import coarse


@pytest.fixture(scope="module")
def leaf() -> Analysis:
    return Analysis(template("leaf-spring"))


@pytest.fixture(scope="module")
def leaf0(leaf: Analysis) -> dict:
    return shapes_at(leaf, 0.0).to_dict()


def _equilibrium(an: Analysis, stroke: float):
    """The equilibrium and modes at ``stroke`` through the public visit hook (independent of model.shapes)."""
    seen = {}
    an.frequency_curve(np.array([stroke]), visit=lambda eq, modes, labels: seen.update(eq=eq, modes=modes))
    return seen["eq"], seen["modes"]


def _master_vector(d: dict, mode: dict, masters: tuple[str, ...]) -> np.ndarray:
    """The JSON's nodal motion as the model's master DOFs (u, psi) in global axes: a node carried by a body at
    X moves by u_n = u_m + psi x (x_n - X), so the body's own translation is u_n - psi x (x_n - X)."""
    out = []
    for m in masters:
        if m in d["bodies"]:
            n = d["bodies"][m]["nodes"][0]
            psi = np.asarray(mode["rotation"][n])
            r = np.asarray(d["nodes"][n]) - np.asarray(d["bodies"][m]["position"])
            out.append(np.r_[np.asarray(mode["translation"][n]) - np.cross(psi, r), psi])
        else:
            out.append(np.r_[mode["translation"][m], mode["rotation"][m]])
    return np.concatenate(out)


@pytest.mark.parametrize(
    "name, stroke",
    [("leaf-spring", 0.0), ("leaf-spring", 30.0), ("parallel-leaf-spring", None), ("cross-spring-pivot", 20.0)],
)
def test_modes_are_mass_normalised_against_the_models_mass_matrix(name: str, stroke: float | None) -> None:
    an = Analysis(template(name, points=3))
    if stroke is None:
        stroke = float(an.scene.stroke.values()[-1])
    d = shapes_at(an, stroke).to_dict()
    eq, _ = _equilibrium(an, stroke)
    sys = an.system
    M = sys.mass(eq.state)
    xis = [sys.from_global(_master_vector(d, m, an.structure.master_names)) for m in d["modes"]]
    for k, xi in enumerate(xis):
        assert xi @ M @ xi == pytest.approx(1.0, rel=1e-9), f"mode {k + 1}: phi^T M phi"
        for j in range(k):  # and M-orthogonal to the others
            assert abs(xi @ M @ xis[j]) < 1e-8


def test_first_parasitic_mode_of_the_leaf_at_stroke_0_is_torsion(leaf0: dict) -> None:
    par = [m for m in leaf0["modes"] if m["label"] == "parasitic"]
    first = min(par, key=lambda m: m["hz"])
    ref.TORSION_FREE_WARPING.check(first["hz"])
    rot = np.array(list(first["rotation"].values()))
    tra = np.array(list(first["translation"].values()))
    share = (rot[:, 0] ** 2).sum() / (rot**2).sum()
    assert share > 0.999, f"rotation about the leaf axis x carries {share:.4f} of the squared rotations"
    # torsion of the centre line: nodes barely translate compared with the plate edges' motion w/2 * psi_x
    assert np.abs(tra).max() < 1e-6 * ref.W / 2 * np.abs(rot[:, 0]).max()
    tip = np.abs(rot[:, 0]).argmax()
    assert list(first["rotation"])[tip] == "tip", "a clamped-free torsion mode rotates most at the free end"


@pytest.mark.parametrize("theta_deg", [10.0, 30.0, -45.0])
def test_leaf_under_pure_end_rotation_lies_on_the_circular_arc(leaf: Analysis, theta_deg: float) -> None:
    """shared/PHYSICS.md: pure bending by an end moment gives a circular arc of radius L / theta. The beam
    element takes constant curvature as eps3 = eps4 = kappa l0^2 / 2; its elongation carries second-order
    bending terms, so an element's chord matches the arc only up to fourth order in its angle theta / n.
    Tolerance: 1e-7 L (Newton, 1e-9 of the length scale, with margin) + (theta / n)^4 L / 100 (observed at
    45 deg: 1.1e-7 L, below the 4.9e-7 L allowed; at 10 deg: below 1e-9 L)."""
    d = shapes_at(leaf, theta_deg).to_dict()
    th = math.radians(theta_deg)
    rho = ref.L / th
    n = 10
    tol = 1e-7 * ref.L + (th / n) ** 4 * ref.L / 100
    for i in range(n + 1):
        name = "root" if i == 0 else "tip" if i == n else f"leaf#{i}"
        s = ref.L * i / n
        want = [rho * math.sin(s / rho), 0.0, -rho * (1 - math.cos(s / rho))]
        assert np.allclose(d["nodes"][name], want, rtol=0, atol=tol), (name, d["nodes"][name], want)
    assert np.allclose(d["orientations"]["tip"], [0.0, th, 0.0], atol=1e-9), "tip rotated by theta about y"
    assert d["stroke"] == theta_deg and d["stroke_unit"] == "deg"


def test_body_pose_and_stress_utilisation_are_reported() -> None:
    an = Analysis(template("parallel-leaf-spring"))
    spec = an.scene.stroke
    s_max = float(spec.values()[-1])
    d = shapes_at(an, s_max).to_dict()
    body = next(iter(d["bodies"].values()))
    # the body follows the driven translation along the drive axis (stroke in m)
    axis = np.asarray(spec.axis, dtype=float) / np.linalg.norm(spec.axis)
    com0 = np.asarray(an.scene.bodies[0].center_of_mass)
    assert (np.asarray(body["position"]) - com0) @ axis == pytest.approx(s_max, rel=1e-9)
    for _name, st in d["stress"].items():
        assert st["utilisation"] == pytest.approx(st["von_mises"] / st["allowable"], rel=1e-12)
        assert 0 < st["utilisation"]
    # an allowable stress below the stress at that stroke must produce a stress warning
    low = template("leaf-spring", allowable_stress=1e6)
    w = shapes_at(Analysis(low), 20.0).to_dict()["warnings"]
    assert w and w[0]["kind"] == "stress" and w[0]["element"] == "leaf" and w[0]["value"] > 1


def test_stroke_past_the_loss_of_equilibrium_is_refused_with_its_cause() -> None:
    from flexopt.model.errors import FlexoptError

    with pytest.raises(FlexoptError, match="no stable equilibrium at stroke 3000"):
        shapes_at(Analysis(template("leaf-spring", points=5)), 3000.0)


# ---------------------------------------------------------------------------------------------- CLI, VTK
def test_cli_modes_json_plot_gif_and_vtk(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import meshio
    from PIL import Image

    png, gif, vtk = tmp_path / "m.png", tmp_path / "m.gif", tmp_path / "vtk"
    code = main(
        [
            "modes",
            "--template",
            "leaf-spring",
            "--set",
            "points=3",
            "--set",
            "stroke=20",
            "--at-stroke",
            "10",
            "--json",
            "--plot",
            str(png),
            "--animate",
            str(gif),
            "--vtk",
            str(vtk),
        ]
    )
    assert code == 0
    d = json.loads(capsys.readouterr().out)
    assert d["stroke"] == 10.0 and set(d["nodes"]) >= {"root", "tip"} and len(d["modes"]) == 6
    assert {"hz", "label", "translation", "rotation"} <= set(d["modes"][0])
    with Image.open(png) as im:
        assert im.size[0] > 500
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.n_frames >= 10
    files = sorted(vtk.glob("*.vtu"))
    assert len(files) == 3 and (vtk / "series.pvd").exists()
    mesh = meshio.read(files[1])  # stroke 0 of -20, 0, 20
    assert "mode_2_translation" in mesh.point_data and mesh.point_data["mode_2_hz"][0] == pytest.approx(
        ref.TORSION_FREE_WARPING.value, rel=ref.TORSION_FREE_WARPING.rtol
    )
    tip = np.argmin(np.linalg.norm(mesh.points - [ref.L, 0, 0], axis=1))
    assert np.linalg.norm(mesh.points[tip] - [ref.L, 0, 0]) < 1e-12, "stroke 0: the tip at its reference"
    assert "quad" in mesh.cells_dict and len(mesh.cells_dict["quad"]) == 10, "the leaf as 10 plate quads"


def test_cli_modes_text_names_the_torsion(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["modes", "--template", "leaf-spring", "--set", "points=3"]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("2 "))
    assert "parasitic" in line and "rotation about x" in line


# -------------------------------------------------------------------------------------------------- HTTP
def test_http_modes_and_curve_shapes() -> None:
    import asyncio

    import httpx
    from flexopt.service.api.app import create_app
    from flexopt.service.api.settings import Settings

    scene = template("leaf-spring", points=5).model_dump(mode="json")
    app = create_app(Settings(executor="thread", api_keys=""))  # the runtime exists before startup (in-process)

    async def run() -> None:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://localhost") as c:
            r = await c.post("/v1/modes", json={"scene": scene, "at_stroke": 0})
            assert r.status_code == 200
            d = r.json()
            assert d["modes"][1]["label"] == "parasitic"
            ref.TORSION_FREE_WARPING.check(d["modes"][1]["hz"])
            r = await c.post(
                "/v1/modes", json={"scene": scene, "at_stroke": 0, "mode": 1}, headers={"Accept": "image/png"}
            )
            assert r.status_code == 200 and r.headers["content-type"] == "image/png" and r.content[:4] == b"\x89PNG"
            r = await c.post("/v1/modes", json={"scene": scene, "at_stroke": 1e4})
            assert r.status_code == 422 and "no stable equilibrium" in r.json()["detail"]
            body = (await c.post("/v1/frequency-curve", json={"scene": scene, "shapes": True})).json()
            pts = body["shapes"]["points"]
            assert [p["stroke"] for p in pts] == body["stroke"]
            assert body["shapes"]["members"]["leaf"]["width"] == ref.W
            th = math.radians(pts[-1]["stroke"])  # PHYSICS.md's arc: tip x = L sin(theta) / theta
            assert pts[-1]["nodes"]["tip"][0] == pytest.approx(ref.L * math.sin(th) / th, rel=1e-6)
            plain = (await c.post("/v1/frequency-curve", json={"scene": scene})).json()
            assert plain.get("shapes") is None
            page = await c.get("/")
            assert page.status_code == 200 and 'data-testid="curve"' in page.text
        # the typed client hands the same wire dict to the one plotting module
        from flexopt.client import AsyncClient

        async with AsyncClient("http://localhost", transport=httpx.ASGITransport(app=app)) as client:
            d = await client.modes(scene, 0.0)
            gif = await client.modes(scene, 0.0, format="gif", mode=1)
        assert gif[:6] == b"GIF89a"
        fig = plots.shapes_figure(d, 1)
        title = fig._suptitle.get_text()
        # the title names the mode with its frequency: the seed leaf's torsion, 198.1 Hz by the free-warping
        # closed form (shared/PHYSICS.md; 198.105 Hz with the consistent mass, 4 significant digits here)
        hz = f"{d['modes'][1]['hz']:.4g}"
        assert hz == "198.1" and f"mode 2: {hz} Hz (parasitic)" in title and "drawn at scale" in title

    asyncio.run(run())


# ------------------------------------------------------------------------------------------------- plots
def test_curve_plot_highlights_the_parasitic_and_marks_the_stress_limit(leaf: Analysis) -> None:
    curve = template("leaf-spring", points=7)
    cv = Analysis(curve).frequency_curve().to_dict()
    fig = plots.curve_figure(cv, curve.model_dump(mode="json"))
    ax, ax2 = fig.axes[:2]
    par = next(line for line in ax.get_lines() if line.get_label() == "first parasitic")
    assert np.allclose(par.get_ydata(), cv["parasitic_hz"])
    labels = [line.get_label() for line in ax.get_lines()]
    assert "mode 2 (parasitic)" in labels and "mode 1 (intended)" in labels
    assert ax.get_yscale() == "log", "modes spanning 60 Hz to 1 kHz: log axis chosen"
    assert "[Hz]" in ax.get_ylabel() and "[deg]" in ax2.get_xlabel()
    limit = next(line for line in ax2.get_lines() if line.get_label() == "allowable")
    assert np.allclose(limit.get_ydata(), 1.0)
    util = next(line for line in ax2.get_lines() if line.get_label() == "leaf")
    assert np.allclose(util.get_ydata(), np.array(cv["max_von_mises"]["leaf"]) / cv["allowable_stress"]["leaf"])
    assert "w 40 mm" in fig._suptitle.get_text() and "t 0.5 mm" in fig._suptitle.get_text()
    cv["warnings"] = [
        {
            "kind": "stress",
            "message": "member 'leaf' over the limit",
            "element": "leaf",
            "stroke_range": None,
            "value": 1.2,
        }
    ]
    fig = plots.curve_figure(cv, log=False)
    assert fig.axes[0].get_yscale() == "linear"
    assert any("over the limit" in t.get_text() for t in fig.texts), "warnings are shown on the figure"


def test_curve_plot_of_a_curve_lost_at_once_says_why() -> None:
    d = {
        "scene": "x",
        "method": "exact",
        "stroke": [],
        "stroke_unit": "deg",
        "stroke_kind": "rotation",
        "parasitic_hz": [],
        "modes_hz": [],
        "mode_labels": [],
        "max_von_mises": {"leaf": []},
        "allowable_stress": {"leaf": 1e8},
        "warnings": [],
        "failures": [{"reason": "unstable", "stroke": 0.1, "last_converged": 0.0, "message": "lost at 0.1 deg"}],
    }
    fig = plots.curve_figure(d)
    assert any("[truncated] lost at 0.1 deg" in t.get_text() for t in fig.texts)


def test_diagnosis_plot_draws_the_rotation_of_the_free_motion() -> None:
    """wire-guide-parallel's free motion is mainly a rotation (0.95 rad per unit) of the slider: the drawn
    motion of the slider's nodes must contain psi x r, not only the 0.30 translation."""
    from flexopt.model.diagnosis import diagnose

    sc = template("wire-guide-parallel")
    dg = diagnose(sc).to_dict()
    motion = dg["kinematic_modes"][0]
    assert motion["slider"]["rotation"][2] == pytest.approx(0.95, abs=0.01)
    scene = sc.model_dump(mode="json")
    geo = plots._scene_geometry(scene)
    drawn = plots._free_motion(scene, geo, motion, dg["characteristic_length"])
    body = scene["bodies"][0]
    com = np.asarray(body["center_of_mass"])
    psi = np.asarray(motion["slider"]["rotation"])
    u = dg["characteristic_length"] * np.asarray(motion["slider"]["translation"])
    for n in body["nodes"]:
        r = np.asarray(geo["nodes"][n]) - com
        assert np.allclose(drawn["translation"][n], u + np.cross(psi, r), atol=1e-12)
    spread = np.ptp([drawn["translation"][n] for n in body["nodes"]], axis=0).max()
    assert spread > 0.5 * np.linalg.norm(u), "the slider's nodes move differently: the rotation is drawn"
    fig = plots.diagnosis_figure(scene, dg)
    assert any("rz+0.95" in t.get_text() for t in fig.texts)
    assert len(fig.axes) == 2, "a 3D view and its colour bar"


def test_modes_carry_the_scene_checks_and_provenance() -> None:
    # issue 11 item 1: every result carries warnings; a leaf as thick as it is long (L/t = 1 < 10) is outside
    # Euler-Bernoulli beam theory (model.checks.SLENDER_MIN), and every result names the scene it came from
    from flexopt.model.checks import scene_hash

    thick = template("leaf-spring", thickness=0.1, points=3)
    d = shapes_at(Analysis(thick), 0.0).to_dict()
    assert any(w["kind"] == "validity" and w["element"] == "leaf" for w in d["warnings"]), d["warnings"]
    assert d["provenance"]["scene_sha256"] == scene_hash(thick)
    assert d["provenance"]["flexopt_version"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, stroke", [("cartwheel-hinge", 45.0), ("cross-spring-pivot", -33.0), ("parallel-leaf-spring", 0.01)]
)
def test_modes_at_a_stroke_are_the_curves_modes_there_with_its_labels(name: str, stroke: float) -> None:
    """Issue 26 item 3: ``modes --at-stroke`` showed other modes than the curve at that stroke (the cartwheel
    at 45 deg: the curve's sixth branch, 352 Hz, left out and a 2,116 Hz mode shown). The modes at a stroke
    are the curve's row there, in its branch order and with its labels (same solves: equal to rounding)."""
    an = Analysis(template(name, **coarse(name)))  # the meshes of the figures above (the former defaults)
    curve = an.frequency_curve()
    i = int(np.argmin(np.abs(curve.stroke - stroke)))
    assert curve.stroke[i] == pytest.approx(stroke)
    d = shapes_at(an, stroke).to_dict()
    np.testing.assert_allclose([m["hz"] for m in d["modes"]], curve.modes_hz[i], rtol=1e-8)
    assert [m["label"] for m in d["modes"]] == list(curve.mode_labels[i])


def test_stroke_figure_draws_each_stroke_with_its_first_parasitic_frequency() -> None:
    """The docs' topology pictures (docs/draw_topology.py): one panel per stroke value, titled with the first
    parasitic frequency of the exact curve at that stroke (computed here by the curve itself, not the shapes),
    each stage of a topology hinge in its own colour."""
    from matplotlib.colors import to_hex

    scene = template("topology-hinge", topology="R:+-|-+", segments=2)
    an = Analysis(scene)
    strokes = [-20.0, 0.0, 20.0]
    fig = plots.stroke_figure(shapes_along(an, strokes), "double cross")
    curve = an.frequency_curve(np.array(strokes))
    assert len(fig.axes) == 3 and fig._suptitle.get_text() == "double cross"
    for ax, s, hz in zip(fig.axes, strokes, curve.parasitic_hz):
        assert ax.get_title() == f"{s:+.0f} deg: first parasitic {hz:.4g} Hz"
    faces = {to_hex(c) for col in fig.axes[0].collections for c in col.get_facecolors()}
    assert {plots.STAGE_COLORS[0], plots.STAGE_COLORS[1]} <= faces, faces


def test_stroke_figure_marks_ground_and_draws_the_axes() -> None:
    """The docs' topology pictures mark ground (a black square at each supported node, where the scene clamps
    the leaves: those nodes do not move over the stroke) and draw the scene's x, y, z axes at the origin, 10 mm
    long, on a twin of each panel with the same view and limits (drawn over the leaves)."""
    from matplotlib.colors import to_hex

    scene = template("topology-hinge", topology="R:+-|-+", segments=2)
    clamped = [s.node for s in scene.supports]
    at = {n.name: np.array(n.position) for n in scene.nodes}
    fig = plots.stroke_figure(shapes_along(Analysis(scene), [-20.0, 20.0]), ground=clamped, axes=0.01)
    panels, twins = fig.axes[:2], fig.axes[2:]
    assert len(twins) == 2
    for ax, twin in zip(panels, twins):
        marks = [c for c in ax.collections if to_hex(c.get_facecolors()[0]) == plots.GROUND_COLOR]
        assert len(marks) == 1
        np.testing.assert_allclose(np.array(marks[0]._offsets3d).T, [at[n] for n in clamped], atol=1e-12)
        assert (twin.get_xlim(), twin.get_zlim()) == (ax.get_xlim(), ax.get_zlim())
        ends = [np.array(line.get_data_3d()).T for line in twin.lines]
        for k, e in enumerate(ends):
            np.testing.assert_allclose(e, [np.zeros(3), 0.01 * np.eye(3)[k]], atol=1e-15)
        assert [line.get_color() for line in twin.lines] == list(plots.AXIS_COLORS)
    assert "ground" in fig.texts[-1].get_text() and "10 mm" in fig.texts[-1].get_text()
