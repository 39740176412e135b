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
