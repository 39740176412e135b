"""The web page in a real browser: Playwright driving the system chromium against a real uvicorn.

Playwright cannot download its own browsers here, so it is pointed at the Debian ``chromium`` binary
(``.ci/run`` installs it); the tests skip, saying why, only when no browser can be had.
Screenshots go to ``FLEXOPT_SCREENSHOTS`` (default: pytest's temporary directory).
"""

from __future__ import annotations

import os
import shutil
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("uvicorn")
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright for Python is not installed")

import uvicorn  # noqa: E402

from flexopt.service.api.app import create_app  # noqa: E402
from flexopt.service.api.settings import Settings  # noqa: E402

CHROMIUM = next((p for p in (os.environ.get("FLEXOPT_CHROMIUM"), shutil.which("chromium"),
                             shutil.which("chromium-browser"), "/usr/bin/chromium") if p and os.path.exists(p)), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (apt-get install chromium; or set "
                                                         "FLEXOPT_CHROMIUM): the browser tests need one")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real uvicorn on 127.0.0.1 (thread executor: no process pool to spawn)."""
    port = _free_port()
    settings = Settings(executor="thread", api_keys="", data_dir=tmp_path_factory.mktemp("data"))
    server = uvicorn.Server(uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning",
                                           lifespan="on", ws="none"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "uvicorn did not start"
        time.sleep(0.02)
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(10)


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                  args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
        except Exception as exc:  # noqa: BLE001 - a browser that cannot start is a skip, said why
            pytest.skip(f"chromium at {CHROMIUM} does not start: {exc}")
        yield b
        b.close()


@pytest.fixture
def shots(tmp_path: Path) -> Path:
    out = Path(os.environ.get("FLEXOPT_SCREENSHOTS") or tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    return out


def test_page_computes_leaf_curve_and_shows_a_mode(url: str, browser: object, shots: Path) -> None:
    import httpx

    from flexopt.model import template

    page = browser.new_page(viewport={"width": 1400, "height": 1500})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    external: list[str] = []
    page.on("request", lambda r: None if r.url.startswith((url, "data:", "blob:")) else external.append(r.url))
    page.goto(f"{url}/?template=leaf-spring")
    curve = page.get_by_test_id("curve")
    # the curve is drawn when plotly has put its traces on the container
    page.wait_for_function("() => { const d = document.querySelector('[data-testid=curve]'); "
                           "return d && d.data && d.data.length > 0; }", timeout=30_000)
    plotted = page.evaluate("""() => {
        const d = document.querySelector('[data-testid=curve]').data.find(t => t.name === 'first parasitic');
        const i = d.x.findIndex(x => x === 0);
        return {x: d.x[i], y: d.y[i]};
    }""")
    api = httpx.post(f"{url}/v1/frequency-curve", json={"scene": template("leaf-spring").model_dump(mode="json")},
                     timeout=60).json()
    i0 = api["stroke"].index(0.0)
    assert plotted["x"] == 0.0
    assert plotted["y"] == pytest.approx(api["parasitic_hz"][i0], rel=1e-12), "plotted first parasitic at stroke 0"
    assert curve.locator(".main-svg").count() > 0, "plotly drew no SVG in the curve container"
    # click the curve's point at stroke 0: the page computes and shows the structure and modes there
    box = curve.bounding_box()
    at = page.evaluate("""([x, y]) => {
        const gd = document.querySelector('[data-testid=curve]'), L = gd._fullLayout;
        return [L.xaxis._offset + L.xaxis.l2p(x), L.yaxis._offset + L.yaxis.l2p(y)];
    }""", [0.0, plotted["y"]])
    page.mouse.move(box["x"] + at[0], box["y"] + at[1])
    page.mouse.click(box["x"] + at[0], box["y"] + at[1])
    page.get_by_test_id("mode-2").wait_for(timeout=30_000)
    page.get_by_test_id("mode-2").click()
    page.wait_for_function("() => { const d = document.querySelector('[data-testid=shape]'); "
                           "return d && d.data && d.data.filter(t => t.type === 'mesh3d').length >= 2; }",
                           timeout=30_000)
    shapes = page.evaluate("() => window.flexopt.shapes")
    assert shapes["stroke"] == 0.0
    assert shapes["modes"][1]["label"] == "parasitic"
    title = page.get_by_test_id("shape-title").inner_text()
    assert "leaf-spring at stroke 0" in title
    assert "drawn at scale" in page.locator("#scale-note").inner_text()
    page.wait_for_timeout(400)  # let the animation draw a displaced frame
    page.screenshot(path=str(shots / "web_page.png"), full_page=False)
    assert not errors, f"JavaScript errors on the page: {errors}"
    assert not external, f"the page loaded assets from outside the server: {external}"
    page.close()


def test_diagnosis_and_docs_offline(url: str, browser: object, shots: Path, tmp_path: Path) -> None:
    page = browser.new_page(viewport={"width": 1400, "height": 1200})
    external: list[str] = []
    page.on("request", lambda r: None if r.url.startswith((url, "data:", "blob:")) else external.append(r.url))
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    # a scene file, as an engineer would load one (here wire-guide-parallel's scene)
    from flexopt.model import template

    path = tmp_path / "guide.json"
    path.write_text(template("wire-guide-parallel").model_dump_json())
    page.set_input_files("#scene-file", str(path))
    page.wait_for_function("() => window.flexopt.fileScene && window.flexopt.fileScene.name === 'wire-guide-parallel'")
    assert "using scene file guide.json" in page.locator("#scene-note").inner_text()
    page.get_by_test_id("diagnose").click()
    page.get_by_test_id("diagnosis-3d").wait_for(timeout=30_000)
    text = page.get_by_test_id("diagnosis").inner_text()
    assert "free motion 1" in text and "rz 0.95" in text, text[:500]
    page.wait_for_timeout(300)
    page.get_by_test_id("diagnosis").screenshot(path=str(shots / "web_diagnosis.png"))
    assert not external, f"the page loaded assets from outside the server: {external}"
    # the API docs work offline: every request leaving the server is refused, the pages still render
    # (ReDoc asks its CDN for its own logo only; refused, it shows none)
    page.route("**/*", lambda route: route.continue_() if route.request.url.startswith(url) else route.abort())
    page.goto(url + "/docs")
    page.wait_for_selector(".swagger-ui .opblock", timeout=20_000)
    assert page.locator(".swagger-ui .opblock").count() >= 5
    page.goto(url + "/redoc")
    page.wait_for_selector("[data-role='redoc-summary'], .menu-content", timeout=20_000)
    assert "frequency-curve" in page.content()
    page.close()


def test_optimisation_from_the_page_shows_progress_and_ranking(url: str, browser: object) -> None:
    import json

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    tiny = {"families": [{"template": "cross-spring-pivot", "design": {"thickness": [1e-4, 4e-4]}}], "stroke": 10,
            "samples": 3, "modes": 1, "starts": 1, "max_iterations": 30, "refine_rounds": 0, "verify_points": 31}
    # enough iterations to converge: an unconverged start is not ranked (optim), and a job without any ranked
    # optimum ends 'failed' with the reasons (service.jobs)
    page.fill("#problem", json.dumps(tiny))
    page.get_by_test_id("optimise").click()
    page.wait_for_function("() => window.flexopt.job && ['succeeded', 'failed', 'cancelled']"
                           ".includes(window.flexopt.job.status)", timeout=120_000)
    job = page.evaluate("() => window.flexopt.job")
    assert job["status"] == "succeeded", job.get("error")
    assert "1 of 1 cases" in page.get_by_test_id("opt-progress").inner_text()
    cells = page.get_by_test_id("ranking").locator("tr").nth(1).locator("td").all_inner_texts()
    best = job["result"]["ranking"][0]
    assert cells[1] == "cross-spring-pivot" and float(cells[2]) == pytest.approx(best["worst_hz"], rel=1e-4)
    page.close()


def test_topology_search_from_the_page_shows_ranking_with_thumbnails(url: str, browser: object, shots: Path) -> None:
    import json

    from flexopt.optim.topology.spec import TopologySpec

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelector('#topo-spec').value.length > 0")
    assert json.loads(page.input_value("#topo-spec")) == TopologySpec().model_dump(mode="json"), "the defaults"
    tiny = {"topologies": ["R:+-", "R:++"], "segments": 4, "samples": 5, "verify_points": 31, "refine_rounds": 1,
            "starts": 1}
    page.fill("#topo-spec", json.dumps(tiny))
    page.get_by_test_id("topology").click()
    page.wait_for_function("() => window.flexopt.topoJob && ['succeeded', 'failed', 'cancelled']"
                           ".includes(window.flexopt.topoJob.status)", timeout=180_000)
    job = page.evaluate("() => window.flexopt.topoJob")
    assert job["status"] == "succeeded", job.get("error")
    table = page.get_by_test_id("topo-ranking")
    page.wait_for_function("() => document.querySelectorAll('#topo-ranking svg.thumb').length === 2")
    first = table.locator("tr").nth(1)
    cells = first.locator("td").all_inner_texts()
    best = job["result"]["best"]
    assert cells[0] == "1" and cells[2] == "R:+-" and float(cells[7]) == pytest.approx(best["worst_case_hz"], rel=1e-3)
    assert first.locator("svg.thumb line.leaf").count() == 2, "the two leaves of the optimised design"
    second = table.locator("tr").nth(2).locator("td").all_inner_texts()
    assert second[2] == "R:++" and second[6].startswith("rejected: underconstrained")
    assert table.locator("tr").nth(2).locator("svg.thumb line.leaf").count() == 2, "drawn from the template"
    page.locator("section", has=table).screenshot(path=str(shots / "web_topology.png"))
    page.close()
