"""The notebook side of the Python API: a curve's short repr, its Jupyter HTML, DataFrame and figure."""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model import frequency_curve, template


@pytest.fixture(scope="module")
def curve():
    return frequency_curve(template("leaf-spring", points=5, segments=4))


def test_repr_is_one_short_line(curve) -> None:
    """The dataclass repr printed every array (24,874 characters for a 91-point curve): now one line."""
    text = repr(curve)
    assert "\n" not in text and len(text) < 250, text
    assert "leaf-spring" in text and "exact" in text and "complete" in text


def test_html_repr_escapes_server_and_scene_text(curve) -> None:
    """Strings from the scene reach the notebook's HTML escaped: a name is text, never markup."""
    import dataclasses

    evil = dataclasses.replace(curve, scene="<img src=x onerror=alert(1)>")
    page = evil._repr_html_()
    assert "<img" not in page and "&lt;img src=x onerror=alert(1)&gt;" in page
    assert page.count("<tr>") == 1 + len(curve.stroke)  # header and every row of a 5-point curve


def test_dataframe_holds_the_arrays(curve) -> None:
    pd = pytest.importorskip("pandas")
    df = curve.to_dataframe()
    assert isinstance(df, pd.DataFrame)
    np.testing.assert_array_equal(df.index.to_numpy(), curve.stroke)
    np.testing.assert_array_equal(df["parasitic_hz"].to_numpy(), curve.parasitic_hz)
    for i in range(curve.modes_hz.shape[1]):
        np.testing.assert_array_equal(df[f"mode{i + 1}_hz"].to_numpy(), curve.modes_hz[:, i])


def test_plot_returns_a_figure(curve) -> None:
    from matplotlib.figure import Figure

    fig = curve.plot()
    assert isinstance(fig, Figure) and fig.axes


def test_root_namespace_shows_only_the_package_names() -> None:
    """Tab completion on ``flexopt`` showed ``Any``, ``annotations`` and ``importlib``."""
    import flexopt

    names = set(dir(flexopt))
    assert not names & {"Any", "annotations", "importlib"}, names
    assert {"curve", "modes", "diagnose", "optimise", "template", "load", "model", "client"} <= names


def test_top_level_curve_is_the_model_curve(tmp_path) -> None:
    """``flexopt.curve`` on a template name with parameters, on a scene dict and on a scene file gives the
    curve of ``flexopt.model`` on the same scene (the same numbers: one code path underneath)."""
    import json

    import flexopt

    scene = template("leaf-spring", points=3, segments=4)
    ref = frequency_curve(scene)
    path = tmp_path / "leaf.json"
    path.write_text(scene.model_dump_json())
    for got in (
        flexopt.curve("leaf-spring", points=3, segments=4),
        flexopt.curve(json.loads(path.read_text())),
        flexopt.curve(path),
    ):
        np.testing.assert_array_equal(got.parasitic_hz, ref.parasitic_hz)


def test_top_level_load_names_what_it_cannot_find() -> None:
    import flexopt

    with pytest.raises(FileNotFoundError, match="no scene file 'leaf-sprung' and no template"):
        flexopt.load("leaf-sprung")
    with pytest.raises(TypeError, match="template parameters apply to a template's name"):
        flexopt.load(template("leaf-spring"), points=3)


@pytest.mark.slow
def test_example_notebook_executes(tmp_path) -> None:
    """examples/notebook.py (jupytext percent format) runs top to bottom as a Jupyter notebook."""
    jupytext = pytest.importorskip("jupytext")
    nbclient = pytest.importorskip("nbclient")
    from pathlib import Path

    nb = jupytext.read(Path(__file__).resolve().parent.parent / "examples" / "notebook.py")
    client = nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any("text/html" in o.get("data", {}) for o in outputs), "the curve's rich HTML form was shown"
    assert any("image/png" in o.get("data", {}) for o in outputs), "a figure was drawn"
