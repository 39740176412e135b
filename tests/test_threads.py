"""flexopt computes on one BLAS thread without the user setting anything (issue 26 item 2, model/threads.py).

Each check runs in a fresh subprocess whose environment has none of the ``*_NUM_THREADS`` variables that
tests/conftest.py sets for the test process: that is how users run flexopt. The thread counts are read with
threadpoolctl *inside* the compute (a callback that sees every converged point, or a probe on the eigen
solve) and after it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

# every variable through which a BLAS, LAPACK or OpenMP library reads its thread count, and flexopt's own
_VARIABLES = (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "FLEXOPT_BLAS_THREADS",
)
pytestmark = pytest.mark.slow


def _clean_env() -> dict[str, str]:
    """The test process's environment without any BLAS thread setting (as a user's shell has it)."""
    return {k: v for k, v in os.environ.items() if k not in _VARIABLES}


_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def blas_counts(case: dict) -> dict:
    """A batch case (run in a pool worker): the BLAS thread counts there, scipy's own OpenBLAS loaded."""
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info

    return {"counts": sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})}


def _run(code: str, timeout: float = 300) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=_clean_env(),
        capture_output=True,
        check=False,
        text=True,
        timeout=timeout,
        cwd=_ROOT,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


_PRELUDE = textwrap.dedent("""
    import json, threading
    import numpy as np
    from threadpoolctl import threadpool_info, threadpool_limits

    def counts():
        return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})

    def all_libs():  # scipy's own OpenBLAS loads with scipy.linalg: load it so the user's setting covers it
        import scipy.linalg  # noqa: F401

    all_libs()
    threadpool_limits(limits=2)  # the user's own setting, which flexopt must give back after each call
    user = counts()
""")


def test_python_api_computes_on_one_thread_and_restores_the_users_setting() -> None:
    got = _run(
        _PRELUDE
        + textwrap.dedent("""
        from flexopt.model import Analysis, template
        from flexopt.model.methods import frequency_curve

        inside = []
        an = Analysis(template("leaf-spring"))
        an.frequency_curve(visit=lambda eq, modes, labels: inside.append(counts()))
        after_exact = counts()
        import flexopt.model.methods.hermite as h  # the fast method's eigen solves, probed where it calls them
        solve = h.modes_at
        fast = []
        def probe(*a, **k):
            fast.append(counts())
            return solve(*a, **k)
        h.modes_at = probe
        frequency_curve(template("leaf-spring"), method="hermite")
        print(json.dumps({"user": user, "inside": inside, "after_exact": after_exact, "fast": fast,
                          "after_fast": counts()}))
    """)
    )
    assert got["user"] == [2], f"the user's setting did not take: {got['user']}; the test cannot tell 1 from it"
    assert got["inside"] and all(c == [1] for c in got["inside"]), (
        f"exact curve computed with BLAS threads {got['inside']} (one expected: model/threads.py)"
    )
    assert got["fast"] and all(c == [1] for c in got["fast"]), (
        f"hermite computed with BLAS threads {got['fast']} (one expected)"
    )
    assert got["after_exact"] == got["user"] and got["after_fast"] == got["user"], (
        f"the user's setting {got['user']} was not restored: {got['after_exact']}, {got['after_fast']}"
    )


def test_concurrent_calls_keep_the_limit_until_the_last_leaves() -> None:
    """Thread A and thread B compute at once; A returns while B still computes. A naive context (each call
    saves and restores) gives B the user's threads back in the middle of its curve, and leaves the process
    at one thread after both."""
    got = _run(
        _PRELUDE
        + textwrap.dedent("""
        from flexopt.model import Analysis, template

        both_in = threading.Barrier(2, timeout=120)
        a_done = threading.Event()
        seen = {"A": [], "B": []}

        def visit_a(eq, modes, labels):
            if not seen["A"]:
                both_in.wait()
            seen["A"].append(counts())

        def visit_b(eq, modes, labels):
            if not seen["B"]:
                both_in.wait()
                a_done.wait(120)  # B's remaining points run after A has returned
            seen["B"].append(counts())

        an_a, an_b = Analysis(template("leaf-spring")), Analysis(template("leaf-spring"))

        def run_a():
            an_a.frequency_curve(visit=visit_a, mirror=False)
            a_done.set()

        ta = threading.Thread(target=run_a)
        tb = threading.Thread(target=lambda: an_b.frequency_curve(visit=visit_b, mirror=False))
        ta.start(); tb.start(); ta.join(); tb.join()
        print(json.dumps({"user": user, "A": seen["A"], "B": seen["B"], "after": counts()}))
    """)
    )
    assert got["user"] == [2]
    assert got["A"] and got["B"] and all(c == [1] for c in got["A"] + got["B"]), (
        f"a concurrent call computed with other than one BLAS thread: A {got['A']}, B {got['B']}"
    )
    assert got["after"] == got["user"], f"after both calls the process has {got['after']}, not the user's {got['user']}"


def test_pool_workers_compute_on_one_thread() -> None:
    """A batch on the default process pool: each worker limits itself at its start, the caller is untouched."""
    got = _run(
        _PRELUDE
        + textwrap.dedent("""
        from flexopt.optim.batch import run_cases

        if __name__ == "__main__":
            recs = run_cases([{"i": 0}, {"i": 1}], "tests.test_threads:blas_counts", workers=2)
            print(json.dumps({"user": user, "workers": [r.get("result", r) for r in recs], "after": counts()}))
    """)
    )
    assert got["workers"] and all(r.get("counts") == [1] for r in got["workers"]), (
        f"pool workers' BLAS threads: {got['workers']}"
    )
    assert got["after"] == got["user"] == [2]


def test_a_bad_thread_setting_is_one_line_naming_the_variable() -> None:
    from flexopt.model import threads

    old = os.environ.get("FLEXOPT_BLAS_THREADS")
    os.environ["FLEXOPT_BLAS_THREADS"] = "many"
    try:
        with pytest.raises(ValueError, match="FLEXOPT_BLAS_THREADS='many' is not a positive integer"):
            threads.threads()
    finally:
        if old is None:
            del os.environ["FLEXOPT_BLAS_THREADS"]
        else:
            os.environ["FLEXOPT_BLAS_THREADS"] = old


def test_cli_limits_its_whole_process() -> None:
    """``flexopt curve``: one thread inside the compute, and the process (and any child it starts: the
    variables) stays limited after it, since the process is flexopt's."""
    got = _run(
        _PRELUDE
        + textwrap.dedent("""
        import os
        import flexopt.model.analysis as a
        from flexopt.service.cli.main import main

        solve, inside = a.modes_at, []
        def probe(*args, **kw):
            inside.append(counts())
            return solve(*args, **kw)
        a.modes_at = probe
        code = main(["curve", "--template", "leaf-spring", "--set", "points=5", "--set", "segments=4"])
        print(json.dumps({"code": code, "user": user, "inside": inside, "after": counts(),
                          "env": os.environ.get("OPENBLAS_NUM_THREADS")}))
    """)
    )
    assert got["code"] == 0 and got["user"] == [2]
    assert got["inside"] and all(c == [1] for c in got["inside"]), f"CLI computed with {got['inside']}"
    assert got["after"] == [1] and got["env"] == "1", f"the CLI's process is not limited: {got}"


def test_server_lifespan_limits_the_process() -> None:
    """``flexopt serve``'s application: from its start, the server process is limited (its worker and job
    processes too: they limit themselves, and inherit the variables); a request still answers."""
    got = _run(
        _PRELUDE
        + textwrap.dedent("""
        import os, tempfile
        from fastapi.testclient import TestClient
        from flexopt.model import template
        from flexopt.service.api.app import create_app
        from flexopt.service.api.settings import Settings

        app = create_app(Settings(data_dir=tempfile.mkdtemp()))
        with TestClient(app, base_url="http://localhost") as client:  # a Host the allow-list accepts
            during = counts()
            env = os.environ.get("OPENBLAS_NUM_THREADS")
            scene = template("leaf-spring", points=3, segments=2).model_dump(mode="json")
            r = client.post("/v1/frequency-curve", json={"scene": scene})
        print(json.dumps({"user": user, "during": during, "env": env, "status": r.status_code,
                          "curve": r.json().get("status")}))
    """)
    )
    assert got["user"] == [2]
    assert got["during"] == [1] and got["env"] == "1", f"the server's process is not limited: {got}"
    assert got["status"] == 200 and got["curve"] == "complete"
