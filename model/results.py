"""Result of a frequency-curve analysis and its public (JSON and CSV) forms."""

from __future__ import annotations

import csv
import html
import io
import json
from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["FrequencyCurve", "Failure", "ResultWarning", "WARNING_KINDS"]

#: The kinds of :class:`ResultWarning`: a limit broken by the result (``stress``), a model outside the
#: validity of beam theory (``validity``), a discretisation not converged within its estimate (``mesh``),
#: input whose units look wrong (``units``), and anything else a user must read (``notice``).
WARNING_KINDS = ("stress", "validity", "mesh", "units", "notice")


@dataclass(frozen=True)
class ResultWarning:
    """One thing a result's user must know: the one warning type of every result (curve, modes, diagnosis,
    optimisation). Serialised as ``{"kind", "message", "element", "stroke_range", "value"}``."""

    kind: str  # one of WARNING_KINDS
    message: str  # one line: what is wrong, where, and what to do
    element: str | None = None  # the scene element (member) it applies to, if one
    stroke_range: tuple[float, float] | None = None  # (from, to) in the result's stroke unit, if limited
    value: float | None = None  # the figure behind it (e.g. peak stress utilisation, relative mesh error)

    def to_dict(self) -> dict:
        """A JSON-ready dict."""
        return {
            "kind": self.kind,
            "message": self.message,
            "element": self.element,
            "stroke_range": None if self.stroke_range is None else [float(x) for x in self.stroke_range],
            "value": None if self.value is None or not np.isfinite(self.value) else float(self.value),
        }


@dataclass(frozen=True)
class Failure:
    """Where and why the curve stops before the requested range ends."""

    reason: str  # "divergence" (Newton failed: limit point, snap-through) or "unstable" (bifurcation)
    stroke: float  # estimated stroke at which equilibrium was lost (stroke unit)
    last_converged: float  # last converged, stable stroke value (stroke unit)
    message: str


@dataclass(frozen=True, repr=False)
class FrequencyCurve:
    """Stroke-dependent natural frequencies of a scene.

    Only converged, stable equilibria appear; when the continuation stops early, ``status`` is
    ``"truncated"`` and ``failures`` says at which stroke and why (one entry per direction from 0).
    """

    scene: str
    method: str
    stroke: np.ndarray  # (p,) stroke values in stroke_unit, ascending
    stroke_unit: str
    stroke_kind: str
    modes_hz: np.ndarray  # (p, k) tracked modes, branch order = frequency order at stroke 0
    mode_labels: np.ndarray  # (p, k) "parasitic" | "intended" | "drive"
    parasitic_hz: np.ndarray  # (p,) first parasitic frequency
    drive_reaction: np.ndarray  # (p,) actuator moment [N m] or force [N] along the drive axis
    drive_reaction_unit: str
    max_von_mises: dict[str, np.ndarray]  # member -> (p,) largest von Mises stress [Pa]
    allowable_stress: dict[str, float]  # member -> allowable stress of its material [Pa]
    status: str  # "complete" | "truncated"
    failures: tuple[Failure, ...] = ()
    conventions: dict[str, str] = field(default_factory=dict)
    solver: dict[str, float | str] = field(default_factory=dict)  # numbers, and notes (auto_method, mirrored)
    warnings: tuple[ResultWarning, ...] = ()
    mesh_error: float | None = None  # estimated relative discretisation error of parasitic_hz, if estimated
    provenance: dict = field(default_factory=dict)  # flexopt version, scene hash, method, solver settings

    def to_dict(self) -> dict:
        """A JSON-ready dict (lists instead of arrays)."""

        def clean(a: np.ndarray) -> list:
            return [None if not np.isfinite(v) else float(v) for v in np.ravel(a)]

        return {
            "scene": self.scene,
            "method": self.method,
            "stroke": clean(self.stroke),
            "stroke_unit": self.stroke_unit,
            "stroke_kind": self.stroke_kind,
            "parasitic_hz": clean(self.parasitic_hz),
            "modes_hz": [clean(row) for row in self.modes_hz],
            "mode_labels": [list(map(str, row)) for row in self.mode_labels],
            "drive_reaction": clean(self.drive_reaction),
            "drive_reaction_unit": self.drive_reaction_unit,
            "max_von_mises": {k: clean(v) for k, v in self.max_von_mises.items()},
            "allowable_stress": dict(self.allowable_stress),
            "status": self.status,
            "failures": [asdict(f) for f in self.failures],
            "conventions": dict(self.conventions),
            "solver": dict(self.solver),
            "warnings": [w.to_dict() for w in self.warnings],
            "mesh_error": None
            if self.mesh_error is None or not np.isfinite(self.mesh_error)
            else float(self.mesh_error),
            "provenance": dict(self.provenance),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The result as a JSON string."""
        return json.dumps(self.to_dict(), indent=indent)

    def to_csv(self) -> str:
        """One row per stroke point: stroke, parasitic, each mode, drive reaction, stresses."""
        buf = io.StringIO()
        w = csv.writer(buf)
        k = self.modes_hz.shape[1]
        members = list(self.max_von_mises)
        w.writerow(
            [
                f"stroke_{self.stroke_unit}",
                "parasitic_hz",
                *[f"mode{i + 1}_hz" for i in range(k)],
                f"drive_reaction_{self.drive_reaction_unit.replace(' ', '')}",
                *[f"von_mises_{m}_Pa" for m in members],
            ]
        )
        for i in range(len(self.stroke)):
            w.writerow(
                [
                    f"{self.stroke[i]:.10g}",
                    f"{self.parasitic_hz[i]:.10g}",
                    *[f"{v:.10g}" for v in self.modes_hz[i]],
                    f"{self.drive_reaction[i]:.10g}",
                    *[f"{self.max_von_mises[m][i]:.10g}" for m in members],
                ]
            )
        return buf.getvalue()

    def table(self) -> str:
        """A readable fixed-width table (SI; stroke in its unit), after a ``#`` line naming the scene and the
        method that ran, then failures and warnings as ``#`` lines."""
        k = self.modes_hz.shape[1]
        ran = self.solver.get("auto_method")
        method = f"method '{ran}' (chosen by auto)" if ran else f"method '{self.method}'"
        reaction = f"reaction [{self.drive_reaction_unit}]"
        head = (
            f"{'stroke [' + self.stroke_unit + ']':>14} {'parasitic Hz':>13} "
            + " ".join(f"{'mode ' + str(i + 1):>10}" for i in range(k))
            + f" {reaction:>14} {'max VM [MPa]':>13}"
        )
        lines = [f"# scene '{self.scene}', {method}; modes by frequency at stroke 0, tracked along the stroke", head]
        for i in range(len(self.stroke)):
            vm = max((v[i] for v in self.max_von_mises.values()), default=float("nan"))
            lines.append(
                f"{self.stroke[i]:14.4f} {self.parasitic_hz[i]:13.4f} "
                + " ".join(f"{v:10.3f}" for v in self.modes_hz[i])
                + f" {self.drive_reaction[i]:14.4g} {vm / 1e6:13.3f}"
            )
        for f in self.failures:
            lines.append(f"# truncated: {f.message}")
        for wn in self.warnings:
            lines.append(f"# warning [{wn.kind}] {wn.message}")
        return "\n".join(lines)

    # ------------------------------------------------------------------------------------ notebook forms
    def _summary(self) -> str:
        par = self.parasitic_hz[np.isfinite(self.parasitic_hz)]
        span = f"{par.min():.4g}..{par.max():.4g} Hz" if par.size else "none"
        rng = f"{self.stroke[0]:.4g}..{self.stroke[-1]:.4g} {self.stroke_unit}" if len(self.stroke) else "empty"
        mesh = "" if self.mesh_error is None else f", mesh_error {self.mesh_error:.2g}"
        return (
            f"{len(self.stroke)} points over {rng}, first parasitic {span}, {self.status}"
            f"{mesh}, {len(self.warnings)} warning{'s' * (len(self.warnings) != 1)}"
        )

    def __repr__(self) -> str:
        """One line: scene, method, range, the first parasitic frequency's span, status (not the arrays)."""
        return f"FrequencyCurve({self.scene!r}, method={self.method!r}: {self._summary()})"

    def _repr_html_(self) -> str:
        """Jupyter's rich form: the summary, the warnings and a table of at most eleven rows (every string
        from the scene or the solver escaped)."""
        e = html.escape
        n = len(self.stroke)
        rows = sorted(set(np.linspace(0, n - 1, min(n, 11)).round().astype(int))) if n else []
        head = "".join(
            f"<th>{e(h)}</th>"
            for h in (
                f"stroke [{self.stroke_unit}]",
                "first parasitic [Hz]",
                f"drive reaction [{self.drive_reaction_unit}]",
            )
        )
        body = "".join(
            f"<tr><td>{self.stroke[i]:.4g}</td><td>{self.parasitic_hz[i]:.5g}</td>"
            f"<td>{self.drive_reaction[i]:.4g}</td></tr>"
            for i in rows
        )
        warns = "".join(f"<li><b>{e(w.kind)}</b>: {e(w.message)}</li>" for w in self.warnings)
        fails = "".join(f"<li><b>truncated</b>: {e(f.message)}</li>" for f in self.failures)
        notes = f"<ul>{fails}{warns}</ul>" if warns or fails else ""
        return (
            f"<div><p><b>FrequencyCurve</b> <code>{e(self.scene)}</code>, method <code>{e(self.method)}"
            f"</code>: {e(self._summary())}</p>{notes}<table><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table></div>"
        )

    def to_dataframe(self):  # noqa: ANN201 - pandas is optional, so no annotation names it
        """The curve as a pandas DataFrame indexed by stroke: the first parasitic frequency, every tracked
        mode (``mode1_hz`` ...), the drive reaction and each member's largest von Mises stress.

        Requires pandas (``pip install pandas``); the rest of flexopt does not.
        """
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("FrequencyCurve.to_dataframe needs pandas: pip install pandas") from exc
        cols: dict[str, np.ndarray] = {"parasitic_hz": self.parasitic_hz}
        for i in range(self.modes_hz.shape[1]):
            cols[f"mode{i + 1}_hz"] = self.modes_hz[:, i]
        cols[f"drive_reaction_{self.drive_reaction_unit.replace(' ', '')}"] = self.drive_reaction
        for m, v in self.max_von_mises.items():
            cols[f"von_mises_{m}_Pa"] = v
        return pd.DataFrame(cols, index=pd.Index(self.stroke, name=f"stroke_{self.stroke_unit}"))

    def plot(self, log: bool | None = None):  # noqa: ANN201 - a matplotlib Figure, imported lazily
        """The curve and the stress utilisation against stroke, as a matplotlib ``Figure`` (the figure of
        ``flexopt curve --plot``; ``log`` chooses a logarithmic frequency axis, ``None``: when the modes span
        more than a factor 8)."""
        from ..service.plots import curve_figure  # numpy and matplotlib only; loaded on first plot

        return curve_figure(self, log=log)
