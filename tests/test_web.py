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

CHROMIUM = next(
    (
        p
        for p in (
            os.environ.get("FLEXOPT_CHROMIUM"),
            shutil.which("chromium"),
            shutil.which("chromium-browser"),
            "/usr/bin/chromium",
        )
        if p and os.path.exists(p)
    ),
    None,
)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no chromium binary (apt-get install chromium; or set FLEXOPT_CHROMIUM): the browser tests need one",
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real uvicorn on 127.0.0.1 (thread executor: no process pool to spawn)."""
    port = _free_port()
    settings = Settings(executor="thread", api_keys="", data_dir=tmp_path_factory.mktemp("data"))
    server = uvicorn.Server(
        uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning", lifespan="on", ws="none")
    )
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
            b = p.chromium.launch(
                executable_path=CHROMIUM,
                headless=True,
                args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
            )
        except Exception as exc:  # noqa: BLE001 - a browser that cannot start is a skip, said why
            pytest.skip(f"chromium at {CHROMIUM} does not start: {exc}")
        yield b
        b.close()


CSP_WATCH = (
    "window.__csp = []; document.addEventListener('securitypolicyviolation', "
    "(e) => window.__csp.push(`${e.violatedDirective} ${e.blockedURI}`));"
)


@pytest.fixture
def shots(tmp_path: Path) -> Path:
    out = Path(os.environ.get("FLEXOPT_SCREENSHOTS") or tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    return out


def test_page_computes_leaf_curve_and_shows_a_mode(url: str, browser: object, shots: Path) -> None:
    import httpx
    from flexopt.model import template

    page = browser.new_page(viewport={"width": 1400, "height": 1500})
    page.add_init_script(CSP_WATCH)  # the page, plotly's 2D and 3D plots included, runs under its CSP
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    external: list[str] = []
    page.on("request", lambda r: None if r.url.startswith((url, "data:", "blob:")) else external.append(r.url))
    page.goto(f"{url}/?template=leaf-spring")
    curve = page.get_by_test_id("curve")
    # the curve is drawn when plotly has put its traces on the container
    page.wait_for_function(
        "() => { const d = document.querySelector('[data-testid=curve]'); return d && d.data && d.data.length > 0; }",
        timeout=30_000,
    )
    plotted = page.evaluate("""() => {
        const d = document.querySelector('[data-testid=curve]').data.find(t => t.name === 'first parasitic');
        const i = d.x.findIndex(x => x === 0);
        return {x: d.x[i], y: d.y[i]};
    }""")
    api = httpx.post(
        f"{url}/v1/frequency-curve", json={"scene": template("leaf-spring").model_dump(mode="json")}, timeout=60
    ).json()
    i0 = api["stroke"].index(0.0)
    assert plotted["x"] == 0.0
    assert plotted["y"] == pytest.approx(api["parasitic_hz"][i0], rel=1e-12), "plotted first parasitic at stroke 0"
    assert curve.locator(".main-svg").count() > 0, "plotly drew no SVG in the curve container"
    # click the curve's point at stroke 0: the page computes and shows the structure and modes there
    box = curve.bounding_box()
    at = page.evaluate(
        """([x, y]) => {
        const gd = document.querySelector('[data-testid=curve]'), L = gd._fullLayout;
        return [L.xaxis._offset + L.xaxis.l2p(x), L.yaxis._offset + L.yaxis.l2p(y)];
    }""",
        [0.0, plotted["y"]],
    )
    page.mouse.move(box["x"] + at[0], box["y"] + at[1])
    page.mouse.click(box["x"] + at[0], box["y"] + at[1])
    page.get_by_test_id("mode-2").wait_for(timeout=30_000)
    page.get_by_test_id("mode-2").click()
    page.wait_for_function(
        "() => { const d = document.querySelector('[data-testid=shape]'); "
        "return d && d.data && d.data.filter(t => t.type === 'mesh3d').length >= 2; }",
        timeout=30_000,
    )
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
    assert page.evaluate("() => window.__csp") == [], "the page's Content-Security-Policy blocked something"
    page.close()


CURVE_DRAWN = (
    "() => { const d = document.querySelector('[data-testid=curve]'); return d && d.data && d.data.length > 0; }"
)


def test_bad_field_shows_its_problem_beside_it_and_units_are_read(url: str, browser: object, shots: Path) -> None:
    """Issue 26 item 5: a 422 named the field and the page showed nothing, under the old curve and a stale
    'done'; inputs now take units ('0.4 mm', converted by the server with pint as the CLI's --set) and show
    long numbers with a prefix ('210 GPa', not '210000000000' cut off)."""
    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#params input').length > 0")
    page.locator("#params input[data-name=points]").fill("5")  # a short curve: the tests run on 2 cores
    page.get_by_test_id("compute").click()
    page.wait_for_function(CURVE_DRAWN, timeout=30_000)
    field = page.locator("#params input[data-name=E]")
    assert field.input_value() == "210 GPa"
    assert page.evaluate("(i) => i.scrollWidth <= i.clientWidth", field.element_handle()), "E is cut off"
    assert page.locator("#params input[data-name=thickness]").input_value() == "0.5 mm"
    assert page.locator("#params input[data-name=length]").input_value() == "100 mm"
    assert page.locator("#params input[data-name=segments]").input_value() == "10"
    thickness = page.locator("#params input[data-name=thickness]")
    for typed, says in (("-0.3 mm", "must be greater than 0"), ("", "cannot read ''")):
        thickness.fill(typed)
        page.get_by_test_id("compute").click()
        error = page.get_by_test_id("error-thickness")
        error.wait_for(timeout=10_000)
        assert "thickness" in error.inner_text() and says in error.inner_text(), error.inner_text()
        assert thickness.get_attribute("aria-invalid") == "true"
        assert "failed" in page.get_by_test_id("status").inner_text()
        assert page.evaluate("() => window.flexopt.curve") is None
        assert page.evaluate("() => !(document.querySelector('[data-testid=curve]').data || []).length"), (
            "the previous design's curve is still drawn"
        )
        assert "field(s) marked" in page.get_by_test_id("curve-note").inner_text()
        if typed:
            page.locator("#design").screenshot(path=str(shots / "web_field_error.png"))
    thickness.fill("0.4 mm")
    page.locator("#params input[data-name=E]").fill("0.2 TPa")
    page.get_by_test_id("compute").click()
    page.wait_for_function(CURVE_DRAWN, timeout=30_000)
    assert page.locator(".field-error").count() == 0 and "done" in page.get_by_test_id("status").inner_text()
    section = page.evaluate("() => window.flexopt.scene.elements[0].section")
    material = page.evaluate("() => window.flexopt.scene.materials[0]")
    # 0.4 mm = 4e-4 m and 0.2 TPa = 2e11 Pa exactly, up to one rounding per pint factor
    assert section["thickness"] == pytest.approx(4e-4, rel=1e-15)
    assert material["E"] == pytest.approx(2e11, rel=1e-15)
    page.close()


def _leaf_normals(scene: dict) -> list[list[float]]:
    """Each rectangular leaf's face normal (tangent x width direction) from the scene, independently of the page."""
    import numpy as np

    pos = {n["name"]: np.array(n["position"]) for n in scene["nodes"]}
    out = []
    for e in scene["elements"]:
        if (e.get("section") or {}).get("kind") == "rectangular" and e.get("y_axis"):
            p, q = (pos[n] for n in e["nodes"])
            n = np.cross(q - p, np.array(e["y_axis"]))
            out.append(list(n / np.linalg.norm(n)))
    return out


def test_pivot_camera_sees_every_leaf_and_frames_the_structure(url: str, browser: object, shots: Path) -> None:
    """Issue 26 item 5: the cross-spring pivot's 3D view showed a leaf edge-on and cut off the structure's bottom."""
    import io

    import numpy as np

    Image = pytest.importorskip("PIL.Image")
    from flexopt.model import template

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    page.select_option("#template", "cross-spring-pivot")
    page.locator("#params input[data-name=segments]").fill("2")  # the geometry is the same; a smaller model
    page.evaluate("() => loadModes(0)")  # the structure and modes at stroke 0, without the curve
    page.get_by_test_id("mode-1").wait_for(timeout=30_000)
    page.get_by_test_id("mode-1").click()
    page.click("#stop")
    page.wait_for_timeout(300)
    eye = page.evaluate("() => document.querySelector('[data-testid=shape]').layout.scene.camera.eye")
    d = np.array([eye["x"], eye["y"], eye["z"]])
    d /= np.linalg.norm(d)
    normals = _leaf_normals(template("cross-spring-pivot").model_dump(mode="json"))
    assert len(normals) == 2
    # |cos| of the angle between the view and a leaf's normal: 0 is edge-on (the old camera: 0.00 for one leaf);
    # 0.3 is 17 deg away from edge-on
    faces = [abs(float(np.dot(d, n))) for n in normals]
    assert min(faces) > 0.3, f"a leaf is seen nearly edge-on: |cos| {faces}"
    assert np.degrees(np.arcsin(abs(d[2]))) > 10, "not an oblique view from above"
    png = page.get_by_test_id("shape").screenshot(path=str(shots / "web_pivot_3d.png"))
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    orange = (r - b > 90) & (r - g > 40)  # the mode shape (#e67e22, shaded); the axes are grey, the page white
    rows, cols = np.nonzero(orange)
    assert rows.size > 2000, "the mode shape is hardly visible"
    margin = 4
    assert (
        rows.min() >= margin
        and cols.min() >= margin
        and rows.max() < img.shape[0] - margin
        and (cols.max() < img.shape[1] - margin)
    ), (
        f"the structure touches the view's edge: rows {rows.min()}-{rows.max()} "
        f"of {img.shape[0]}, columns {cols.min()}-{cols.max()} of {img.shape[1]}"
    )
    page.close()


def test_server_strings_render_as_text(url: str, browser: object, tmp_path: Path) -> None:
    """Issue 29 item 9: server text went into innerHTML (job.error, names, ...) while the API key is in
    localStorage. A scene and a member named as markup, and a job whose every string is markup, render as text."""
    import json

    from flexopt.model import template

    attack = '<img src=x onerror="window.__xss=(window.__xss||0)+1">'
    scene = template("leaf-spring").model_dump(mode="json")
    scene["name"] = attack
    scene["elements"][0]["name"] = "<img/src=y>"  # member names have no spaces
    scene["stroke"]["points"] = 5
    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    path = tmp_path / "attack.json"
    path.write_text(json.dumps(scene))
    page.set_input_files("#scene-file", str(path))
    page.wait_for_function("() => window.flexopt.fileScene !== null")
    page.get_by_test_id("compute").click()
    page.wait_for_function(CURVE_DRAWN, timeout=30_000)
    assert attack in page.locator("#curve .gtitle").text_content()
    page.evaluate("() => loadModes(0)")
    page.get_by_test_id("mode-1").wait_for(timeout=30_000)
    fake = {
        "id": attack,
        "status": attack,
        "error": attack,
        "progress": {"done": 1, "total": 2},
        "partial": [],
        "result": {
            "ranking": [
                {
                    "template": attack,
                    "worst_hz": 1.0,
                    "zero_stroke_hz": 2.0,
                    "design": {attack: 1e-4},
                    "active_bounds": {attack: "upper"},
                }
            ],
            "families": [],
            "warnings": [{"kind": attack, "message": attack}],
        },
    }
    page.evaluate("(job) => renderJob(job)", fake)
    topo = {
        "id": attack,
        "status": attack,
        "error": attack,
        "progress": {
            "done": attack,
            "total": 2,
            "phase": attack,
            "counts": {"generated": attack, "screened": 1, "passed": attack},
            "best": {"topology": attack, "worst_hz": attack, "phase": attack},
        },
        "result": {
            "counts": {"generated": 1, "rejected": 0, "untraceable": 0, "optimised": 1, "failed": 0},
            "best": {"topology": attack},
            "ranking": [attack],
            "spec": {"motion": "rotation"},
            "candidates": [
                {
                    "topology": attack,
                    "family": attack,
                    "dof": attack,
                    "overconstraints": attack,
                    "status": attack,
                    "reason": attack,
                    "refined": {"worst_hz": attack},
                    "scene": scene,
                }
            ],
        },
    }
    page.evaluate("(job) => renderTopology(job)", topo)
    front = {
        "id": attack,
        "status": attack,
        "error": attack,
        "progress": {"done": attack, "total": 3},
        "partial": [{"worst_hz": 1.0, "status": attack}],
        "result": {
            "template": attack,
            "against": "drive_stiffness",
            "drive_stiffness_unit": attack,
            "points": [{"drive_stiffness": 1.0, "worst_hz": 2.0, "design": {attack: 1e-4}, "stress_ratio": 0.5}],
            "warnings": [{"kind": attack, "message": attack}],
        },
    }
    page.evaluate("(job) => renderPareto(job)", front)
    page.wait_for_timeout(300)
    assert page.locator("img").count() == 0, "server text was parsed as markup"
    assert page.evaluate("() => window.__xss") is None, "server text ran as script"
    assert attack in page.get_by_test_id("opt-progress").inner_text()
    assert attack in page.get_by_test_id("ranking").inner_text()
    assert attack in page.get_by_test_id("topo-progress").inner_text()
    assert page.get_by_test_id("topo-phase").inner_text() == attack, "the progress's phase as text"
    assert attack in page.get_by_test_id("topo-best").inner_text(), "the best so far's descriptor as text"
    assert attack in page.get_by_test_id("topo-counts").inner_text(), "the progress's counts as text"
    assert attack in page.get_by_test_id("topo-ranking").inner_text()
    for part in ("pareto-progress", "pareto-points", "pareto-warnings"):
        assert attack in page.get_by_test_id(part).inner_text(), part
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


def test_optimisation_from_the_page_shows_progress_and_ranking(url: str, browser: object, shots: Path) -> None:
    import json

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    tiny = {
        "families": [{"template": "cross-spring-pivot", "design": {"thickness": [1e-4, 4e-4]}}],
        "stroke": 10,
        "samples": 3,
        "modes": 1,
        "starts": 1,
        "max_iterations": 30,
        "refine_rounds": 0,
        "verify_points": 31,
    }
    # enough iterations to converge: an unconverged start is not ranked (optim), and a job without any ranked
    # optimum ends 'failed' with the reasons (service.jobs)
    page.fill("#problem", json.dumps(tiny))
    page.get_by_test_id("optimise").click()
    page.wait_for_function(
        "() => window.flexopt.job && ['succeeded', 'failed', 'cancelled'].includes(window.flexopt.job.status)",
        timeout=120_000,
    )
    job = page.evaluate("() => window.flexopt.job")
    assert job["status"] == "succeeded", job.get("error")
    assert "1 of 1 cases" in page.get_by_test_id("opt-progress").inner_text()
    cells = page.get_by_test_id("ranking").locator("tr").nth(1).locator("td").all_inner_texts()
    best = job["result"]["ranking"][0]
    assert cells[1] == "cross-spring-pivot" and float(cells[2]) == pytest.approx(best["worst_hz"], rel=1e-4)
    # issue 26 item 6: the design with its unit, and whether it sits on a bound of its box (1e-4 to 4e-4 m)
    t = best["design"]["thickness"]
    side = (best["active_bounds"] or {}).get("thickness")
    want = f"thickness {t * 1e3:.4g} mm" + (
        f" (at its {side} bound {4e-4 * 1e3 if side == 'upper' else 1e-4 * 1e3:.4g} mm)" if side else ""
    )
    assert cells[4] == want
    page.locator("section", has=page.get_by_test_id("ranking")).screenshot(path=str(shots / "web_optimisation.png"))
    page.close()


def test_topology_search_from_the_page_shows_ranking_with_thumbnails(url: str, browser: object, shots: Path) -> None:
    import json

    from flexopt.optim.topology.spec import TopologySpec

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.add_init_script(CSP_WATCH)
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelector('#topo-spec').value.length > 0")
    assert json.loads(page.input_value("#topo-spec")) == TopologySpec().model_dump(mode="json"), "the defaults"
    tiny = {
        "topologies": ["R:+-", "R:++"],
        "segments": 4,
        "samples": 5,
        "verify_points": 31,
        "refine_rounds": 1,
        "starts": 1,
    }
    page.fill("#topo-spec", json.dumps(tiny))
    page.get_by_test_id("topology").click()
    page.wait_for_function(
        "() => window.flexopt.topoJob && ['succeeded', 'failed', 'cancelled'].includes(window.flexopt.topoJob.status)",
        timeout=180_000,
    )
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
    assert page.evaluate("() => window.__csp") == [], "the page's Content-Security-Policy blocked something"
    page.close()


TOPO_WATCH = """
window.__topo = [];
document.addEventListener('DOMContentLoaded', () => {
  const box = document.querySelector('#topo-progress');
  const text = (id) => { const e = box.querySelector(`[data-testid=${id}]`); return e ? e.textContent : null; };
  new MutationObserver(() => window.__topo.push({
    status: text('topo-status'), phase: text('topo-phase'), cases: text('topo-cases'), best: text('topo-best'),
    counts: Object.fromEntries([...box.querySelectorAll('[data-count]')].map((b) => [b.dataset.count, b.textContent])),
    rows: document.querySelectorAll('#topo-ranking tr').length,
  })).observe(box, { childList: true, subtree: true });
});
"""


def test_topology_search_shows_its_progress_live_then_the_table(url: str, browser: object, shots: Path) -> None:
    """Issue 30 item 2: a search submitted from the page shows, while it runs, what its job status carries
    (phase, cases of the phase, counts screened / passed / optimised, the best so far with its descriptor and
    worst case), then the ranking. Every rendering of the progress box is recorded as the page draws it."""
    import json

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.add_init_script(TOPO_WATCH)
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelector('#topo-spec').value.length > 0")
    # two exact-constraint candidates (two full-pass cases, then two refinements) and one the filter rejects
    tiny = {"topologies": ["R:+-", "R:x+-", "R:++"], "segments": 4, "samples": 5, "verify_points": 31, "starts": 1}
    page.fill("#topo-spec", json.dumps(tiny))
    page.get_by_test_id("topology").click()
    page.wait_for_function(
        "() => window.flexopt.topoJob && ['succeeded', 'failed', 'cancelled'].includes(window.flexopt.topoJob.status)",
        timeout=180_000,
    )
    job = page.evaluate("() => window.flexopt.topoJob")
    assert job["status"] == "succeeded", job.get("error")
    seen = page.evaluate("() => window.__topo")
    running = [s for s in seen if s["status"] == "running" and s["phase"]]
    assert running, f"no progress was drawn while the search ran: {seen}"
    phases = {s["phase"] for s in running}
    assert phases <= {"screen", "first pass", "full pass", "refine", "generating and screening"}, phases
    res = job["result"]
    # the counts drawn while it ran end at the result's: 3 generated, 2 passed the filter
    counted = [s["counts"] for s in running if s["counts"]]
    assert counted and all(c["generated"] == "3" for c in counted), counted
    assert any(c.get("screened") == "3" and c.get("passed") == "2" for c in counted), counted
    assert all(s["rows"] <= 1 for s in running), "the ranking was drawn before the search ended"
    # the best so far, with its descriptor and worst case, drawn while the search ran (after its first optimum)
    bests = [s["best"] for s in running if s["best"]]
    optimised = {c["topology"]: c for c in res["candidates"] if c["status"] == "optimised"}
    assert set(optimised) == {"R:+-", "R:x+-"}, {c["topology"]: c["status"] for c in res["candidates"]}
    assert bests, f"no best so far was drawn while the search ran: {running}"
    for b in bests:
        name = b.split("best so far: ")[1].split(",")[0]
        hz = float(b.split("worst case ")[1].split(" Hz")[0])
        # the progress's best is a candidate's verified worst case on the search mesh (4 digits drawn)
        assert name in optimised and hz == pytest.approx(optimised[name]["worst_case_hz"], rel=1e-3), (b, optimised)
    # then the table: the ranking first, every candidate a row, its refined worst case beside the search mesh's
    table = page.get_by_test_id("topo-ranking")
    assert table.locator("tr").count() == 4
    first = table.locator("tr").nth(1).locator("td").all_inner_texts()
    families = {
        row.locator("td").nth(2).inner_text(): row.locator("td").nth(3).inner_text()
        for row in table.locator("tr").all()[1:]
    }  # the pivot at its midpoint (R:+-, the family's R:+-@ without '@') is named, the rejected R:++ is no family
    assert families == {
        "R:+-": "cross-spring-pivot (crossing at the midpoint)",
        "R:x+-": "cartwheel-hinge",
        "R:++": "-",
    }, families
    best = res["best"]
    assert first[2] == best["topology"] == res["ranking"][0]
    assert float(first[9]) == pytest.approx(best["refined"]["worst_hz"], rel=1e-3)
    final = page.get_by_test_id("topo-progress").inner_text()
    assert "succeeded" in final and f"best: {best['topology']}" in final, final
    page.locator("section", has=table).screenshot(path=str(shots / "web_topology_progress.png"))
    page.close()


def test_pareto_front_from_the_page_shows_progress_then_the_front(url: str, browser: object, shots: Path) -> None:
    """Issue 30 item 5: a Pareto front submitted from the page shows its job's progress while it runs, then the
    front: one plotted point and one table row per verified point of the result, ordered by drive stiffness."""
    import json

    page = browser.new_page(viewport={"width": 1400, "height": 1100})
    page.add_init_script(CSP_WATCH)
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelector('#pareto-spec').value.length > 0")
    assert json.loads(page.input_value("#pareto-spec"))["format"] == "flexopt-pareto", "prefilled with the example"
    tiny = {  # three points of a short pivot's front, no gradient-free check: seconds on 2 cores
        "points": 3,
        "problem": {
            "families": [{"template": "cross-spring-pivot", "design": {"thickness": [2e-4, 4e-4]}}],
            "stroke": 10,
            "samples": 3,
            "starts": 1,
            "verify_points": 31,
        },
    }
    page.fill("#pareto-spec", json.dumps(tiny))
    page.get_by_test_id("pareto").click()
    page.wait_for_function(
        "() => window.flexopt.paretoJob && "
        "['succeeded', 'failed', 'cancelled'].includes(window.flexopt.paretoJob.status)",
        timeout=180_000,
    )
    job = page.evaluate("() => window.flexopt.paretoJob")
    assert job["status"] == "succeeded", job.get("error")
    pts = sorted(job["result"]["points"], key=lambda q: q["drive_stiffness"])
    assert len(pts) >= 2
    plotted = page.evaluate("() => document.querySelector('[data-testid=pareto-plot]').data[0]")
    assert plotted["x"] == [q["drive_stiffness"] for q in pts] and plotted["y"] == [q["worst_hz"] for q in pts]
    rows = page.get_by_test_id("pareto-points").locator("tr")
    assert rows.count() == len(pts) + 1
    for i, q in enumerate(pts):
        cells = rows.nth(i + 1).locator("td").all_inner_texts()
        assert float(cells[2]) == pytest.approx(q["worst_hz"], rel=1e-3)
        assert cells[5].startswith("thickness ") and cells[5].endswith(" mm")
    assert "succeeded" in page.get_by_test_id("pareto-progress").inner_text()
    page.locator("section", has=page.get_by_test_id("pareto-plot")).screenshot(path=str(shots / "web_pareto.png"))
    # while it runs: the page draws the front so far from the job's partial summaries, each finished case with its
    # phase and its verified drive stiffness (the same numbers as the result's points: one start per level)
    partial = job["partial"]
    assert {q["phase"] for q in partial} == {"optima", "levels"}, partial
    assert sorted(q["drive_stiffness"] for q in partial) == [q["drive_stiffness"] for q in pts]
    running = {**job, "status": "running", "result": None, "progress": {"phase": "levels", "done": 0, "total": 1}}
    page.evaluate("(job) => renderPareto(job)", running)
    assert page.get_by_test_id("pareto-phase").inner_text() == "levels"
    drawn = page.evaluate("() => document.querySelector('[data-testid=pareto-plot]').data")
    assert drawn[0]["name"] == "front so far (verified)" and len(drawn) == 1, "every finished point is on the front"
    assert drawn[0]["x"] == [q["drive_stiffness"] for q in pts] and drawn[0]["y"] == [q["worst_hz"] for q in pts]
    # the first two cases only (the two optima): the front so far is those two
    page.evaluate("(job) => renderPareto(job)", {**running, "partial": [q for q in partial if q["phase"] == "optima"]})
    ends = page.evaluate("() => document.querySelector('[data-testid=pareto-plot]').data[0]")
    assert ends["x"] == [pts[0]["drive_stiffness"], pts[-1]["drive_stiffness"]]
    assert page.evaluate("() => window.__csp") == [], "the page's Content-Security-Policy blocked something"
    page.close()


def test_spacar_model_loads_from_the_page(url: str, browser: object) -> None:
    """A SPACAR .dat model chosen as the scene file is imported by the server (/v1/scenes/import) and
    diagnosed: the twelve-truss structure of seed 002 has one free motion and one self-stress."""
    page = browser.new_page(viewport={"width": 1400, "height": 1200})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    page.set_input_files("#scene-file", str(Path(__file__).parent / "data" / "spacar" / "truss12.dat"))
    page.wait_for_function("() => window.flexopt.fileScene && window.flexopt.fileScene.name === 'truss12'")
    assert "using SPACAR model truss12.dat" in page.locator("#scene-note").inner_text()
    page.get_by_test_id("diagnose").click()
    page.get_by_test_id("diagnosis-3d").wait_for(timeout=30_000)
    text = page.get_by_test_id("diagnosis").inner_text()
    assert "1 free motion(s), 1 self-stress(es)" in text, text[:300]
    page.close()


def test_state_space_panel_draws_a_bode_plot(url: str, browser: object) -> None:
    """The linearised-model panel posts to /v1/state-space and draws the frequency response; its static gain
    is the seed leaf's clamped-guided tip compliance L^3 / (12 EI) (tests/test_linear.py checks the number)."""
    page = browser.new_page(viewport={"width": 1400, "height": 1200})
    page.goto(f"{url}/")
    page.wait_for_function("() => document.querySelectorAll('#template option').length > 0")
    page.get_by_test_id("statespace").click()
    page.wait_for_function("() => window.flexopt.stateSpace !== undefined", timeout=60_000)
    gain = page.evaluate("() => window.flexopt.stateSpace.static_gain[0][0]")
    L, EI = 0.1, 210e9 * 0.04 * 0.0005**3 / 12
    assert gain == pytest.approx(L**3 / (12 * EI), rel=1e-9)
    assert "static gain" in page.get_by_test_id("ss-note").inner_text()
    assert page.locator("#bode .main-svg").count() > 0
    page.close()
