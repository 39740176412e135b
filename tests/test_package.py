"""The installed package: one `flexopt`, no top-level `model`, `optim` or `service` (issue 11, item 8)."""

from __future__ import annotations

import subprocess
import sys
import tempfile


def _run(code: str) -> subprocess.CompletedProcess:
    # outside the checkout, so only what is installed can be imported (the repository root is not on sys.path)
    with tempfile.TemporaryDirectory() as cwd:
        return subprocess.run(
            [sys.executable, "-c", code],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
            env={"PATH": "", "PYTHONNOUSERSITE": "1"},
        )


def test_one_flexopt_package_and_no_top_level_names() -> None:
    r = _run(
        "import importlib.util as u, sys\n"
        "sys.path = [p for p in sys.path if p not in ('', '.')]\n"
        "import flexopt, flexopt.model, flexopt.optim, flexopt.service, flexopt.client\n"
        "assert flexopt.model.Analysis and flexopt.optim.Problem and flexopt.client.Client\n"
        "leaked = [n for n in ('model', 'optim', 'service') if u.find_spec(n) is not None]\n"
        "print(flexopt.__version__, leaked)\n"
        "sys.exit(1 if leaked else 0)\n"
    )
    assert r.returncode == 0, f"installed top-level packages or import failure: {r.stdout} {r.stderr}"
    version = r.stdout.split()[0]
    assert version[0].isdigit() and version != "0+unknown", r.stdout


def test_a_users_model_module_does_not_shadow_flexopt() -> None:
    # a user's own model.py next to their script must not replace flexopt's model package
    with tempfile.TemporaryDirectory() as cwd:
        with open(f"{cwd}/model.py", "w") as f:
            f.write("raise SystemExit('the user model.py was imported instead of flexopt.model')\n")
        r = subprocess.run(
            [sys.executable, "-c", "import flexopt.model as m; print(m.Analysis.__name__)"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    assert r.returncode == 0 and r.stdout.strip() == "Analysis", r.stderr


def test_import_flexopt_is_light() -> None:
    r = _run(
        "import sys, flexopt\n"
        "bad = [m for m in ('casadi', 'fastapi', 'numpy', 'scipy') if m in sys.modules]\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    assert r.returncode == 0, f"import flexopt loaded {r.stdout.strip()} {r.stderr}"
