"""SPACAR's own D_cc (model.spacar_dcc): its matrix written by hand for a truss and a clamped beam, its counts
by hand for a cross-spring pivot, and the diagnosis reporting it for imported and native scenes."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.diagnosis import diagnose
from flexopt.model.io import load_dat
from flexopt.model.spacar import spacar_dcc_of_scene
from flexopt.model.spacar_dcc import spacar_dcc
from flexopt.model.templates import TEMPLATES, template

DATA = Path(__file__).parent / "data" / "spacar"
s = 1 / math.sqrt(2)

#: Seed 002 sec. 3.3 (tests/data/spacar/truss12.dat): each truss's row of D = d(l - l0)/dx is the unit vector
#: along it, from the joint it pulls towards the other end, with opposite signs at its two ends; only the joints
#: X 5 (1, 0, 1), X 6 (0, 1, 1), X 7 (-1, 0, 1), X 8 (0, -1, 1) have calculable coordinates. Written by hand.
TRUSS_ROWS = {
    "TRUSS 1 eps1": {5: (0, -s, s)},  # 5 -> support (1, 1, 0)
    "TRUSS 2 eps1": {5: (0, s, s)},  # 5 -> (1, -1, 0)
    "TRUSS 3 eps1": {6: (-s, 0, s)},  # 6 -> (1, 1, 0)
    "TRUSS 4 eps1": {6: (s, 0, s)},  # 6 -> (-1, 1, 0)
    "TRUSS 5 eps1": {7: (0, -s, s)},  # 7 -> (-1, 1, 0)
    "TRUSS 6 eps1": {7: (0, s, s)},  # 7 -> (-1, -1, 0)
    "TRUSS 7 eps1": {8: (s, 0, s)},  # 8 -> (-1, -1, 0)
    "TRUSS 8 eps1": {8: (-s, 0, s)},  # 8 -> (1, -1, 0)
    "TRUSS 9 eps1": {5: (s, -s, 0), 6: (-s, s, 0)},
    "TRUSS 10 eps1": {6: (s, s, 0), 7: (-s, -s, 0)},
    "TRUSS 11 eps1": {7: (-s, s, 0), 8: (s, -s, 0)},
    "TRUSS 12 eps1": {8: (-s, -s, 0), 5: (s, s, 0)},
}


def _hand(rows: dict[str, dict[int, tuple]], drop: str | None = None) -> tuple[list[str], list[str], np.ndarray]:
    labels = [r for r in rows if r != drop]
    cols = [f"X {n} {c}" for n in (5, 6, 7, 8) for c in "xyz"]
    D = np.zeros((len(labels), 12))
    for i, r in enumerate(labels):
        for n, v in rows[r].items():
            D[i, 3 * (n - 5) : 3 * (n - 5) + 3] = v
    return labels, cols, D


def test_truss_of_seed_002_is_the_hand_written_matrix():
    """Seed 002 sec. 3.3: D_cc is the 12 x 12 matrix of unit vectors above (exactly), of rank 11, so its
    condition number is infinite; its statically indeterminate stresses are all +-sqrt(3)/6 (the paper's
    value, sec. 3.3) and its free motion moves the four joints tangentially by 0.5 each (eq. 16)."""
    d = spacar_dcc((DATA / "truss12.dat").read_text())
    labels, cols, D = _hand(TRUSS_ROWS)
    assert list(d.rows) == labels and list(d.columns) == cols
    np.testing.assert_allclose(d.D_cc, D, atol=1e-15)  # exact up to round-off
    assert (d.m, d.n, d.rank, d.dof) == (12, 12, 11, 0)
    assert d.condition_number == math.inf and d.to_dict()["condition_number"] is None
    assert d.over_constrained == d.under_constrained == 1
    U, _, Vt = np.linalg.svd(d.D_cc)
    np.testing.assert_allclose(np.abs(U[:, -1]), math.sqrt(3) / 6, rtol=1e-12)
    np.testing.assert_allclose(sorted(np.abs(Vt[-1])), [0.0] * 8 + [0.5] * 4, atol=1e-12)


def test_truss_with_one_truss_released_has_the_hand_matrix_condition_number():
    """RLSE 12 1 makes truss 12's elongation calculable: D_cc is the hand matrix without its row, 11 x 12 of
    rank 11 (one free motion, no self-stress) and its condition number is that of the hand matrix (numpy's
    SVD of it: an independent computation) to 1e-12."""
    text = (DATA / "truss12.dat").read_text().replace("END", "RLSE 12 1\nEND", 1)
    d = spacar_dcc(text)
    _, _, D = _hand(TRUSS_ROWS, drop="TRUSS 12 eps1")
    sv = np.linalg.svd(D, compute_uv=False)
    assert (d.m, d.n, d.rank, d.under_constrained, d.over_constrained) == (11, 12, 11, 1, 0)
    assert d.condition_number == pytest.approx(sv[0] / sv[-1], rel=1e-12)


L_BEAM = 0.1
CLAMPED = f"""# one beam along x, clamped at X 1 / R 2, all six deformations dynamic
X 1 0 0 0
X 3 {L_BEAM} 0 0
BEAM 1 1 2 3 4 0 1 0
ESTIFF 1 4.2e6 0.13 0.0875 560 0 0
EM 1 0.156 2.080325e-05 3.25e-09 2.08e-05 0
DYNE 1 1 2 3 4 5 6
FIX 1
FIX 2
END
HALT
"""


def test_clamped_beam_is_the_hand_written_matrix():
    """A clamped beam of length L along x (Oy = y) at the reference, differentiated by hand from seed 002 eq. 2
    with R(lambda) = (l0^2 - v.v) I + 2 v v^T + 2 l0 [v]x (so dR/dlambda0 = 2 I, dR/dlambda_i = 2 [e_i]x):
    eps1 = x, eps2 = 2 L lambda1, eps3 = -z, eps4 = z + 2 L lambda2, eps5 = y, eps6 = -y + 2 L lambda3 and the
    normalisation 2 lambda0. Its singular values: 1 (x), 2 (lambda0), 2 L (lambda1) and, for each bending
    plane, those of [[-1, 0], [1, 2 L]]: sigma^2 = (tr -+ sqrt(tr^2 - 16 L^2)) / 2 with tr = 2 + 4 L^2; so the
    condition number is 2 / sigma_min (closed form)."""
    d = spacar_dcc(CLAMPED)
    L = L_BEAM
    rows = {  # columns: X 3 x y z, R 4 lambda0..lambda3
        "R 4 norm": [0, 0, 0, 2, 0, 0, 0],
        "BEAM 1 eps1": [1, 0, 0, 0, 0, 0, 0],
        "BEAM 1 eps2": [0, 0, 0, 0, 2 * L, 0, 0],
        "BEAM 1 eps3": [0, 0, -1, 0, 0, 0, 0],
        "BEAM 1 eps4": [0, 0, 1, 0, 0, 2 * L, 0],
        "BEAM 1 eps5": [0, 1, 0, 0, 0, 0, 0],
        "BEAM 1 eps6": [0, -1, 0, 0, 0, 0, 2 * L],
    }
    assert list(d.rows) == list(rows)
    assert list(d.columns) == ["X 3 x", "X 3 y", "X 3 z", "R 4 lambda0", "R 4 lambda1", "R 4 lambda2", "R 4 lambda3"]
    np.testing.assert_allclose(d.D_cc, np.array(list(rows.values()), dtype=float), atol=1e-15)
    tr = 2 + 4 * L**2
    smin = math.sqrt((tr - math.sqrt(tr**2 - 16 * L**2)) / 2)
    assert (d.m, d.n, d.rank, d.dof) == (7, 7, 7, 6) and d.verdict.startswith("exactly constrained")
    assert d.condition_number == pytest.approx(2 / smin, rel=1e-12)


@pytest.mark.parametrize("fixture", ["cross_pivot_2node.dat", "cross_pivot_3node.dat"])
def test_cross_spring_pivot_counts_by_hand(fixture):
    """The hand-written cross-spring pivot (counts in the file's comments): 41 rows (24 dynamic deformations,
    12 of the two rigid links, 5 normalisations), 34 columns (5 free X nodes x 3, 5 free R nodes x 4, less the
    input lambda3), full column rank; 25 degrees of freedom. The leaves' 24 deformations and the input span
    the rotor's 6 and the 2 x 6 of the mid nodes, 18 motions, plus 7 more: over-constrained by 7, which SPACAR
    resolves by releasing 7 of them (the note says so). Both numberings give the same matrix."""
    d = spacar_dcc((DATA / fixture).read_text())
    assert (d.m, d.n, d.rank, d.dof) == (41, 34, 34, 25)
    assert (d.over_constrained, d.under_constrained) == (7, 0)
    assert any("released (RLSE" in n for n in d.notes)
    other = spacar_dcc((DATA / "cross_pivot_2node.dat").read_text())
    np.testing.assert_allclose(d.singular_values, other.singular_values, rtol=1e-12)


def _pivot_native(points: int = 3):
    return template(
        "cross-spring-pivot",
        length=0.04 * math.sqrt(2),
        segments=2,
        body_offset=0.01,
        body_radius=0.02,
        points=points,
        stroke=10.0,
    )


def test_cross_spring_pivot_fixture_is_the_native_pivot():
    """The fixture gives the native template's frequencies (same geometry to 4e-18 m) to 1e-9 at 0, 5 and
    10 deg and the same flexopt diagnosis (Table 1 counts); the native scene's export (two beams per leaf, as
    the fixture) releases the fixture's surplus, 7 dynamic deformations (the count by hand above), so its
    D_cc is the fixture's 41 x 34 less 7 rows, square and regular, with 25 - 7 degrees of freedom."""
    scene, imp = load_dat(str(DATA / "cross_pivot_3node.dat"))
    native = _pivot_native()
    vals = [0.0, 5.0, 10.0]
    got = Analysis(scene).frequency_curve(np.array(vals), mesh_error=False)
    ref = Analysis(native).frequency_curve(np.array(vals), mesh_error=False)
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    a = diagnose(scene, spacar_text=imp.text)
    b = diagnose(native)
    assert (a.m, a.n, a.rank) == (b.m, b.n, b.rank)
    assert a.spacar_dof == imp.spacar_dof == 25
    full = spacar_dcc_of_scene(native)  # the export as written: two beams per leaf
    assert (full.m, full.n, full.rank, full.dof, len(full.released)) == (34, 34, 34, 18, 7)
    assert math.isfinite(full.condition_number)


def test_native_diagnosis_reports_spacar_counts_with_one_beam_per_member():
    """A native scene's diagnosis reports SPACAR's count of its model with one beam element per member as
    write_dat writes it: for the cross-spring pivot 12 dynamic deformations and the input, D_cc 27 x 20 (12 +
    12 + 3 rows, 3 x 3 + 3 x 4 - 1 columns) over-constrained by 7 (by hand, as above), so 7 released: D_cc
    20 x 20 and 6 degrees of freedom, the rotor's six motions (each leaf one beam: no node between rotor and
    base), the input one of them; the report and the JSON carry it."""
    d = diagnose(_pivot_native())
    assert d.spacar_dof == 6
    sp = d.spacar
    assert (sp["m"], sp["n"], sp["rank"], sp["over_constrained"], sp["released"]) == (20, 20, 20, 0, 7)
    assert d.to_dict()["spacar_condition_number"] == pytest.approx(d.spacar_condition_number)
    assert "SPACAR's count" in d.report()


def test_a_scene_spacar_cannot_hold_says_why():
    """A drive about a skew axis has no SPACAR input coordinate: the diagnosis says SPACAR's count is not
    available and why, and everything else is reported as usual."""
    sc = template("leaf-spring", segments=2)
    sc = sc.model_copy(update={"stroke": sc.stroke.model_copy(update={"axis": (0.0, 1.0, 1.0)})})
    d = diagnose(sc)
    assert d.spacar_dof is None and d.spacar is not None and d.spacar["available"] is False
    assert "coordinate axis" in d.spacar["why"] and "not available" in d.report()


def _kinematic(text: str) -> str:
    """Seed 002 sec. 4.2's kinematic model of a folded-sheet guide in SPACAR's terms: every sheet keeps its
    elongation and in-plane bending (eps1, eps5, eps6: Oy is the fold line) rigid, sheet B (odd elements) has
    one independent (DYNE) out-of-plane bending, eps4, and the other compliant deformations are dependent
    (RLSE, calculable)."""

    def one(m: re.Match) -> str:
        ne = int(m.group(1))
        return f"DYNE {ne} 4\nRLSE {ne} 2 3" if ne % 2 else f"RLSE {ne} 2 3 4"

    return re.sub(r"DYNE (\d+) 1 2 3 4 5 6", one, text)


@pytest.mark.parametrize(
    "fixture, counts, kinematic",
    [
        # five flexures: 60 DYNE + 30 rigid-link + 11 normalisation rows; 11 X nodes x 3 - 1 + 11 R nodes x 4
        # columns; 61 dof of which 36 independent motions (cylinder 6, folds 30): over-constrained by 25.
        # Kinematic: 30 + 5 + 30 + 11 = 76 rows, square and regular (seed 002 sec. 4.2: "D_cc is non-singular")
        ("folded_guide_5_2node.dat", (101, 76, 76, 61), (76, 76, 76, 0, 0)),
        # six (Figure 5b): the extra flexure adds one constraint: over-constrained by 1 (sec. 4.2)
        ("folded_guide_6_3node.dat", (121, 90, 90, 73), (91, 90, 90, 1, 0)),
        # Figure 5a: the second side's fold lines parallel: under- and over-constrained by 1 (sec. 4.2)
        ("folded_guide_5a_2node.dat", (101, 76, 76, 61), (76, 76, 75, 1, 1)),
    ],
)
def test_folded_sheet_guides_counts_and_seed_002_verdicts(fixture, counts, kinematic):
    """The folded-sheet guides of seed 002 Figures 3b, 5a and 5b (fixtures, both numberings): SPACAR's counts
    of the dynamic model by hand, and of the kinematic model (sec. 4.2) the paper's verdicts."""
    text = (DATA / fixture).read_text()
    d = spacar_dcc(text)
    assert (d.m, d.n, d.rank, d.dof) == counts
    k = spacar_dcc(_kinematic(text))
    assert (k.m, k.n, k.rank, k.over_constrained, k.under_constrained) == kinematic
    if fixture.startswith("folded_guide_5_"):  # regression pin (this code's number; no SPACAR log to check)
        assert k.condition_number == pytest.approx(349.7492928768, rel=1e-9)
    assert k.dof == len(re.findall(r"^DYNE ", _kinematic(text), re.M)) + 1  # the generalised bendings, the input


@pytest.mark.parametrize("count, fixture", [(5, "folded_guide_5_2node.dat"), (6, "folded_guide_6_3node.dat")])
def test_folded_sheet_guide_fixtures_are_the_native_guides(count, fixture):
    """The fixtures give the native templates' frequencies (one beam per sheet, as seed 002 sec. 5 models
    them; the drive free: DYNX) to 1e-9 at 0 and 2 mm, and flexopt's diagnosis of the same partition (the
    template's generalised bending dropped: a .dat's DYNE is flexible, not generalised) has the same counts."""
    scene, imp = load_dat(str(DATA / fixture))
    native = template(f"folded-sheet-guide-{count}", segments=1)
    vals = np.array([0.0, 0.002])
    got = Analysis(scene).frequency_curve(vals, mesh_error=False)
    ref = Analysis(native).frequency_curve(vals, mesh_error=False)
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    plain = native.model_copy(
        update={"elements": tuple(e.model_copy(update={"generalised": ()}) for e in native.elements)}
    )
    a, b = diagnose(scene, spacar_text=imp.text), diagnose(plain)
    assert (a.m, a.n, a.rank) == (b.m, b.n, b.rank)
    assert a.spacar_dof == imp.spacar_dof


def test_cross_hinge_joined_through_a_rigid_link_is_the_native_hinge():
    """Leaf B's end joined to leaf A's by a rigid beam with mass (the fixture): the moving part is that link, a
    rod of m = rhoA L at its middle with inertia m L^2/12 (I - e e^T) (closed form), which the native scene
    states by hand; same frequencies to 1e-9, the same diagnosis, and SPACAR's counts by hand (the file's
    comments)."""
    scene, imp = load_dat(str(DATA / "cross_hinge_link_2node.dat"))
    a1, b1 = np.array([0.02, 0.02, 0.011]), np.array([-0.02, 0.02, -0.011])
    Lr = float(np.linalg.norm(a1 - b1))
    m = 0.5 * Lr
    e = (a1 - b1) / Lr
    native_dict = _pivot_native().model_dump(mode="json")
    native_dict["bodies"] = [
        {
            "name": "link",
            "mass": m,
            "center_of_mass": list((a1 + b1) / 2),
            "inertia": (m * Lr**2 / 12 * (np.eye(3) - np.outer(e, e))).tolist(),
            "nodes": ["a1", "b1"],
        }
    ]
    native_dict["stroke"] = {**native_dict["stroke"], "body": "link", "start": 0.0}
    from flexopt.model.io import scene_from_dict

    native = scene_from_dict(native_dict)
    vals = np.array([0.0, 5.0, 10.0])
    got = Analysis(scene).frequency_curve(vals, mesh_error=False)
    ref = Analysis(native).frequency_curve(vals, mesh_error=False)
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    a, b = diagnose(scene, spacar_text=imp.text), diagnose(native)
    assert (a.m, a.n, a.rank) == (b.m, b.n, b.rank)
    d = a.spacar
    assert (d["m"], d["n"], d["rank"], d["dof"], d["over_constrained"]) == (34, 27, 27, 25, 7)


def _export(name: str, segments: int = 2) -> str:
    """The template's .dat export with ``segments`` beams per member and its stroke from 0 (a SPACAR input
    starts at the reference)."""
    from flexopt.model.scene import Beam
    from flexopt.model.spacar import write_dat

    sc = template(name)
    upd: dict = {
        "elements": tuple(
            e.model_copy(update={"segments": segments}) if isinstance(e, Beam) else e for e in sc.elements
        )
    }
    if sc.stroke is not None:
        upd["stroke"] = sc.stroke.model_copy(update={"start": 0.0})
    return write_dat(sc.model_copy(update=upd))


@pytest.mark.parametrize("name", sorted(set(TEMPLATES) - {"truss12"}))
def test_every_template_export_has_a_square_regular_spacar_dcc(name):
    """write_dat releases (RLSE) the dynamic deformations beyond a maximal independent set (pivoted QR), so
    SPACAR's D_cc of every template's export is square and regular (finite condition number): rows rigid +
    DYNE equal the calculable coordinates, as SPACAR needs to run. The released rows are the surplus: D_cc of
    the export read with every deformation dynamic again (RLSE -> DYNE) has the same rank and as many more rows
    as were released, and the file's second line states the count."""
    text = _export(name)
    d = spacar_dcc(text)
    assert d.m == d.n == d.rank and math.isfinite(d.condition_number), d.verdict
    assert f"{len(d.released)} dynamic deformations released" in text.splitlines()[1]
    unreleased = spacar_dcc(re.sub(r"^RLSE ", "DYNE ", text, flags=re.M))
    assert unreleased.rank == d.rank and unreleased.m == d.m + len(d.released)


def test_truss12_export_keeps_its_rigid_over_constraint():
    """Seed 002 sec. 3.3's truss has rigid trusses (no DYNE): nothing to release, and its D_cc stays 12 x 12 of
    rank 11 (one free motion, one self-stress: the paper's point), which the file's second line does not hide."""
    text = _export("truss12")
    d = spacar_dcc(text)
    assert (d.m, d.n, d.rank, len(d.released)) == (12, 12, 11, 0) and "0 dynamic deformations released" in text


def test_spacar_light_file_with_automatic_releases_is_the_native_pivot():
    """tests/data/spacar/cross_pivot_light_rlse.dat: the cross-spring pivot in the layout SPACAR Light writes
    (stiffness, mass and increments after END/HALT, SPACAR Light's ITERSTEP, BEAMPROPS/CROSSDIM) with 7
    deformations released on the last beam of each leaf as its automatic release does. Released deformations
    keep their ESTIFF stiffness, so the file gives the native pivot's frequencies to 1e-9 at 0, 5 and 10 deg;
    the import report lists the releases; SPACAR's D_cc is the 41 x 34 of the unreleased file (by hand, above)
    less the 7 released rows, square and regular, with 25 - 7 degrees of freedom; ITERSTEP's second number
    (2 steps) gives 3 stroke points."""
    scene, imp = load_dat(str(DATA / "cross_pivot_light_rlse.dat"))
    assert imp.released == {"BEAM 2": [1, 4, 6], "BEAM 4": [1, 3, 5, 6]}
    assert any(n.startswith("released (RLSE") and "BEAM 4 1 3 5 6" in n for n in imp.notes)
    assert imp.spacar_dof == 18 and scene.stroke.points == 3
    vals = np.array([0.0, 5.0, 10.0])
    got = Analysis(scene).frequency_curve(vals, mesh_error=False)
    ref = Analysis(_pivot_native()).frequency_curve(vals, mesh_error=False)
    np.testing.assert_allclose(got.modes_hz, ref.modes_hz, rtol=1e-9)
    d = spacar_dcc(imp.text)
    assert (d.m, d.n, d.rank, d.dof, len(d.released)) == (34, 34, 34, 18, 7)
    assert math.isfinite(d.condition_number)
    # the same file without its releases (RLSE read as DYNE): the fixture's unreleased counts
    u = spacar_dcc(re.sub(r"^RLSE", "DYNE", imp.text, flags=re.M))
    assert (u.m, u.n, u.rank, u.over_constrained) == (41, 34, 34, 7)


def test_spacar_light_tables_with_releases():
    """SPACAR Light's tables of the cross-spring pivot with ``opt.rls`` releasing 7 deformations on each leaf's
    last beam (those of the fixture above): the released deformations keep their stiffness, so the frequencies
    equal those of the same tables without releases to 1e-9 at 0, 5 and 10 deg; the report lists them, and
    SPACAR's D_cc is square and regular (without the releases: over-constrained by 7, as by hand above)."""
    from flexopt.model.io import scene_from_dict
    from flexopt.model.spacar import spacar_light

    nodes = [[-0.02, -0.02, 0.011], [0.02, 0.02, 0.011], [0.02, -0.02, -0.011], [-0.02, 0.02, -0.011], [0, 0.03, 0]]
    leaf = {"emod": 210e9, "smod": 79e9, "dens": 7800, "cshape": "rect", "dim": [0.02, 0.0003], "orien": [0, 0, 1]}
    eprops = [
        {**leaf, "elems": [1, 2], "nbeams": 2, "flex": [1, 2, 3, 4, 5, 6]},
        {**leaf, "elems": [3, 4], "dim": [0.01, 0.01]},  # the rotor's rigid links (flex empty)
    ]
    nprops = {
        1: {"fix": True},
        3: {"fix": True},
        5: {"rot_z": math.radians(10), "mass": 0.1, "mominertia": [2e-5, 0, 0, 2e-5, 0, 2e-5]},
    }
    args = (nodes, [[1, 2], [3, 4], [5, 2], [5, 4]], nprops, eprops)
    rls = [{"def": [1, 4, 6]}, {"def": [1, 3, 5, 6]}]
    released, plain = spacar_light(*args, {"rls": rls}), spacar_light(*args)
    assert released.released == {"BEAM 2": [1, 4, 6], "BEAM 4": [1, 3, 5, 6]} and plain.released == {}
    vals = np.array([0.0, 5.0, 10.0])
    a = Analysis(scene_from_dict(released.scene)).frequency_curve(vals, mesh_error=False)
    b = Analysis(scene_from_dict(plain.scene)).frequency_curve(vals, mesh_error=False)
    np.testing.assert_allclose(a.modes_hz, b.modes_hz, rtol=1e-9)
    d, u = spacar_dcc(released.text), spacar_dcc(plain.text)
    assert d.m == d.n == d.rank and math.isfinite(d.condition_number)
    assert u.over_constrained == 7
