"""SPACAR .dat models (issue 28, items 3 and 5): import, export and both node numberings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.diagnosis import diagnose
from flexopt.model.errors import SceneError
from flexopt.model.io import load_dat, scene_from_dict
from flexopt.model.spacar import read_dat, write_dat
from flexopt.model.templates import template

from tests.helpers import SEED_LEAF_LIGHT_SET

DATA = Path(__file__).parent / "data" / "spacar"


def _curve(scene, stroke):
    return Analysis(scene).frequency_curve(np.asarray(stroke, dtype=float), mesh_error=False)


@pytest.mark.parametrize(
    "fixture, numbering",
    [
        ("seed_leaf_3node.dat", "X 3i-2, R 3i-1 (three SPACAR nodes per point)"),
        ("seed_leaf_2node.dat", "X 2i-1, R 2i (two SPACAR nodes per point)"),
    ],
)
def test_hand_written_seed_leaf_is_the_native_leaf(fixture, numbering):
    """The hand-written seed leaf (numbers derived in the file's comments) in either numbering gives the native
    leaf-spring template's frequencies (4 segments, an independent path: rectangle -> section -> material)
    to 1e-9: the same model up to the rounding of the printed stiffness numbers (17 digits)."""
    scene, imp = load_dat(str(DATA / fixture))
    assert imp.numbering == numbering
    assert imp.spacar_dof == 24 + 1  # four beams' six dynamic deformations and the input
    assert len(scene.elements) == 1 and scene.elements[0].segments == 4  # the chain read as one meshed member
    native = template("leaf-spring", segments=4)
    got, ref = _curve(scene, [0.0, 22.5, 45.0]), _curve(native, [0.0, 22.5, 45.0])
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    np.testing.assert_allclose(got.drive_reaction, ref.drive_reaction, rtol=1e-9)
    vm = next(iter(got.max_von_mises.values()))
    if fixture.startswith("seed_leaf_3"):  # with CROSSDIM, the section's geometry: stresses as the native leaf's
        np.testing.assert_allclose(
            max(np.nanmax(v) for v in got.max_von_mises.values()),
            max(np.nanmax(v) for v in ref.max_von_mises.values()),
            rtol=1e-6,
        )
    else:
        assert np.all(np.isnan(vm)) and any("stresses are not available" in n for n in imp.notes)


@pytest.mark.parametrize(
    "name, numbering",
    [
        ("cross-spring-pivot", 2),
        ("cross-spring-pivot", 3),
        ("folded-sheet-guide-5", 2),
        ("wire-guide-5", 3),
        ("cartwheel-hinge", 2),
    ],
)
def test_export_then_import_gives_the_same_frequencies(name, numbering):
    """Issue 28 item 5: importing the export gives the same frequencies to 1e-9 (stroke from 0: a SPACAR input
    starts at the reference), in both numberings; the drive left free in the eigen analysis (wire guide)
    survives as DYNX on the input. Each of these exports releases (RLSE) its surplus dynamic deformations
    (an input, or closed loops, over-constrain them): read back as elastic, they change no frequency."""
    sc = template(name, points=3)
    sc = sc.model_copy(update={"stroke": sc.stroke.model_copy(update={"start": 0.0})})
    text = write_dat(sc, numbering=numbering)
    assert "\nRLSE " in text
    back = scene_from_dict(read_dat(text, name).scene)
    assert back.stroke.drive == sc.stroke.drive
    a, b = _curve(sc, sc.stroke.values()), _curve(back, back.stroke.values())
    k = min(a.modes_hz.shape[1], b.modes_hz.shape[1])
    np.testing.assert_allclose(b.modes_hz[:, :k], a.modes_hz[:, :k], rtol=1e-9)


def test_export_keeps_loads_and_gravity():
    """A ramped force and gravity survive the round trip (XF + DELXF, GRAVITY): same frequencies to 1e-9."""
    sc = template("leaf-spring", segments=4, points=3)
    sc = scene_from_dict(
        {
            **sc.model_dump(mode="json"),
            "stroke": {**sc.stroke.model_dump(mode="json"), "start": 0.0},
            "gravity": [0.0, 0.0, -9.81],
            "loads": [{"node": "tip", "ramp": {"start": [0.0, 0.0, -0.1], "stop": [0.2, 0.0, -0.3]}}],
        }
    )
    text = write_dat(sc)
    assert "DELXF" in text and "GRAVITY" in text
    back = scene_from_dict(read_dat(text).scene)
    np.testing.assert_allclose(
        _curve(back, sc.stroke.values()).modes_hz, _curve(sc, sc.stroke.values()).modes_hz, rtol=1e-9
    )


def test_truss_of_seed_002_is_diagnosed_as_the_paper_says():
    """Seed 002 sec. 3.3: twelve rigid trusses, D_cc 12 x 12 of rank 11: one kinematic mode, the joints moving
    tangentially by 0.5 each (the paper's eq. 16, a unit vector), and one static mode; the same as the native
    truss12 template's diagnosis."""
    scene, imp = load_dat(str(DATA / "truss12.dat"))
    assert scene.stroke is None and imp.spacar_dof == 0
    d, ref = diagnose(scene), diagnose(template("truss12"))
    assert d.rank == ref.rank == 11 and len(d.kinematic_modes) == len(d.static_modes) == 1
    moves = sorted(abs(v) for node in d.kinematic_modes[0].values() for v in node["translation"] if abs(v) > 1e-9)
    np.testing.assert_allclose(moves, [0.5] * 4, rtol=1e-9)


@pytest.mark.parametrize(
    "text, words",
    [
        ("X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nFOO 1 2\n", "line 4: FOO: unknown keyword"),
        (
            "X 1 0 0 0\nBEAM 1 1 2 3 4 0 1 0\n",
            "line 2: BEAM: element 1: node 3 is used as a translational node but never declared",
        ),
        ("X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 1 0 0\n", "line 3: BEAM: element 1: Oy = (1.0, 0.0, 0.0) is parallel"),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nXF 4 1 2 3 4 5\n",
            "line 4: XF: node 4 is rotational: a moment takes 3 values (mx my mz, since 2017) or 4 "
            "Euler-parameter values (older files), got 5; give 3",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nXF 4 1 1 0 0\n",
            "line 4: XF: node 4 is rotational: of 4 Euler-parameter values (the form before 2017) the first, on "
            "lambda0, must be 0",
        ),
        (
            "X 1 0 0 0\nX 4 1 0 0\nBEAMW 1 1 2 3 4 5 0 1 0\n",
            "line 3: BEAMW: expected 'BEAMW Ne Xp Rp Wp Xq Rq Wq Oy_x Oy_y Oy_z' (10 numbers after the keyword), got 9",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nDYNE 1 1 2 3 4 5 6\nESTIFF 1 1 1 1 1 0 0 -2\nEM 1 1\n",
            "line 5: ESTIFF: element 1: warping stiffness EIw = -2.0 must be 0 or positive",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nDYNE 1 1 2 3 4 5 6\nESTIFF 1 1 1 1 1 -1 0\nEM 1 1\n",
            "line 5: ESTIFF: element 1: shear flexibilities Sy, Sz = [-1.0, 0.0] must be 0 or positive",
        ),
        (  # a released beam deformation keeps ESTIFF's stiffness; without one it is free, which is not modelled
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nRLSE 1 3\n",
            "line 3: BEAM: element 1 has flexible deformations [3] but no ESTIFF line (released [3] without "
            "stiffness are free deformations of a beam",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nDYNE 1 1 2 3\nRLSE 1 3 4\n",
            "line 5: RLSE: element 1: deformations [3] are listed in DYNE too",
        ),
        ("X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nRLSE 2 1\n", "line 4: RLSE: element 2 is no BEAM, TRUSS or"),
        ("X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nRLSE 1 7\n", "line 4: RLSE: deformation numbers [7] are not"),
        (
            "X 1 0 0 0\nX 3 1 0 0\nTRUSS 1 1 3\nRLSE 1 1\nEM 1 1\n",
            "line 3: TRUSS: element 1: released (RLSE) without ESTIFF: a free elongation",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nX 5 2 0 0\nBEAM 1 1 2 3 4 0 1 0\nBEAM 2 3 6 5 7 0 1 0\nHINGE 3 4 6 0 0 1\n"
            "RLSE 3 1\nESTIFF 3 5\n",
            "line 8: ESTIFF: element 3: a hinge with ESTIFF is a torsion spring",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nX 5 2 0 0\nBEAM 1 1 2 3 4 0 1 0\nBEAM 2 3 6 5 7 0 1 0\n",
            "line 5: BEAM: element 2: translational node 3 carries two rotational nodes (4 and 6) that no HINGE joins",
        ),
        (
            "X 1 0 0 0\nX 3 1 0 0\nBEAM 1 1 2 3 4 0 1 0\nDYNE 1 1 2 3 4 5 6\nESTIFF 1 1 1 1\n",
            "line 5: ESTIFF: element 1 is a beam: give EA GJ EIy EIz",
        ),
        ("X 1 0 0 0\nX 2 1 two 0\n", "line 2: X: '2 1 two 0' is not a list of numbers"),
    ],
)
def test_bad_lines_name_line_keyword_and_why(text, words):
    with pytest.raises(SceneError) as info:
        read_dat(text)
    assert words in str(info.value)


BAD = (
    "X 1 0 0 0\nX 3 1 0 0\nX 5 2 0 0\nBEAM 1 1 2 3 4 0 1 0\nBEAM 2 3 6 5 7 0 1 0\nRLSE 9 3\nFOO 2\nHINGE 3 4 6 0 0 1\n"
)


def test_every_unmappable_line_is_reported_at_once():
    """Nothing is silently dropped: each unmappable line is its own error, with its number, keyword and why."""
    with pytest.raises(SceneError) as info:
        read_dat(BAD)
    lines = info.value.lines
    assert any(m.startswith("line 6: RLSE: element 9 is no BEAM, TRUSS or HINGE") for m in lines)
    assert any(m.startswith("line 7: FOO: unknown keyword") for m in lines)
    assert any(m.startswith("line 8: HINGE: element 3: free deformations none") for m in lines)  # locked hinge


def _strip_frame() -> dict:
    strip = {"kind": "rectangular", "width": 0.01, "thickness": 0.001}
    return {
        "name": "four-bar",
        "materials": [{"name": "steel", "E": 210e9, "G": 79e9, "density": 7800, "allowable_stress": 5e8}],
        "nodes": [
            {"name": "A", "position": [0, 0, 0]},
            {"name": "B1", "position": [0, 0.04, 0]},
            {"name": "B2", "position": [0, 0.04, 0]},
            {"name": "C", "position": [0.08, 0.04, 0]},
            {"name": "D", "position": [0.08, 0, 0]},
        ],
        "elements": [
            {"kind": "beam", "name": n, "nodes": e, "material": "steel", "section": strip, "y_axis": [0, 0, 1]}
            for n, e in (("crank", ["A", "B1"]), ("coupler", ["B2", "C"]), ("rocker", ["D", "C"]))
        ],
        "joints": [{"name": "pin", "nodes": ["B1", "B2"], "axis": [0, 0, 1]}],
        "supports": [{"node": "A", "dofs": ["x", "y", "z", "rx", "ry"]}, {"node": "D"}],
        "stroke": {"kind": "rotation", "node": "A", "axis": [0, 0, 1], "start": 0, "stop": 5, "points": 6},
    }


def test_four_bar_with_one_hinge_is_the_native_frame():
    """The hand-written four-bar (tests/data/spacar/four_bar_hinge.dat: three strips, a HINGE with its rotation
    released where the crank and the coupler have their own rotational nodes on one translational node) gives
    the frequencies and drive reaction of the native scene (three beams and a joint) to 1e-9, and so does
    the native scene's export read back."""
    scene, imp = load_dat(str(DATA / "four_bar_hinge.dat"))
    assert len(scene.joints) == 1 and scene.joints[0].kind == "hinge" and imp.spacar_dof == 18 + 1
    native = scene_from_dict(_strip_frame())
    got, ref = _curve(scene, native.stroke.values()), _curve(native, native.stroke.values())
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    np.testing.assert_allclose(got.drive_reaction, ref.drive_reaction, rtol=1e-9, atol=1e-12)
    text = write_dat(native)
    assert "HINGE" in text and "RLSE" in text
    back = scene_from_dict(read_dat(text).scene)
    np.testing.assert_allclose(_curve(back, native.stroke.values()).modes_hz, ref.modes_hz, rtol=1e-9)


def test_cli_import_export_and_a_dat_scene_path(tmp_path, capsys):
    """``flexopt import`` prints the scene and reports on stderr; ``flexopt export`` writes a .dat that reads back;
    a command taking a scene path takes the .dat directly."""
    from flexopt.service.cli.main import main

    assert main(["import", str(DATA / "seed_leaf_3node.dat")]) == 0
    out, err = capsys.readouterr()
    scene = scene_from_dict(__import__("json").loads(out))
    assert "SPACAR degrees of freedom (inputs and dynamic deformations): 25" in err
    assert "SPACAR's D_cc (its variables, SI, at the reference; docs: SPACAR models): 28 x 27, rank 27" in err
    path = tmp_path / "leaf.json"
    path.write_text(out)
    assert main(["export", str(path), "--numbering", "3"]) == 0
    text = capsys.readouterr().out
    assert "BEAM 1 1 2 7 8" in text
    back = scene_from_dict(read_dat(text).scene)
    np.testing.assert_allclose(_curve(back, [45.0]).modes_hz, _curve(scene, [45.0]).modes_hz, rtol=1e-9)
    assert main(["curve", str(DATA / "seed_leaf_2node.dat"), "--method", "exact"]) == 0
    assert "45.0000" in capsys.readouterr().out
    assert main(["diagnose", str(DATA / "truss12.dat"), "--json"]) == 0
    d = __import__("json").loads(capsys.readouterr().out)
    assert d["spacar_dof"] == 0 and d["rank"] == 11
    assert d["spacar"]["rank"] == 11 and d["spacar_condition_number"] is None  # rank deficient: infinite
    bad = tmp_path / "bad.dat"
    bad.write_text(BAD)
    assert main(["import", str(bad)]) == 2
    assert "line 7: FOO" in capsys.readouterr().err


def test_http_import_and_export():
    """``POST /v1/scenes/import``: the scene and the report, or a 422 with one error per unmappable line;
    ``POST /v1/scenes/export``: the .dat text."""
    import asyncio

    import httpx
    from flexopt.service.api.app import create_app

    async def run():
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=create_app()), base_url="http://127.0.0.1") as c:
            ok = await c.post("/v1/scenes/import", json={"text": (DATA / "truss12.dat").read_text(), "name": "t"})
            bad = await c.post("/v1/scenes/import", json={"text": BAD})
            dat = await c.post("/v1/scenes/export", json={"scene": ok.json()["scene"], "numbering": 3})
            light = await c.post("/v1/scenes/import", json={"text": (DATA / "cross_pivot_light_rlse.dat").read_text()})
            return ok, bad, dat, light

    ok, bad, dat, light = asyncio.run(run())
    assert ok.status_code == 200 and ok.json()["spacar_dof"] == 0 and len(ok.json()["scene"]["elements"]) == 12
    assert ok.json()["released"] == {}
    assert light.status_code == 200 and light.json()["released"] == {"BEAM 2": [1, 4, 6], "BEAM 4": [1, 3, 5, 6]}
    assert ok.json()["spacar"]["rank"] == 11 and ok.json()["spacar"]["condition_number"] is None
    assert bad.status_code == 422
    assert {e["msg"][:10] for e in bad.json()["errors"]} == {"line 5: BE", "line 6: RL", "line 7: FO", "line 8: HI"}
    assert dat.status_code == 200 and dat.text.count("TRUSS") == 12


def test_spacar_light_tables_port_line_by_line():
    """SPACAR Light's four tables (a YAML file written from the MATLAB script, and the Python function with
    arrays and dicts) give the native leaf's frequencies to 1e-9; a field SPACAR Light has but flexopt does not
    map is an error naming the table, entry and field."""
    from flexopt.model.io import load_scene
    from flexopt.model.spacar import spacar_light

    scene = load_scene(DATA / "seed_leaf_light.yaml")
    ref = _curve(template("leaf-spring", segments=4), [0.0, 11.25, 22.5, 33.75, 45.0])
    np.testing.assert_allclose(_curve(scene, scene.stroke.values()).modes_hz, ref.modes_hz, rtol=1e-9)
    eprops = [dict(SEED_LEAF_LIGHT_SET)]
    imp = spacar_light(
        np.array([[0, 0, 0], [0.1, 0, 0]]), np.array([[1, 2]]), {1: {"fix": True}, 2: {"rot_y": np.pi / 4}}, eprops
    )
    assert scene_from_dict(imp.scene).stroke.stop == pytest.approx(45.0, rel=1e-12)
    with pytest.raises(SceneError, match=r"nprops\(2\): fields \['moment'\] are not mapped"):
        spacar_light([[0, 0, 0], [0.1, 0, 0]], [[1, 2]], [{"fix": True}, {"moment": [0, 1, 0]}], eprops)


def test_moments_on_rotational_nodes_are_the_native_moments():
    """XF/DELXF on a rotational node are moments: 3 values (mx my mz, the form since 2017 and SPACAR Light's)
    as they are, 4 Euler-parameter values (before 2017) as half their last three (generalised forces on the
    Euler parameters at the reference, dtheta = 2 dlambda); the report says which form was read. On the
    cross-spring pivot's rotor (a rigid body) XF + DELXF give a moment ramped over the stroke: the same
    frequencies to 1e-9 at 0, 5 and 10 deg as the native pivot with the same moment on its rotor (a Load
    written by hand), and not those of the unloaded pivot (so the moment is applied)."""
    from tests.test_spacar_dcc import _pivot_native

    base = (DATA / "cross_pivot_2node.dat").read_text()
    three = base.replace("END\n", "XF 14 0.02 0 0.01\nDELXF 14 0 0.01 0\nEND\n", 1)
    four = base.replace("END\n", "XF 14 0 0.04 0 0.02\nDELXF 14 0 0 0.02 0\nEND\n", 1)
    a, b = read_dat(three), read_dat(four)
    assert a.scene["loads"] == b.scene["loads"]
    assert any("3 values (mx my mz, the form since 2017) read" in n for n in a.notes)
    assert any("4 Euler-parameter values (the form before 2017) read as the dead moment" in n for n in b.notes)
    native = _pivot_native().model_dump(mode="json")
    native["stroke"] = {**native["stroke"], "start": 0.0}  # the ramp runs over the input's 0 to 10 deg
    native["loads"] = [
        {"body": "rotor", "kind": "moment", "ramp": {"start": [0.02, 0.0, 0.01], "stop": [0.02, 0.01, 0.01]}}
    ]
    vals = [0.0, 5.0, 10.0]
    got = _curve(scene_from_dict(a.scene), vals).modes_hz
    np.testing.assert_allclose(got, _curve(scene_from_dict(native), vals).modes_hz, rtol=1e-9)
    unloaded = _curve(_pivot_native(), vals).modes_hz
    assert np.max(np.abs(got / unloaded - 1)) > 1e-6
    back = read_dat(write_dat(scene_from_dict(native)))  # the export writes the moment back on the rotor's R
    np.testing.assert_allclose(_curve(scene_from_dict(back.scene), vals).modes_hz, got, rtol=1e-9)
