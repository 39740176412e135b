"""What the command line prints (issue 26, items 6 and 7): units in every output, the method that ran, modes
in order of frequency, one line per case when redirected, --version, the page's address, requested strokes."""

from __future__ import annotations

import json
import re
from importlib.metadata import version
from pathlib import Path

import pytest
from flexopt.service.cli.main import main


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"flexopt {version('flexopt')}"


def test_serve_prints_the_pages_address(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    uvicorn = pytest.importorskip("uvicorn")
    ran = {}
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: ran.update(kw))
    monkeypatch.setenv("FLEXOPT_DATA_DIR", str(tmp_path))
    code, _, err = _run(capsys, "serve", "--port", "8123")
    assert code == 0 and ran["port"] == 8123
    assert "http://127.0.0.1:8123/" in err and "/docs" in err, err
    code, _, err = _run(capsys, "serve", "--host", "0.0.0.0", "--port", "8125")
    assert "http://127.0.0.1:8125/" in err, "a server on every interface is reached on this machine at 127.0.0.1"


@pytest.mark.parametrize(
    "method, named", [("exact", "method 'exact'"), ("fd1", "method 'fd1'"), ("auto", "(chosen by auto)")]
)
def test_curve_table_names_the_method_and_the_reactions_unit(
    capsys: pytest.CaptureFixture[str], method: str, named: str
) -> None:
    code, out, _ = _run(
        capsys,
        "curve",
        "--template",
        "leaf-spring",
        "--set",
        "points=3",
        "--set",
        "segments=2",
        "--set",
        "stroke=10",
        "--method",
        method,
    )
    assert code in (0, 1)
    first, head = out.splitlines()[:2]
    assert first.startswith("#") and named in first, first
    assert "reaction [N m]" in head, head


def test_curve_json_strokes_are_the_requested_values(capsys: pytest.CaptureFixture[str]) -> None:
    """deg -> rad -> deg gave -29.999999999999996 for a requested -30; the grid is np.linspace(-45, 45, 7),
    whose values are exactly -45, -30, ..., 45 (multiples of 15 in binary floating point)."""
    code, out, _ = _run(
        capsys, "curve", "--template", "cross-spring-pivot", "--set", "points=7", "--set", "segments=2", "--json"
    )
    assert json.loads(out)["stroke"] == [-45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0]


def test_modes_table_in_order_of_frequency_with_the_reactions_unit(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "modes", "--template", "cross-spring-pivot", "--set", "segments=2", "--at-stroke", "45")
    assert code == 0
    lines = out.splitlines()
    assert re.search(r"drive reaction -?[0-9.]+ N m", lines[0]), lines[0]
    rows = [ln.split() for ln in lines[2:] if re.match(r"\s+\d+\s+[0-9.]+\s", ln)]
    hz = [float(r[1]) for r in rows]
    assert len(hz) == 6 and hz == sorted(hz), hz
    assert sorted(int(r[0]) for r in rows) == list(range(1, 7)), "each mode keeps the number --mode takes"


# --- optimise and topology: their tables and plot from result dicts (no optimisation run) ---------------------


def _optimisation_result() -> dict:
    curve = {"stroke": [-45.0, 0.0, 45.0], "parasitic_hz": [80.0, 120.0, 80.0], "method": "exact", "stress_ratio": 0.5}
    return {
        "problem": {
            "verify_points": 31,
            "safety_factor": 1.5,
            "tolerance": 1e-3,
            "families": [
                {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}
            ],
        },
        "families": [
            {
                "template": "cross-spring-pivot",
                "failed": [],
                "best": {
                    "design": {"length": 0.05212, "thickness": 4e-4},
                    "status": "optimal",
                    "initial": curve,
                    "verified": {**curve, "worst_hz": 80.0, "zero_stroke_hz": 120.0, "ratio": 0.667},
                },
            }
        ],
        "ranking": [{"template": "cross-spring-pivot"}],
        "warnings": [],
    }


def test_optimise_table_gives_units_and_the_bound_a_value_sits_on() -> None:
    from flexopt.service.cli.optimise import _table

    row = _table(_optimisation_result()).splitlines()[1]
    assert "length=52.12 mm" in row and "thickness=0.4 mm (upper bound)" in row, row
    assert "length=52.12 mm (" not in row, "a value inside its box is not on a bound"


def test_optimise_plot_names_the_strokes_unit() -> None:
    import matplotlib.pyplot as plt
    from flexopt.service.cli.optimise import result_figure

    fig = result_figure(_optimisation_result())
    try:
        assert fig.axes[0].get_xlabel() == "stroke [deg]"
    finally:
        plt.close(fig)


def test_optimise_prints_one_line_per_case_when_redirected(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import flexopt.optim

    def fake(problem, **kw):  # three cases finishing; the result of the table test
        for done in (1, 2, 3):
            kw["progress"]({"done": done, "total": 3, "id": str(done), "status": "optimal"})
        return _optimisation_result()

    monkeypatch.setattr(flexopt.optim, "optimise", fake)
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(_optimisation_result()["problem"]))
    code, _, err = _run(capsys, "optimise", str(spec))  # capsys: stderr is not a terminal
    assert code == 0
    assert [ln for ln in err.splitlines() if ln.startswith("optimise: case")] == [
        "optimise: case 1/3 optimal",
        "optimise: case 2/3 optimal",
        "optimise: case 3/3 optimal",
    ], err


def test_topology_table_shows_a_design_once_with_its_crossing_variants() -> None:
    from flexopt.service.cli.topology import table

    design = {"length": 0.05, "thickness": 3e-4, "crossing": 0.5}
    common = {
        "family": None,
        "dof": 1,
        "overconstraints": 0,
        "worst_case_hz": 80.0,
        "zero_stroke_hz": 120.0,
        "ratio": 0.667,
        "status": "optimised",
        "design": design,
    }
    cands = [
        {**common, "topology": "R:+-", "same_design_as": None},
        {**common, "topology": "R:+-@", "same_design_as": "R:+-"},
        {**common, "topology": "R:-+@", "same_design_as": "R:+-"},
        {
            **common,
            "topology": "R:++",
            "same_design_as": None,
            "worst_case_hz": 60.0,
            "design": {"length": 0.04, "thickness": 2e-4},
        },
    ]
    result = {
        "counts": {
            "generated": 4,
            "rejected": 0,
            "rejected_by": {},
            "untraceable": 0,
            "optimised": 4,
            "failed": 0,
            "accepted": 4,
        },
        "seconds": {"screen": 0.1, "optimise": 1.0},
        "spec": {"motion": "rotation"},
        "candidates": cands,
        "ranking": ["R:+-", "R:+-@", "R:-+@", "R:++"],
    }
    text = table(result)
    assert text.count("length=50 mm") == 1, text
    assert "also R:+-@, R:-+@" in text and "thickness=0.3 mm" in text and "length=40 mm" in text, text
    ranked = [ln.split()[1] for ln in text.splitlines()[2:] if re.match(r"\s+\d+\s", ln)]
    assert ranked == ["R:+-", "R:++"], ranked
    # the family in words (grammar.family_form), not "-": R:+- is the cross-spring pivot R:+-@ crossing at 0.5
    rows = {ln.split()[1]: ln for ln in text.splitlines()[2:] if re.match(r"\s+\d+\s", ln)}
    assert "cross-spring-pivot (crossing at the midpoint)" in rows["R:+-"], text
    assert rows["R:++"].split()[2] == "-", text
    header = text.splitlines()[1]
    end = header.index("worst [Hz]") + len("worst [Hz]")  # the numbers are right-aligned under their heading
    assert rows["R:+-"].index("80.00") + len("80.00") == end == rows["R:++"].index("60.00") + len("60.00"), text
