"""A fast-method curve in a fresh process pays no scipy.optimize or scipy.linalg import (issue 26 item 2).

As a one-off command, ``flexopt curve --method auto`` paid 0.15-0.8 s importing ``scipy.optimize`` (for the
mode matching's assignment) and ``scipy.linalg`` (imported by the Taylor module that hermite shares helpers
with, and by the banded solve of the path's curvature): on the double cross that made it slower than exact.
The assignment now certifies its answer without scipy (model/modal.py): checked here against scipy's
``linear_sum_assignment``, the independent solver it must agree with.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from flexopt.model.modal import _assign_certified, assign
from scipy.optimize import linear_sum_assignment


def _scipy(mac: np.ndarray) -> np.ndarray:
    rows, cols = linear_sum_assignment(-mac)
    perm = np.empty(len(rows), dtype=int)
    perm[rows] = cols
    return perm


def _cases() -> list[np.ndarray]:
    """Random square matrices (1-12), MAC-like ones (a permutation plus noise, rows normalised as MACs
    are, with close competitors), and integer ones full of ties (where a certificate must not hold)."""
    rng = np.random.default_rng(26)
    out = []
    for t in range(600):
        n = int(rng.integers(1, 13))
        kind = t % 3
        if kind == 0:
            out.append(rng.random((n, n)))
        elif kind == 1:
            A = 0.3 * rng.random((n, n)) ** 4
            A[np.arange(n), rng.permutation(n)] += rng.uniform(0.2, 1.0, n)
            out.append(A / A.sum(axis=1, keepdims=True))
        else:
            out.append(rng.integers(0, 3, (n, n)).astype(float))
    return out


def test_certified_assignment_is_scipys() -> None:
    """Where the certificate holds, the permutation is scipy's (its exact solver, the independent method);
    it holds on nearly every matrix without ties (else the cold path would still import scipy)."""
    n_cert = n_cont = n_cont_cert = 0
    for k, mac in enumerate(_cases()):
        got = _assign_certified(mac)
        if k % 3 != 2:
            n_cont += 1
        if got is None:
            continue
        n_cert += 1
        n_cont_cert += k % 3 != 2
        ref = _scipy(mac)
        # when each row's best column differs, assign keeps that permutation (optimal, maybe not unique);
        # otherwise it must be scipy's permutation itself
        if np.bincount(np.argmax(mac, axis=1), minlength=len(mac)).max() == 1:
            assert mac[np.arange(len(mac)), got].sum() >= mac[np.arange(len(mac)), ref].sum() - 1e-12
        else:
            np.testing.assert_array_equal(got, ref, err_msg=f"certified assignment differs from scipy's on\n{mac}")
    assert n_cont_cert >= 0.99 * n_cont, f"certified only {n_cont_cert} of {n_cont} matrices without ties"


def test_ties_are_left_to_scipy() -> None:
    """Two optimal assignments (a 2x2 of equal MACs with the best columns equal): no certificate, scipy's
    answer (the previous behaviour) is returned."""
    mac = np.array([[0.5, 0.5], [0.5, 0.5]])
    assert _assign_certified(mac) is None
    np.testing.assert_array_equal(assign(mac), _scipy(mac))


_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.slow
def test_fast_methods_in_a_fresh_process_import_no_scipy_optimize_or_linalg() -> None:
    """The parallel guide's auto curve needs the assignment on ambiguous matches (two per curve), the double
    cross's is the issue's case; neither may load scipy.optimize or scipy.linalg."""
    code = (
        "import json, sys\n"
        "from flexopt.model import template\n"
        "from flexopt.model.methods import frequency_curve\n"
        "for name in ('parallel-leaf-spring', 'double-cross-hinge'):\n"
        "    c = frequency_curve(template(name), method='auto')\n"
        "    assert c.status == 'complete', c.status\n"
        "print(json.dumps(sorted(m for m in sys.modules if m in ('scipy.optimize', 'scipy.linalg'))))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=_ROOT, check=False
    )
    assert out.returncode == 0, out.stderr[-3000:]
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert loaded == [], f"a cold fast-method curve imported {loaded} (0.15-0.8 s each)"
