"""A/B benchmark of the warm exact curve: this checkout against another flexopt (e.g. the base commit).

On a shared machine absolute times drift; what holds is a ratio measured side by side. This script runs
the two versions in alternating child processes (A B A B ...), each child timing ``--inner`` warm 91-point
curves per case after one warm-up, and prints the medians and the median of the per-pair ratios.

Version B is a directory put first on ``PYTHONPATH`` that contains a ``flexopt`` package, e.g. made from a
commit with::

    git archive <commit> | tar -x -C /tmp/base/src
    mkdir -p /tmp/base/pkg/flexopt && cp /tmp/base/src/service/_root/*.py /tmp/base/pkg/flexopt/
    for d in model optim service; do ln -s /tmp/base/src/$d /tmp/base/pkg/flexopt/$d; done
    python bench/bench_ab.py --base /tmp/base/pkg

"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[1])
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_curve import CASES  # noqa: E402  (the cases of the README's speed table, so the rows match)

_CHILD = """
import json, statistics, time
from flexopt.model import Analysis, template
out = {}
for label, name, params in CASES:
    an = Analysis(template(name, **params))
    an.frequency_curve()
    ts = []
    for _ in range(INNER):
        t = time.perf_counter()
        c = an.frequency_curve()
        ts.append(time.perf_counter() - t)
    assert c.status == "complete" and len(c.stroke) == 91
    out[label] = statistics.median(ts)
print(json.dumps(out))
"""


def _run(pythonpath: str, inner: int) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=pythonpath, OPENBLAS_NUM_THREADS="1")
    code = f"CASES = {CASES!r}\nINNER = {inner}\n" + _CHILD
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    """Alternate A (this checkout) and B (``--base``) and print one markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="directory holding the other version's flexopt package")
    ap.add_argument("--pairs", type=int, default=5, help="A B pairs of child processes")
    ap.add_argument("--inner", type=int, default=5, help="warm curves per case and child (median taken)")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    a_runs, b_runs = [], []
    for _ in range(args.pairs):
        a_runs.append(_run(ROOT, args.inner))
        b_runs.append(_run(args.base, args.inner))
    print(f"{args.pairs} interleaved A/B pairs x {args.inner} warm curves; load average {load0:.2f} at start, "
          f"{os.getloadavg()[0]:.2f} at end; {os.cpu_count()} CPUs")
    print("| case | A: this checkout, median [ms] | B: base, median [ms] | speed-up B/A (median of pairs) |")
    print("|---|---|---|---|")
    for label, _, _ in CASES:
        a = [r[label] for r in a_runs]
        b = [r[label] for r in b_runs]
        ratio = statistics.median([y / x for x, y in zip(a, b)])
        print(f"| {label} | {statistics.median(a) * 1e3:.1f} | {statistics.median(b) * 1e3:.1f} | {ratio:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
