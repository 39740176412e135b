"""The ``hermite`` method: exact samples with exact stroke derivatives, joined by cubic Hermite interpolation.

At a few stroke samples ``s_i`` the equilibrium and the eigenpairs are solved exactly (model.statics,
model.modal, the same solves as the exact method), and each tracked eigenvalue's stroke derivative is
computed exactly there (Nelson's formula for a mass-normalised mode; Fox and Kapoor 1968, eq. 9 of seed
000 with the corrected denominator):

    d lambda_i / ds = phi_i^T (dK/ds - lambda_i dM/ds) phi_i,

with ``dq/ds`` the equilibrium tangent (from the Newton system), ``dK/ds`` the exact directional derivative
of the element Hessians along it (CasADi third derivative, :meth:`System.hessian_derivative`) carried
into the chart the exact method uses at ``s`` (:func:`model.methods.taylor._to_reference_chart`, first
order, plus the drive reaction times the first-order BCH term ``Gamma_e``, which vanishes at stroke 0 but
not at a loaded sample) and ``dM/ds`` from :func:`model.methods.taylor.projected_mass_slope`. Clusters of
(numerically) equal eigenvalues take the eigenvalues of the cluster
matrix ``P^T (dK/ds - lambda_c dM/ds) P`` (degenerate perturbation) in ascending order; the gap is
``SLOPE_CLUSTER_GAP``.

Between samples each tracked branch (modes matched by the mass-weighted MAC, as in the exact method)
is the cubic Hermite polynomial through both values and both slopes of ``mu = 1 / lambda``
(``dmu/ds = -lambda' / lambda^2``); its interpolation error is ``h^4 / 384`` times the largest fourth
derivative of ``mu`` (de Boor, A Practical Guide to Splines, ch. IV). Why ``1 / lambda``: a parasitic
stiffness of a flexure is a support stiffness in series with a compliance that grows as ``s^2``
(PHYSICS.md, the 1/700 term), so ``1 / lambda`` is close to a low-order polynomial in the stroke where
``lambda`` itself falls by orders of magnitude (cross-spring pivot: 426 Hz to 39 Hz over 45 deg).
Where the lowest two parasitic modes exchange their shapes between two samples (a veering, as on the double
cross hinge near 37 deg, where the MAC cannot tell which branch continues which), the two are interpolated
together through ``mu_1 + mu_2`` and ``(mu_1 - mu_2)^2`` (the pair form, :func:`_pair_forms`), smooth
through the veering where each branch alone turns sharply. The eigenvalues at the samples cannot tell a
veering from a crossing where the MAC follows the two cleanly (both exchange the shapes), so the eigenvectors
decide: where the lowest parasitic branch at one sample is not the lowest at the next (a swap), or keeps its
place while its shape turns (MAC with itself below ``VEER_MAC``), the two lowest are interpolated as a pair,
and the branches read as a crossing are its comparison in the estimate; a probe is trusted only where the
lowest parasitic mode at each end is, by its shape, the lowest at the midpoint (:func:`_follows`), otherwise
the midpoint becomes a sample.

Adaptive samples (per side of stroke 0): the continuation passes 0, s_max/4, s_max/2, 3 s_max/4 and s_max, with
samples at 0, s_max/2 and s_max and, unless the first parasitic frequency at s_max/2 is within ``SMOOTH`` of
its value at 0, at s_max/4 too, and at s_max/8 where the frequency at s_max/4 is not within ``STEEP``
of its value at 0 (:meth:`_Side.initial`); then bisect
every interval whose error estimate exceeds the tolerance (relative, on the first parasitic frequency,
the quantity the tolerance is about), down to intervals of s_max/64 or the sample budget. The estimate (:func:`_error`)
compares the interpolant in ``1 / lambda`` with one in the frequency and with the quintic through a
neighbouring sample, all built from the same samples: no extra solve. It is cautious where the branch is
far from its asymptotic form (14 to 140 times the true error near stroke 0 of the hinges) and where a
crossing may hide between the samples, so an interval it rejects is first *probed*: the exact equilibrium
and eigenpairs at its midpoint, the sample a bisection would add, without the slopes (:meth:`_Side.probe`).
The interval is kept with ``PROBE_FACTOR`` times the interpolant's error there as its estimate when that
meets the tolerance (and the estimate from the samples is below ``PROBE_GATE``); otherwise the probe gets its
slopes and becomes the sample. The two halves of the stroke, when the quarter points are not samples, are
probed there whatever their estimate (the samples alone are too far apart to judge them), and so is the
second half when only the first half has its quarter point as a sample. The estimated error of the
curve is the largest remaining interval estimate. With ``fill`` (the ``auto`` method) the requested points
inside intervals that still miss the tolerance when the samples stop are computed exactly instead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..analysis import MeshAnalysis
from ..errors import FlexoptError
from ..modal import Modes, assign, mac_matrix, modes_at
from ..rotations import skew
from ..statics import Equilibrium, StepFailure, path_curvature, solve_point, walk
from ..symmetry import image_indices, one_side
from .common import CLUSTER_GAP, _curve_from
from .taylor import _multiple, _projected_mass_slope

__all__ = ["hermite_curve", "stroke_slopes", "HermiteResult"]

#: Relative gap below which eigenvalues are one degenerate cluster for the slopes. Nelson's formula is exact
#: for every simple eigenvalue, however close its neighbour; only (numerically) repeated ones -- symmetric
#: pairs, gap at rounding level -- need the cluster matrix. (The Taylor methods use the wider CLUSTER_GAP
#: because their expansions divide by the gap; here nothing does.)
SLOPE_CLUSTER_GAP = 1e-6
#: A branch matched across an interval with a MAC below ``MAC_MIN`` has an uncertain identity (a crossing in
#: between); for a branch in a cluster of nearly equal eigenvalues, the MAC with the cluster's subspace
#: (``_Side.retrack``). An interval is refined while the lowest parasitic branch at either end is uncertain,
#: or while a cubic through an uncertain branch's exact value and slope at one end and any uncertain
#: branch's at the other comes within ``CROSS_MARGIN`` of the lowest certain branch (see :func:`_error`).
MAC_MIN, CROSS_MARGIN = 0.9, 0.1
#: An interval whose estimate from the samples misses the tolerance is first probed at its midpoint (exact
#: equilibrium and eigenpairs, no slopes: :meth:`_Side.probe`); its estimate is then ``PROBE_FACTOR`` times
#: the relative error of the interpolant there. The midpoint is where the cubic Hermite error kernel
#: ``(s - a)^2 (s - b)^2`` peaks; over the 90 intervals the refinement visited on the six templates at
#: tolerances 1e-2, 1e-3 and 1e-4 the largest error over an interval (exact on a 0.03 deg grid) was at most 2.2
#: times the midpoint's, but for one interval where the error changes sign near the midpoint (double cross
#: hinge, 3.8 times, at 5e-7). Such an error is what a probe does not see; every kept interval is checked
#: against exact in tests/test_hermite.py.
PROBE_FACTOR = 2.5
#: A probe is trusted only where the samples' own comparison interpolants agree within this (finite estimate):
#: beyond it the branch is far from a cubic over the interval and the error can change sign at the midpoint.
#: Measured: the three intervals where the error over the interval was 6 to 104 times the midpoint's (the
#: pivot's and the three-fold's [0, s/2], sampled at 0, s/2 and s) had estimates of 0.45 to 0.48; the
#: intervals kept on a probe on the six templates at 1e-2/1e-3/1e-4 read 0.06 or less at the end.
PROBE_GATE = 0.1
#: The pair form (:func:`_pair_forms`) applies where the lowest two parasitic frequencies are within this factor
#: of each other at one end of the interval at least: a veering needs the two close (the double cross hinge's
#: lowest two: 1.09 to 1.51 across its veering). Farther apart (the leaf's: 2.8 to 2.9) a MAC below ``MAC_MIN``
#: is the lowest mode's own change of shape, which its single branch follows, checked by a probe as before.
PAIR_RATIO = 1.6
#: Where the lowest parasitic branch keeps its place but its shape turns across an interval (its MAC with itself
#: below this) while the lowest two parasitic modes span the same subspace at both ends, the two are in or near a
#: veering: they are interpolated as a pair (:func:`_pair_forms`) and compared with the single branches.
VEER_MAC = 0.98
#: The initial samples (:meth:`_Side.initial`) skip the quarter points where the first parasitic frequency at
#: half the stroke differs from its value at 0 by at most this (leaf 7 %, guide 0.03 %, double cross 0.4 %;
#: pivot, cartwheel and three-fold 71 to 83 %).
SMOOTH = 0.2
#: Where the quarter points are samples, the eighth point s_max/8 is one too when the first parasitic frequency
#: at s_max/4 differs from its value at 0 by more than this (pivot 68 %, three-fold cross hinge 66 to 69 %: their
#: first interval needs it at 1 %, and a sample placed now saves a round of refinement; cartwheel 50 %: its
#: first quarter meets 1 % as it is).
STEEP = 0.6


@dataclass
class _Sample:
    s: float  # internal stroke
    eq: Equilibrium
    modes: Modes  # k eigenpairs, ascending at this sample (not yet tracked)
    slope: np.ndarray | None  # (k,) d lambda / ds of those modes (None: a probe's, :meth:`_Side.probe`)
    labels: list[str] | None = None  # labels of ``modes`` in their order here (computed once, by retrack)
    filled: bool = False  # an exact point of the curve filled into an interval (no slope: never interpolated)


@dataclass
class HermiteResult:
    """Interpolated branches at the requested strokes plus the bookkeeping the caller reports."""

    hz: np.ndarray  # (p, n_rep) tracked branches [Hz]
    labels: np.ndarray  # (p, n_rep)
    parasitic: np.ndarray  # (p,)
    estimate: float  # estimated max relative error of the first parasitic frequency
    samples: int  # exact samples used (stroke 0 included)
    converged: bool  # every interval's estimate met the tolerance
    mirrored: str | None = None  # the symmetry that gave the negative strokes (None: both sides sampled)
    filled: int = 0  # requested points computed exactly in intervals that missed the tolerance (``fill``)


def stroke_slopes(an: MeshAnalysis, eq: Equilibrium, modes: Modes) -> np.ndarray:
    """Exact ``d lambda_i / ds`` of the eigenpairs ``modes`` at the equilibrium ``eq`` (see module docstring).

    With ``K1 = D3L[t]`` (reference chart of ``eq``), the chart change of :func:`_to_reference_chart` to
    first order, ``K1' = K1 - (J1^T K + K J1) - g_e Gamma_e'``, is applied as bilinear forms on the modes
    (``J1 = 1/2 skew(t_rot)`` per master), so no n x n chart matrix is formed:
    ``Q = P^T K1 P - (K P)^T (J1 P) - (J1 P)^T (K P) - g_e P^T Gamma_e' P - lambda P^T M1 P``.
    """
    sys = an.system
    s = sys.s
    t = np.asarray(eq.tangent, dtype=float)
    K = eq.ev.H
    K1 = sys.hessian_derivative(eq.state, t)
    order = np.argsort(modes.omega2)  # clusters are runs of the ascending eigenvalues
    lam, P = modes.omega2[order], modes.phi[:, order]
    nm = len(s.master_names)
    tg = sys.to_global(t).reshape(nm, 6)[:, 3:]  # rotation part of the tangent per master (global)
    Pg = sys.to_global(P).reshape(nm, 6, -1)  # modes per master (global)
    # J1 P per master: the rotation rows 1/2 tg x w of each mode's rotation part w, the translation rows zero
    S = skew(tg)  # (nm, 3, 3): S @ w = tg x w
    JPg = np.zeros_like(Pg)
    JPg[:, 3:, :] = 0.5 * (S @ Pg[:, 3:, :])
    JP = sys.from_global(JPg.reshape(6 * nm, -1))
    KP = K @ P
    Q1 = P.T @ (K1 @ P)  # P^T sym(K1) P as sym(P^T K1 P): k x k work instead of n x n
    X = KP.T @ JP
    Q = 0.5 * (Q1 + Q1.T) - (X + X.T)
    if s.drive_kind == "rotation":
        # first-order BCH term of the chart change times the drive moment g_e (zero at stroke 0 only)
        e = np.asarray(s.drive_axis, dtype=float)
        e = e / np.linalg.norm(e)
        tr = tg[s.drive_master]
        G = float(tr @ e) / 6.0 * np.eye(3) - (np.outer(tr, e) + np.outer(e, tr)) / 12.0
        Pr = Pg[s.drive_master, 3:, :]
        Q -= float(eq.ev.g[sys.drive]) * (Pr.T @ G @ Pr)
    MP = _projected_mass_slope(sys, eq.state, S @ eq.state.R, P)
    out = np.diagonal(Q) - lam * np.diagonal(MP)  # Nelson's formula for every simple eigenvalue
    for c in _multiple(lam, SLOPE_CLUSTER_GAP):
        A = Q[np.ix_(c, c)] - float(np.mean(lam[c])) * MP[np.ix_(c, c)]
        out[c] = np.linalg.eigvalsh(0.5 * (A + A.T))  # ascending, to the ascending cluster members
    res = np.empty(len(lam))
    res[order] = out
    return res


def _hz(mu: np.ndarray) -> np.ndarray:
    """Frequencies [Hz] from the interpolated compliances ``mu = 1 / omega^2``."""
    return np.sign(mu) / np.sqrt(np.abs(mu)) / (2 * np.pi)


class _Side:
    """Samples on one side of stroke 0 and their tracked branches."""

    def __init__(
        self, an: MeshAnalysis, first: _Sample, k: int, drive: str, curvature: np.ndarray | None = None
    ) -> None:
        self.an, self.k, self.drive = an, k, drive
        self.samples = [first]
        self.lam = self.slope = np.zeros((0, k))
        self.labels: list[list[str]] = []
        self.mac: list[np.ndarray] = []  # per interval: each branch's MAC match across it (:meth:`retrack`)
        self.macs: list[np.ndarray] = []  # per interval: the MAC matrix of the branches at its two ends
        self.pairs: tuple | None = None  # the intervals in the pair form, decided by :func:`_errors`
        self.visited: dict[float, Equilibrium] = {}  # converged equilibria of the initial continuation
        self.curvature = curvature  # d2 xi/ds2 at stroke 0: the first step's predictor (statics.path_curvature)
        self._pairs: dict = {}  # (id(sample), id(next sample)) -> (their raw MAC matrix, the two samples)
        self._tracked: dict = {}  # (id(sample), id(previous), its permutation) -> what retrack derives
        self.checked: dict[tuple[float, float], float] = {}  # interval -> its estimate from a probe (:meth:`probe`)
        self.coarse: set[tuple[float, float]] = set()  # intervals probed whatever their estimate (:meth:`initial`)

    def at(self, s: float) -> _Sample:
        """The sample at stroke ``s`` (one of :meth:`strokes`)."""
        return next(x for x in self.samples if x.s == s)

    def estimates(self) -> dict[tuple[float, float], float]:
        """:func:`_errors` of every interval, keyed by its end strokes."""
        S = self.strokes()
        est = dict(zip(zip(S[:-1].tolist(), S[1:].tolist()), _errors(self).tolist()))
        for iv, e in self.checked.items():  # an interval probed at its midpoint: the probe's estimate
            if iv in est:
                est[iv] = e
        return est

    def sample(self, start: _Sample, s_new: float, end: _Sample | None = None, slopes: bool = True) -> _Sample:
        """The exact equilibrium, eigenpairs and slopes at ``s_new``, reached from the sample ``start``.

        Between two samples (``end`` given) Newton starts from the cubic Hermite interpolation of the state
        through both samples and their tangents (about two iterations); otherwise, or if that fails, the
        continuation walks from ``start`` with step control.
        """
        an = self.an
        sys = an.system
        # a stroke the initial continuation passed through (bisection and the halved steps both land on
        # binary fractions of the stroke, equal up to the rounding of their sums)
        eq = next((e for v, e in self.visited.items() if abs(v - s_new) <= 1e-12 * abs(s_new)), None)
        if eq is None and end is not None:
            h = end.s - start.s
            u = (s_new - start.s) / h
            delta = sys.difference(end.eq.state, start.eq.state)
            step = (
                (u * (1 - u) ** 2 * h) * start.eq.tangent
                + (u * u * (3 - 2 * u)) * delta
                + (u * u * (u - 1) * h) * end.eq.tangent
            )
            try:
                eq = solve_point(sys, sys.update(start.eq.state, step), s_new, an.options, start.s)
            except StepFailure:
                eq = None
        if eq is None:
            got: list[Equilibrium] = []

            def accept(e: Equilibrium) -> None:
                got.append(e)
                return None

            fail = walk(sys, np.array([s_new]), an.options, accept, start=start.eq)
            if fail is not None or not got:
                raise _Fallback(fail.message if fail is not None else "no equilibrium")
            eq = got[-1]
        modes = modes_at(sys, eq, self.k, self.drive, start.modes)
        if len(modes.omega2) == 0 or modes.omega2[0] <= 0:
            raise _Fallback("equilibrium unstable at a sample")
        return _Sample(s_new, eq, modes, stroke_slopes(an, eq, modes) if slopes else None)

    def probe(self, a_s: float, b_s: float) -> tuple[float, _Sample]:
        """The exact equilibrium and eigenpairs at the midpoint of the interval (a_s, b_s) without the slopes,
        and the interval's error estimate from them: ``PROBE_FACTOR`` times the relative difference of the
        interpolated first parasitic frequency from the exact one there (infinite where either has none).
        The midpoint is the sample a refinement would add, so a probe whose estimate misses the tolerance
        becomes that sample once its slopes are added (:meth:`promote`); nothing is computed twice.
        Infinite too where the lowest parasitic mode at either end is not, by its shape, the lowest at the
        midpoint (:func:`_follows`): a crossing, a veering or a mixing of the lowest with other modes inside the
        interval, where the error can peak away from the midpoint (butterfly-like double cross hinges: 0.1 % at
        31 deg, 10 times the midpoint's at 28 deg; 1.3 % at 27 deg where the midpoint 34 deg read 0.33 %), is
        sampled, not judged by one point."""
        i = next(j for j, x in enumerate(self.samples) if x.s == a_s)  # the interval [S_i, S_i+1]
        a, b = self.samples[i], self.samples[i + 1]
        smp = self.sample(a, 0.5 * (a_s + b_s), b, slopes=False)
        smp.labels = self.an.label_modes(smp.modes, smp.eq.tangent)[0]
        is_par = np.array(smp.labels) == "parasitic"
        at = np.array(self.labels[i]) == "parasitic"  # the labels of the nearer sample, as interpolate gives
        if not (is_par.any() and at.any()) or not (_follows(a, smp) and _follows(smp, b)):
            return np.inf, smp
        # the interpolant at the midpoint: cubic Hermite per branch, and the pair form where the estimate just
        # made chose it, the midpoint taking the branches of S_i (as its labels)
        j = np.array([i])
        basis = _basis(np.array([a_s]), np.array([b_s]), np.array([[smp.s]]))
        mu = _interpolate(basis, self.lam[j], self.lam[j + 1], self.slope[j], self.slope[j + 1])
        if self.pairs is not None and self.pairs[1][i]:
            _, _, ia, ib, V, W = self.pairs
            _put_pair(mu, np.array([0]), np.ones((1, 1), dtype=bool), ia[j], ib[j], *_pair_at(basis, V, W, j))
        exact = float(smp.modes.hz[is_par].min())
        interp = float(_hz(mu[0, 0])[at].min())
        return PROBE_FACTOR * abs(interp / exact - 1.0), smp

    def promote(self, smp: _Sample) -> None:
        """A probe's sample with its stroke slopes added joins the samples."""
        smp.slope = stroke_slopes(self.an, smp.eq, smp.modes)
        self.add(smp)

    def fill(self, a_s: float, b_s: float, s_req: np.ndarray) -> int:
        """Exact points at the requested strokes strictly inside the interval (a_s, b_s): the continuation
        walks from the sample at ``a_s`` through them (as the exact method does), each gets its eigenpairs and
        joins the samples, so the curve there is exact and nothing is interpolated. Returns their number."""
        an = self.an
        sys = an.system
        lo, hi = sorted((abs(a_s), abs(b_s)))
        pts = np.array(sorted((x for x in s_req if lo < abs(x) < hi), key=abs))
        if not len(pts):
            return 0
        left = self.at(a_s)
        last = [left.modes]  # the previous point's modes: where its eigen solve starts (modal.modes_at's near)

        def accept(e: Equilibrium) -> None:
            modes = last[0] = modes_at(sys, e, self.k, self.drive, last[0])
            if len(modes.omega2) == 0 or modes.omega2[0] <= 0:
                raise _Fallback("equilibrium unstable at a requested point")
            self.add(_Sample(float(e.stroke), e, modes, np.zeros(len(modes.omega2)), filled=True))
            return None

        fail = walk(sys, pts, an.options, accept, start=left.eq)
        if fail is not None:
            raise _Fallback(fail.message)
        return len(pts)

    def initial(self, smax: float) -> None:
        """Continuation from stroke 0 to ``smax`` through a quarter, half, three quarters and the end (the
        continuation halves a step that fails; from the second target on its predictor is the cubic through
        two converged points), with samples at the half and the end. Where the first parasitic frequency at
        the half is within ``SMOOTH`` of its value at 0 (a branch close to flat over the first half: the leaf,
        the guide, the double cross hinge), the quarter and three-quarter points stay equilibria only: the
        intervals [0, s/2] and [s/2, s] are then probed there (:meth:`probe`, no Newton solve: the
        continuation's) whatever their estimate. Otherwise (the pivot, the cartwheel and the three-fold cross
        hinge, whose frequency falls 3 to 6 times over the first half) s/4 becomes a sample too (the steep
        first half needs it) while [s/2, s] is probed at 3s/4 (kept on the three templates at 1 %), and so does
        s/8 where the frequency at s/4 is not within ``STEEP`` of its value at 0 (pivot, three-fold), reached
        by Newton from the cubic through the samples at 0 and s/4 (:meth:`sample`): the sample a refinement of
        [0, s/4] would add, one round earlier."""
        an = self.an
        sys = an.system
        first = self.samples[0]
        last = [first.modes]
        quarter: list[Equilibrium] = []  # the equilibrium at s/4, until the sample at s/2 decides
        flat = [False]
        f_zero = [float("nan")]  # the first parasitic frequency at stroke 0
        half = [0.0]  # the stroke of the sample at s/2

        def full(e: Equilibrium) -> _Sample:
            modes = last[0] = modes_at(sys, e, self.k, self.drive, last[0])
            if len(modes.omega2) == 0 or modes.omega2[0] <= 0:
                raise _Fallback("equilibrium unstable at a sample")
            smp = _Sample(float(e.stroke), e, modes, stroke_slopes(an, e, modes))
            self.add(smp)
            return smp

        def accept(e: Equilibrium) -> None:
            k = int(round(4 * float(e.stroke) / smax))  # 1..4: which quarter of the stroke
            if k == 1:
                quarter.append(e)
            elif k == 2:
                smp = full(e)
                half[0] = smp.s
                smp.labels, f_half = an.label_modes(smp.modes, e.tangent)
                first.labels, f_zero[0] = an.label_modes(first.modes, first.eq.tangent)  # retrack reuses the labels
                flat[0] = bool(abs(f_half / f_zero[0] - 1) <= SMOOTH)  # False when either is NaN (no parasitic)
                if flat[0]:
                    self.coarse = {(0.0, float(e.stroke)), (float(e.stroke), float(smax))}
                else:
                    full(quarter[0])
            elif k == 3:
                if not flat[0]:  # the second half probed at 3s/4 (its first half has s/4 as a sample)
                    self.coarse.add((half[0], float(smax)))
            else:
                full(e)
            return None

        def seen(e: Equilibrium) -> None:
            self.visited[float(e.stroke)] = e

        fail = walk(
            sys,
            np.linspace(0.0, smax, 5)[1:],
            an.options,
            accept,
            start=first.eq,
            on_step=seen,
            curvature=self.curvature,
        )
        if fail is not None:
            raise _Fallback(fail.message)
        if not flat[0]:
            q = self.at(float(quarter[0].stroke))
            q.labels, f_quarter = an.label_modes(q.modes, q.eq.tangent)  # retrack reuses the labels
            if not abs(f_quarter / f_zero[0] - 1) <= STEEP:  # also where either is NaN (no parasitic mode)
                self.add(self.sample(first, 0.5 * q.s, q))  # Newton from the cubic through 0 and s/4

    def add(self, smp: _Sample) -> None:
        self.samples.append(smp)
        self.samples.sort(key=lambda x: abs(x.s))

    def retrack(self) -> None:
        """Branch identities from stroke 0 outwards through every sample (MAC, as the exact method).

        The MAC matrix of two neighbouring samples' modes is computed once per pair (``_pairs``) and read
        through the previous sample's permutation: the tracking (:func:`model.modal.track`) permutes with
        its input, so this equals tracking the permuted modes. Each sample's tracked data depend only on the
        pair and the previous sample's permutation, so they are kept under that key (``_tracked``): a new
        sample recomputes only the samples whose predecessor or its permutation changed."""
        prev_groups: list[np.ndarray] = []  # read from the second sample on
        prev_perm: np.ndarray | None = None
        prev_smp: _Sample | None = None
        lam, slope, labels, mac, macs = [], [], [], [], []
        for smp in self.samples:
            m = smp.modes
            key = (id(smp), id(prev_smp), None if prev_perm is None else prev_perm.tobytes())
            hit = self._tracked.get(key)
            if hit is None:
                match = full = None
                if prev_smp is None:
                    perm = np.arange(len(m.omega2))
                else:
                    pair = (id(prev_smp), id(smp))
                    raw = self._pairs.get(pair)
                    if raw is None:
                        raw = self._pairs[pair] = (mac_matrix(prev_smp.modes, m), prev_smp, smp)
                    rows = raw[0][prev_perm]  # (previous branch, current raw mode)
                    perm = assign(rows)
                    # MAC of each branch's match across the interval (1: same shape): a branch in a cluster of
                    # nearly equal eigenvalues at the previous sample (relative gap CLUSTER_GAP, as the modal
                    # derivatives) is matched by its shape's share in the cluster's subspace: inside a cluster
                    # the individual shapes are arbitrary mixtures that rotate freely as the eigenvalues split
                    # (the pivot's mirror-leaf pairs at stroke 0: single-mode MAC 0.46 however short the
                    # interval), so only the subspace tells a crossing from a rotation
                    full = rows[:, perm]  # (previous branch, current branch)
                    match = np.diag(full).copy()
                    for idx in prev_groups:
                        match[idx] = full[np.ix_(idx, idx)].sum(axis=0)
                w2 = m.omega2[perm]
                order = np.argsort(w2)
                groups = [order[c] for c in _multiple(w2[order], CLUSTER_GAP)]  # this sample's clusters (branches)
                # labels as the exact method gives them: with the drive free, the drive mode is the one most
                # like the equilibrium path's tangent; a label belongs to a mode, so it is computed once per
                # sample and follows the mode through the permutation
                if smp.labels is None:
                    smp.labels = self.an.label_modes(m, smp.eq.tangent)[0]
                assert smp.slope is not None  # a probe joins the samples with its slopes (promote)
                # interpolated variable: mu = 1 / lambda (see module docstring), and its slope
                hit = self._tracked[key] = (
                    perm,
                    groups,
                    1.0 / w2,
                    -smp.slope[perm] / w2**2,
                    [smp.labels[j] for j in perm],
                    match,
                    full,
                )
            perm, groups, mu, dmu, lab, match, full = hit
            if match is not None and full is not None:  # both from the second sample on
                mac.append(match)
                macs.append(full)
            lam.append(mu)
            slope.append(dmu)
            labels.append(lab)
            prev_groups, prev_perm, prev_smp = groups, perm, smp
        self.lam, self.slope, self.labels, self.mac, self.macs = np.array(lam), np.array(slope), labels, mac, macs

    def strokes(self) -> np.ndarray:
        return np.array([x.s for x in self.samples])

    def interpolate(self, s: np.ndarray) -> tuple[np.ndarray, list[list[str]]]:
        """Interpolated eigenvalues (p, k) at strokes ``s`` of this side, with the labels of the nearer sample."""
        S = self.strokes()
        a = np.abs(S)
        idx = np.clip(np.searchsorted(a, np.abs(s), side="right") - 1, 0, len(S) - 2)
        s = np.asarray(s, dtype=float)
        out = self.evaluate(idx, s[:, None])[:, 0, :]  # each point as the one interior point of its own interval
        near = np.where(np.abs(s - S[idx]) <= np.abs(S[idx + 1] - s), idx, idx + 1)
        return out, [self.labels[j] for j in near]

    def evaluate(self, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The interpolated ``mu`` (n, p, k) of the branches at the points ``x`` (n, p) of the intervals ``idx``
        (n,): cubic Hermite per branch, and the pair form where :func:`_errors` chose it (:func:`_pair_forms`)."""
        S = self.strokes()
        if self.pairs is None or self.pairs[0] != S.tobytes():
            _errors(self)  # decides the forms for these samples
        assert self.pairs is not None  # _errors has set them
        a, b = S[idx], S[idx + 1]
        basis = _basis(a, b, x)
        mu, d = self.lam, self.slope
        A = _interpolate(basis, mu[idx], mu[idx + 1], d[idx], d[idx + 1])
        use, ia, ib, V, W = self.pairs[1:]
        if use[idx].any():
            R = np.flatnonzero(use[idx])
            j = idx[R]
            ja, jb = ia[j], ib[j]
            m1, m2 = _pair_at(tuple(c[R] for c in basis), V, W, j)
            left = np.abs(x[R] - a[R][:, None]) <= np.abs(b[R][:, None] - x[R])
            _put_pair(A, R, left, ja, jb, m1, m2)
        return A


def _lowest_parasitic(smp: _Sample) -> int | None:
    """The index (in ``smp.modes``' own order) of the sample's lowest parasitic mode, None if it has none."""
    par = np.flatnonzero(np.array(smp.labels) == "parasitic")
    return int(par[np.argmin(smp.modes.omega2[par])]) if len(par) else None


def _follows(p: _Sample, q: _Sample) -> bool:
    """Whether the lowest parasitic mode of ``p`` is, by its shape, the lowest parasitic mode of ``q`` and the
    other way round: a MAC of at least ``MAC_MIN`` between the two, or with the subspace of a cluster of nearly
    equal eigenvalues holding the other (``CLUSTER_GAP``, whose single shapes are arbitrary mixtures:
    :meth:`_Side.retrack`). False across a crossing, a veering or a mixing of the lowest with another mode."""
    lp, lq = _lowest_parasitic(p), _lowest_parasitic(q)
    if lp is None or lq is None:
        return lp is None and lq is None
    F = mac_matrix(p.modes, q.modes)  # (mode at p, mode at q)
    return (
        _cluster_share(F[lp], q.modes.omega2, lq) >= MAC_MIN and _cluster_share(F[:, lq], p.modes.omega2, lp) >= MAC_MIN
    )


def _cluster_share(row: np.ndarray, lam: np.ndarray, j: int) -> float:
    """``row[j]``, or the sum of ``row`` over the cluster of nearly equal eigenvalues ``lam`` holding ``j``."""
    order = np.argsort(lam)
    for c in _multiple(lam[order], CLUSTER_GAP):
        if j in order[c]:
            return float(row[order[c]].sum())
    return float(row[j])


class _Fallback(Exception):
    """The samples cannot be computed (loss of equilibrium, instability): the caller uses the exact method."""


_INTERIOR = np.arange(1, 17, dtype=float)  # the 16 interior points of an interval in units of its 17th


def _errors(side: _Side) -> np.ndarray:
    """Estimated error of the interpolated first parasitic frequency over each interval [S_i, S_i+1] (I,).

    The reported interpolant (cubic Hermite in ``mu = 1 / lambda``, or the pair form) is compared on 16
    interior points with others built from the same exact data, and the largest relative difference of the
    first parasitic frequency is the estimate (no extra exact solve):

    - the cubic Hermite interpolant in ``1 / sqrt(mu)`` (the frequency up to 2 pi): a different fourth
      derivative, so the two disagree where the branch changes faster than a cubic can follow
      (pre-asymptotic sampling);
    - the quintic through the values and slopes at this interval's samples and at a neighbouring sample's
      (either side, where its match of the lowest branch is certain): the next order of the same data,
      whose difference from the cubic is the cubic's leading error term. The first comparison alone reads
      almost nothing on a nearly flat branch, where the two forms are nearly affine images of each other
      (double cross hinge before its veering: estimate 7e-5, true error 4.4e-4); the second alone
      understates the pre-asymptotic intervals (pivot at 1 %: 3e-3 against 1.5e-2). Where no neighbour
      supports a quintic and the lowest two parasitic modes form a closed pair (:func:`_pair_forms`), the
      pair form is compared instead (the double cross's last interval, after its veering: 7.2e-5 from the
      first comparison, true error 1.3e-4, pair form 1.7e-4).
    - on an interval in the pair form (single branches uncertain, the pair closed), the pair form in ``mu``
      against the same in ``r``.

    Their maximum, measured on the six templates at tolerances 1e-2, 1e-3 and 1e-4, is at least the curve's
    true error in all 18 cases (1.8 to 25 times; tests/test_hermite.py checks half of it at 1e-3). An
    interval this estimate rejects is probed (:meth:`_Side.probe`) before it is halved.

    Infinite (refine) when a mode crossing inside the interval may change the first parasitic frequency
    and the pair form does not apply: the lowest parasitic branch at either end was matched with a MAC below
    ``MAC_MIN``, or a branch with an uncertain match could reach it (in the pair form: a branch outside the
    pair). Where the match of a branch is uncertain, its true continuation is one of the uncertain modes at
    the other end; each such pairing is a cubic through exact values and exact
    slopes (a slope belongs to a mode, not to its tracking), and the interval is refined when any of these
    cubics comes within ``CROSS_MARGIN`` (10 %: well above the interpolation errors that are refined away
    anyway) of the lowest parasitic frequency of the certain branches. Uncertain branches that stay clear
    of it cannot change the first parasitic frequency (they can change the higher tracked modes between
    the samples, which the tolerance is not about). A crossing and back between two samples (a dip of a
    higher branch that no pairing of the end values shows) is not detected by this or any estimate from
    the samples alone.

    All intervals are evaluated at once (arrays over intervals, points and branches: the same elementwise
    arithmetic as one interval at a time, at the cost of about one).
    """
    S = side.strokes()
    n_iv = len(S) - 1
    if n_iv <= 0:
        side.pairs = _no_pairs(S)
        return np.zeros(max(n_iv, 0))
    fr = _frame(side, S)
    inf, unc = _uncertain(fr)
    quintic = _quintic_sides(fr)
    exact_iv = fr.filled[:-1] | fr.filled[1:]
    lone = ~inf & ~exact_iv & ~(quintic[0] | quintic[1])  # single branches with no quintic comparison
    # the pair form (:func:`_pair_forms`) where the single branches are uncertain but the two lowest parasitic
    # modes span the same subspace at both ends (a veering or a crossing between them); on the lone intervals
    # where the pair is closed, the pair form is the second comparison instead of the quintic
    # a swap: the lowest parasitic branch at S_i is not the lowest at S_i+1 (by their shapes the two lowest
    # cross in between), a crossing or a veering, which the end samples cannot tell apart (both exchange the
    # shapes); the pair form is exact for either in a 2 x 2 model, and the branches read as a crossing are its
    # comparison (their difference is what a veering would change: :func:`_compare`)
    turn = np.asarray(side.mac, dtype=float)[np.arange(n_iv), fr.low[:-1]] < VEER_MAC  # the lowest's shape turns
    swap = fr.has[:-1] & fr.has[1:] & ((fr.low[:-1] != fr.low[1:]) | turn) & ~inf & ~exact_iv
    key, closed, ia, ib, V, W = _pair_forms(S, fr.mu, fr.d, fr.P, side.macs, (inf | lone | swap) & ~exact_iv)
    side.pairs = (key, closed & (inf | swap), ia, ib, V, W)  # the intervals interpolated in the pair form
    cross = np.flatnonzero(closed & swap)
    crossing = (cross, fr.A[cross].copy())  # the single branches, before the pair form is written in
    in_r = _apply_pairs(fr, side.pairs, inf, unc)
    est = _compare(fr, side.pairs, quintic, closed & lone & ~swap, in_r, crossing)
    out = np.where(inf, np.inf, est)
    out[exact_iv] = 0.0  # every requested point of the interval is an exact sample
    return out


@dataclass
class _Frame:
    """What :func:`_errors` compares, over the I intervals of one side, each at its 16 interior points."""

    S: np.ndarray  # (I + 1,) the samples' strokes
    mu: np.ndarray  # (I + 1, k) the tracked branches' 1 / lambda at the samples
    d: np.ndarray  # (I + 1, k) their stroke slopes
    P: np.ndarray  # (I + 1, k) parasitic labels
    sure: np.ndarray  # (I, k) branch matched with certainty across interval i (MAC >= MAC_MIN)
    filled: np.ndarray  # (I + 1,) the sample is an exact point filled in (no slope)
    x: np.ndarray  # (I, 16) interior points
    basis: tuple  # :func:`_basis` of the intervals at x
    left: np.ndarray  # (I, 16) the point is nearer S_i than S_i+1
    par: np.ndarray  # (I, 16, k) labels of the nearer sample
    low: np.ndarray  # (I + 1,) each sample's lowest parasitic branch (0 if none)
    has: np.ndarray  # (I + 1,) the sample has a parasitic branch
    A: np.ndarray  # (I, 16, k) the reported interpolant in mu (the pair form written in by _apply_pairs)
    hz_a: np.ndarray  # (I, 16, k) its frequencies


def _frame(side: _Side, S: np.ndarray) -> _Frame:
    """The samples' data of ``side`` and the cubic Hermite interpolant in mu on every interval (:class:`_Frame`)."""
    mu, d = np.asarray(side.lam, dtype=float), np.asarray(side.slope, dtype=float)  # (samples, k)
    P = np.array(side.labels) == "parasitic"  # (samples, k)
    a_, b_ = S[:-1], S[1:]
    # (I, 16) interior points: numpy.linspace(a, b, 18)[1:-1] of each interval, written out (its checks cost
    # more than the rest of this estimate)
    x = _INTERIOR[None, :] * ((b_ - a_) / 17)[:, None] + a_[:, None]
    basis = _basis(a_, b_, x)
    A = _interpolate(basis, mu[:-1], mu[1:], d[:-1], d[1:])  # (I, 16, k)
    left = np.abs(x - a_[:, None]) <= np.abs(b_[:, None] - x)
    return _Frame(
        S=S,
        mu=mu,
        d=d,
        P=P,
        sure=np.asarray(side.mac, dtype=float) >= MAC_MIN,
        filled=np.array([x.filled for x in side.samples]),
        x=x,
        basis=basis,
        left=left,
        par=np.where(left[:, :, None], P[:-1, None, :], P[1:, None, :]),
        low=np.where(P, _hz(mu), np.inf).argmin(axis=1),
        has=P.any(axis=1),
        A=A,
        hz_a=_hz(A),
    )


def _uncertain(fr: _Frame) -> tuple[np.ndarray, np.ndarray]:
    """The intervals where a crossing may change the first parasitic frequency (I,) (see :func:`_errors`), and
    the branches uncertain across each interval (I, k)."""
    idx = np.arange(len(fr.S) - 1)
    sure, low, has, P = fr.sure, fr.low, fr.has, fr.P
    inf = (has[:-1] & ~sure[idx, low[:-1]]) | (has[1:] & ~sure[idx, low[1:]])
    # a crossing of uncertain branches that may reach the lowest certain one: every pairing (j at S_i, l at
    # S_i+1) of the branches uncertain across the interval, all intervals and pairings at once
    either = P[:-1] | P[1:]
    unc = ~sure & either
    check = unc & ~inf[:, None]  # an interval already uncertain in its lowest branch needs no crossing check
    if check.any():
        lowest = np.where((sure & either)[:, None, :], fr.hz_a, np.inf).min(axis=2)
        inf |= np.any(_crossings(fr.basis, fr.mu, fr.d, check) < (1 + CROSS_MARGIN) * lowest, axis=1)
    return inf, unc


def _quintic_sides(fr: _Frame) -> list[np.ndarray]:
    """The intervals (I,) with a certain neighbour sample on the left and on the right, through which the
    quintic comparison of :func:`_compare` is built."""
    n_iv = len(fr.S) - 1
    idx = np.arange(n_iv)
    quintic = []
    for shift in (-1, 2):
        nb = idx + shift
        between = idx - 1 if shift < 0 else idx + 1
        ok = (nb >= 0) & (nb <= n_iv)
        ok[ok] &= ~fr.filled[nb[ok]] & fr.sure[between[ok], fr.low[:-1][ok]]
        quintic.append(ok)
    return quintic


def _apply_pairs(fr: _Frame, pairs: tuple, inf: np.ndarray, unc: np.ndarray) -> tuple:
    """Writes the pair form into ``fr.A`` and ``fr.hz_a`` on the intervals ``pairs`` puts in it (uncertain,
    their pair closed), which are then infinite only where a branch outside the pair with an uncertain match comes near
    the pair's lowest frequency (``inf`` updated in place). Returns (those intervals, their pair branches at
    both ends, the pair form in r) for the second comparison."""
    _, use, ia, ib, V, W = pairs
    R = np.flatnonzero(use)
    if not len(R):
        return R, None, None, None, None
    bR = tuple(c[R] for c in fr.basis)
    aR, bRr = ia[R], ib[R]
    m1, m2, r1, r2 = _pair_at(bR, V, W, R, in_r=True)
    _put_pair(fr.A, R, fr.left[R], aR, bRr, m1, m2)
    fr.hz_a[R] = _hz(fr.A[R])
    # branches outside the pair whose match is uncertain must stay clear of the pair's lowest frequency
    out_unc = unc[R]
    rr = np.arange(len(R))[:, None]
    out_unc[rr, aR] = False
    out_unc[rr, bRr] = False
    near = np.zeros(len(R), dtype=bool)
    if out_unc.any():
        near = np.any(_crossings(bR, fr.mu, fr.d, out_unc, R) < (1 + CROSS_MARGIN) * _hz(m1), axis=1)
    inf[R] = near
    return R, aR, bRr, r1, r2


def _compare(
    fr: _Frame, pairs: tuple, quintic: list[np.ndarray], cmp: np.ndarray, in_r: tuple, crossing: tuple
) -> np.ndarray:
    """The largest relative difference (I,) of the reported interpolant's first parasitic frequency from the
    comparison interpolants of :func:`_errors` (in r, the quintic, the pair form on ``cmp``), over the interior
    points; ``in_r``: what :func:`_apply_pairs` returns; ``crossing``: the swapped intervals and their single
    branches (I_c, 16, k)."""
    n_iv = len(fr.S) - 1
    idx = np.arange(n_iv)
    mu, d, basis = fr.mu, fr.d, fr.basis
    _, _, ia, ib, V, W = pairs
    R, aR, bRr, r1, r2 = in_r
    fa = np.where(fr.par, fr.hz_a, np.inf).min(axis=2)
    # second interpolant in r = mu^(-1/2) (proportional to the frequency): dr/ds = -mu'/(2 mu^(3/2))
    r = mu**-0.5
    dr = -0.5 * d * r**3
    Br = _interpolate(basis, r[:-1], r[1:], dr[:-1], dr[1:]) ** -2.0
    if len(R):  # the pair form in r as well
        _put_pair(Br, R, fr.left[R], aR, bRr, r1, r2)
    others = [Br]
    rows = [idx]
    # third: the quintic through this interval's samples and a neighbour's (values and slopes at three
    # strokes), the next order of the same data: the left neighbour (through interval i - 1) and the right
    # one (through interval i + 1), where it is a sample and its match of the lowest branch is certain (not
    # for the pair form, whose branches are not matched one by one)
    in_pair = np.zeros(n_iv, dtype=bool)
    in_pair[R] = True
    ivs, nbs = [], []
    for shift, ok in zip((-1, 2), quintic):
        ok = ok & ~in_pair
        ivs.append(idx[ok])
        nbs.append(idx[ok] + shift)
    iv = np.concatenate(ivs)
    if len(iv):
        others.append(_quintic_all(fr.S, mu, d, iv, np.concatenate(nbs), fr.x[iv], fr.A[iv]))
        rows.append(iv)
    if len(crossing[0]):  # the pair form against the single branches read as a crossing (a swap)
        others.append(crossing[1])
        rows.append(crossing[0])
    C = np.flatnonzero(cmp)
    if len(C):  # the pair form against the single branches where no quintic is built
        m1, m2 = _pair_at(tuple(c[C] for c in basis), V, W, C)
        Ac = fr.A[C]
        _put_pair(Ac, np.arange(len(C)), fr.left[C], ia[C], ib[C], m1, m2)
        others.append(Ac)
        rows.append(C)
    at = np.concatenate(rows)
    fb = np.where(fr.par[at], _hz(np.concatenate(others)), np.inf).min(axis=2)
    f = fa[at]
    ok = np.isfinite(f) & np.isfinite(fb)
    rel = np.abs(np.divide(f, fb, out=np.ones_like(f), where=ok) - 1).max(axis=1)
    est = np.zeros(n_iv)
    np.maximum.at(est, at, rel)
    return est


def _crossings(
    basis: tuple, mu: np.ndarray, d: np.ndarray, unc: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray:
    """The lowest frequency (I, p) of the cubics through every pairing (j at S_i, l at S_i+1) of the branches
    ``unc`` (I, k) marks uncertain across each interval (``rows``: the intervals, all by default); inf where
    an interval has no such pairing. Only the pairings that exist are evaluated (a few per interval)."""
    n_iv, p = basis[0].shape[:2]
    out = np.full((n_iv, p), np.inf)
    some = np.flatnonzero(unc.any(axis=0))  # the branches uncertain somewhere
    j, l = np.repeat(some, len(some)), np.tile(some, len(some))
    ri, ci = np.nonzero(unc[:, j] & unc[:, l])  # (interval, pairing) of every pairing of uncertain branches
    if not len(ri):
        return out
    jj, ll = j[ci], l[ci]
    g = ri if rows is None else rows[ri]  # the intervals' indices into the samples
    b = tuple(c[ri] for c in basis)
    cand = _hz(_interpolate(b, mu[g, jj][:, None], mu[g + 1, ll][:, None], d[g, jj][:, None], d[g + 1, ll][:, None]))
    first = np.flatnonzero(np.r_[True, ri[1:] != ri[:-1]])  # ri is sorted: each interval's run of pairings
    out[ri[first]] = np.minimum.reduceat(cand[..., 0], first, axis=0)
    return out


def _no_pairs(S: np.ndarray) -> tuple:
    n = max(len(S) - 1, 0)
    none = np.zeros((n, 2), dtype=int)
    return S.tobytes(), np.zeros(n, dtype=bool), none, none, None, None


def _pair_forms(S: np.ndarray, mu: np.ndarray, d: np.ndarray, P: np.ndarray, macs: list, want: np.ndarray) -> tuple:
    """Which intervals take the pair form: among ``want`` (I,), those where both ends have two parasitic
    branches and the two lowest at S_i (``ia``, branches, lowest first) and at S_i+1 (``ib``) span the same
    subspace: every mode of either pair has a MAC share of at least ``MAC_MIN`` in the other pair (the sum of
    its MACs with the other pair's modes; 1 for a mode inside the other pair's span, mass-normalised modes),
    and their frequencies are within ``PAIR_RATIO`` of each other at one end at least.

    The pair form: two branches whose shapes mix between the samples (a veering, or a crossing the MAC cannot
    follow) are interpolated through their symmetric functions ``T = mu_1 + mu_2`` and ``D = (mu_1 -
    mu_2)^2``, each a cubic Hermite interpolant (:func:`_pair_roots`: ``mu_1,2 = (T +- sqrt(D)) / 2``). ``T``
    and ``D`` are smooth however the two exchange their shapes: for a 2 x 2 compliance ``C(s)`` linear in
    the stroke, ``T`` is linear and ``D`` quadratic, so the form is exact, where either branch alone turns
    sharply at the veering. The pair at each sample is its two lowest parasitic modes, so ``T`` and ``D`` are
    data of the sample: ``V`` (samples, 4) holds ``T``, ``D`` and the same in ``r = mu^(-1/2)`` (the second
    interpolant of the estimate), ``W`` their stroke slopes.

    Returns (the strokes it was decided for, use (I,), ia (I, 2), ib (I, 2), V, W)."""
    m = np.where(P, mu, -np.inf)
    two = np.argsort(-m, axis=1, kind="stable")[:, :2]  # largest mu first: the lowest frequency
    ia, ib = two[:-1], two[1:]
    use = np.zeros(len(want), dtype=bool)
    if m.shape[1] < 2 or not want.any():
        return S.tobytes(), use, ia, ib, None, None
    both = P.sum(axis=1) >= 2  # two parasitic branches at the sample
    rows = np.arange(len(m))[:, None]
    y = mu[rows, two]  # (samples, 2): mu of the lowest two parasitic modes, the larger first
    near = y[:, 0] <= PAIR_RATIO**2 * y[:, 1]  # their frequencies within PAIR_RATIO of each other
    for i in np.flatnonzero(want & both[:-1] & both[1:] & (near[:-1] | near[1:])).tolist():
        F = macs[i]  # (branch at S_i, branch at S_i+1)
        (a0, a1), (b0, b1) = ia[i].tolist(), ib[i].tolist()
        s00, s01, s10, s11 = float(F[a0, b0]), float(F[a0, b1]), float(F[a1, b0]), float(F[a1, b1])
        use[i] = min(s00 + s10, s01 + s11, s00 + s01, s10 + s11) >= MAC_MIN
    if not use.any():
        return S.tobytes(), use, ia, ib, None, None
    dy = d[rows, two]
    r = y**-0.5
    dr = -0.5 * dy * r**3
    g, gr = y[:, 0] - y[:, 1], r[:, 0] - r[:, 1]
    V, W = np.empty((len(m), 4)), np.empty((len(m), 4))
    V[:, 0], V[:, 1], V[:, 2], V[:, 3] = y[:, 0] + y[:, 1], g * g, r[:, 0] + r[:, 1], gr * gr
    W[:, 0], W[:, 1] = dy[:, 0] + dy[:, 1], 2 * g * (dy[:, 0] - dy[:, 1])
    W[:, 2], W[:, 3] = dr[:, 0] + dr[:, 1], 2 * gr * (dr[:, 0] - dr[:, 1])
    return S.tobytes(), use, ia, ib, V, W


def _pair_at(basis: tuple, V: np.ndarray, W: np.ndarray, j: np.ndarray, in_r: bool = False) -> tuple:
    """The pair form on the intervals ``j`` (their :func:`_basis` rows ``basis``) from the samples' ``V``, ``W``
    of :func:`_pair_forms`: mu_1, mu_2 (R, p), and with ``in_r`` the same from the form in r after them."""
    c = 4 if in_r else 2
    return _pair_roots(_interpolate(basis, V[j, :c], V[j + 1, :c], W[j, :c], W[j + 1, :c]))


def _pair_roots(V: np.ndarray) -> tuple[np.ndarray, ...]:
    """mu_1 >= mu_2 (the lower frequency first) of the pair form from the interpolated ``T``, ``D`` (V[..., 0:2])
    and, where V has them, the same from the form in r (V[..., 2:4])."""
    root = np.sqrt(np.maximum(V[..., 1::2], 0.0))
    hi, lo = 0.5 * (V[..., 0::2] + root), 0.5 * (V[..., 0::2] - root)
    if V.shape[-1] == 2:
        return hi[..., 0], lo[..., 0]
    # in r the smaller root is the lower frequency
    return hi[..., 0], lo[..., 0], np.maximum(lo[..., 1], 1e-300) ** -2.0, np.maximum(hi[..., 1], 1e-300) ** -2.0


def _put_pair(
    A: np.ndarray, R: np.ndarray, left: np.ndarray, ia: np.ndarray, ib: np.ndarray, m1: np.ndarray, m2: np.ndarray
) -> None:
    """Writes the pair form into the pair's branches of the intervals ``R`` of ``A`` (I, p, k): at each point
    the lowest branch of the nearer sample takes ``m1`` (the lower frequency) and its second ``m2``
    (``left`` (R, p): the point is nearer S_i)."""
    r = R[:, None]
    p = np.arange(A.shape[1])[None, :]
    A[r, p, np.where(left, ia[:, 0:1], ib[:, 0:1])] = m1
    A[r, p, np.where(left, ia[:, 1:2], ib[:, 1:2])] = m2


def _error(side: _Side, i: int) -> float:
    """:func:`_errors` of the interval [S_i, S_i+1]."""
    return float(_errors(side)[i])


def _basis(s0: np.ndarray, s1: np.ndarray, s: np.ndarray) -> tuple:
    """The cubic Hermite basis on every interval at once: ends ``s0``, ``s1`` (I,), points ``s`` (I, p); the
    four basis functions (I, p, 1) of ``u = (s - s0) / (s1 - s0)`` -- ``(1 + 2u)(1 - u)^2``, ``u (1 - u)^2``,
    ``u^2 (3 - 2u)``, ``u^2 (u - 1)`` -- and the lengths (I, 1, 1)."""
    h = (s1 - s0)[:, None, None]
    u = ((s - s0[:, None]) / (s1 - s0)[:, None])[:, :, None]
    w2 = (1 - u) ** 2
    uu = u * u
    return (1 + 2 * u) * w2, u * w2, uu * (3 - 2 * u), uu * (u - 1), h


def _interpolate(basis: tuple, y0: np.ndarray, y1: np.ndarray, d0: np.ndarray, d1: np.ndarray) -> np.ndarray:
    """The cubic Hermite interpolant on every interval at once, from its :func:`_basis`: values and slopes (I, k)
    at the ends; (I, p, k)."""
    h00, h10, h01, h11, h = basis
    return h00 * y0[:, None, :] + h10 * h * d0[:, None, :] + h01 * y1[:, None, :] + h11 * h * d1[:, None, :]


def _quintic_all(
    S: np.ndarray, y: np.ndarray, dy: np.ndarray, i: np.ndarray, nb: np.ndarray, x: np.ndarray, cubic: np.ndarray
) -> np.ndarray:
    """The polynomial of degree 5 through the values ``y`` and slopes ``dy`` (rows: samples, columns:
    branches) at the samples ``i``, ``i + 1`` and ``nb`` (arrays over intervals), at ``x`` (I, p): (I, p, k).
    ``cubic``: the cubic Hermite interpolant on [S_i, S_i+1] at ``x``. The two differ by ``w(s) (alpha + beta
    (s - a))`` with ``w = (s - a)^2 (s - b)^2`` (zero with its slope at both ends of the interval), whose two
    coefficients per branch match the value and slope at the neighbour ``t = S_nb``: no linear solve."""
    a, b, t = S[i][:, None], S[i + 1][:, None], S[nb][:, None]
    h = b - a
    u = (t - a) / h
    # the cubic and its slope at t (the Hermite basis evaluated outside [0, 1])
    ct = (
        (1 + 2 * u) * (1 - u) ** 2 * y[i]
        + u * (1 - u) ** 2 * h * dy[i]
        + u * u * (3 - 2 * u) * y[i + 1]
        + u * u * (u - 1) * h * dy[i + 1]
    )
    dct = (
        (6 * u * u - 6 * u) * (y[i] - y[i + 1]) / h + (3 * u * u - 4 * u + 1) * dy[i] + (3 * u * u - 2 * u) * dy[i + 1]
    )
    wt, dwt = (t - a) ** 2 * (t - b) ** 2, 2 * (t - a) * (t - b) * (2 * t - a - b)
    g = (y[nb] - ct) / wt
    beta = (dy[nb] - dct - dwt * g) / wt
    alpha = g - beta * (t - a)
    xs = np.asarray(x, dtype=float)[:, :, None]
    a3 = a[:, :, None]
    return cubic + ((xs - a3) ** 2 * (xs - b[:, :, None]) ** 2) * (alpha[:, None, :] + beta[:, None, :] * (xs - a3))


def _stroke_zero(an: MeshAnalysis, k: int, drive: str) -> _Sample:
    """The sample at stroke 0: the reference equilibrium, its ``k`` lowest eigenpairs and their slopes."""
    sys = an.system
    eq0 = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
    m0 = modes_at(sys, eq0, k, drive)
    if an.symmetry is not None and not _multiple(np.sort(m0.omega2), SLOPE_CLUSTER_GAP):
        # a symmetry that reverses the stroke maps the spectrum at s onto the one at -s, so each simple
        # eigenvalue is even in the stroke: every slope at stroke 0 is zero (computed, they are at rounding
        # level: tests/test_hermite.py); a repeated one (mirror pair) splits with slopes +-c and is computed
        return _Sample(0.0, eq0, m0, np.zeros(len(m0.omega2)))
    return _Sample(0.0, eq0, m0, stroke_slopes(an, eq0, m0))


def _refine(side: _Side, s_req: np.ndarray, tolerance: float, max_samples: int | None) -> dict:
    """The samples of one side (the requested strokes ``s_req``): the initial ones at s/4, s/2, 3s/4 and s
    (:meth:`_Side.initial`), then bisection of every interval whose estimate exceeds the tolerance, each
    first probed at its midpoint (:meth:`_Side.probe`), down to intervals of s_max/64 or the budget
    ``max_samples``. Returns the intervals' estimates."""
    smax = s_req[np.argmax(np.abs(s_req))]
    side.initial(smax)
    side.retrack()
    h_min = abs(smax) / 64.0
    while True:
        est = side.estimates()
        todo = [
            iv
            for iv, e in est.items()
            if (e > tolerance or (iv in side.coarse and iv not in side.checked)) and abs(iv[1] - iv[0]) > h_min * 1.5
        ]
        if not todo or (max_samples is not None and len(side.samples) - 1 >= max_samples):
            return est
        # every interval of the round probed against the tracked branches of its start, then the
        # probes that miss the tolerance join the samples (within the budget)
        room = np.inf if max_samples is None else max_samples - (len(side.samples) - 1)
        grow: list[_Sample] = []
        for a_s, b_s in sorted(todo, key=lambda iv: abs(iv[0])):
            if len(grow) >= room:
                break
            e, smp = side.probe(a_s, b_s)
            if e <= tolerance and not (PROBE_GATE < est[(a_s, b_s)] < np.inf):
                side.checked[(a_s, b_s)] = est[(a_s, b_s)] = e
            else:
                grow.append(smp)
        if not grow:
            return est
        for smp in grow:
            side.promote(smp)
        side.retrack()


def _fill(side: _Side, est: dict, s_req: np.ndarray, tolerance: float) -> int:
    """The requested points inside the intervals whose estimate ``est`` misses the tolerance, computed
    exactly (:meth:`_Side.fill`), the branches retracked; returns their number."""
    missed = [iv for iv, e in est.items() if e > tolerance]
    n = sum(side.fill(a_s, b_s, s_req) for a_s, b_s in missed)
    side.retrack()
    return n


def hermite_curve(
    an: MeshAnalysis,
    internal: np.ndarray,
    tolerance: float,
    max_samples: int | None = None,
    mirror: bool = True,
    fill: bool = False,
) -> HermiteResult | None:
    """Frequencies at the internal strokes ``internal`` by adaptive exact samples and cubic Hermite branches.

    Returns ``None`` when a sample cannot be computed (the continuation fails or an equilibrium is
    unstable): the caller then computes the exact curve, which reports where and why.
    ``max_samples`` bounds the exact samples per side (default: unlimited up to intervals of s_max/64).
    ``mirror``: on a design whose symmetry reverses the stroke (:mod:`model.symmetry`) only the side of
    positive strokes is sampled and each point at ``-s`` takes the interpolated branches at ``s`` (as the
    exact method does, :meth:`MeshAnalysis.frequency_curve`).
    ``fill``: when the samples stop (budget or shortest interval) with intervals whose estimate misses the
    tolerance, the requested points inside those intervals are computed exactly (:meth:`_Side.fill`): what
    remains interpolated has an estimate within the tolerance, at the cost of those exact points (``auto``).
    """
    if mirror and an.symmetry is not None and np.any(internal < 0):
        pos = one_side(internal)
        res = hermite_curve(an, pos, tolerance, max_samples, mirror=False, fill=fill)
        if res is None:
            return None
        idx = np.asarray(image_indices(pos, internal), dtype=int)  # every |s| is in pos by construction
        return HermiteResult(
            res.hz[idx],
            res.labels[idx],
            res.parasitic[idx],
            res.estimate,
            res.samples,
            res.converged,
            an.symmetry.describe(),
            res.filled,
        )
    sys = an.system
    spec = an.stroke
    drive = spec.drive
    n_rep = min(an.scene.modes, (len(sys.free) if drive == "locked" else sys.n) - sys.n_con)
    k = n_rep + 2
    if sys.n_con:
        return None  # the slopes need d(lambda)/ds of rigid-deformation multipliers: not implemented
    first = _stroke_zero(an, k, drive)
    eq0, m0 = first.eq, first.modes
    curvature = path_curvature(sys, eq0)  # both sides' first step of 1/4 of the stroke is a parabola
    hz = np.empty((len(internal), n_rep))
    labels = np.empty((len(internal), n_rep), dtype=object)
    par = np.empty(len(internal))
    estimate, used, converged, filled = 0.0, 1, True, 0
    try:
        for sel in (internal >= 0, internal < 0):
            s_req = internal[sel]
            if not len(s_req) or np.abs(s_req).max() == 0:
                if len(s_req):  # only stroke 0 on this side
                    lab, par0 = an.label_modes(m0, eq0.tangent)
                    hz[sel] = _hz(1.0 / m0.omega2)[:n_rep]
                    labels[sel] = np.array(lab[:n_rep], dtype=object)
                    par[sel] = par0
                continue
            side = _Side(an, first, k, drive, curvature)
            est = _refine(side, s_req, tolerance, max_samples)
            if fill and any(e > tolerance for e in est.values()):
                filled += _fill(side, est, s_req, tolerance)
                est = side.estimates()
            side_est = max(est.values())
            estimate = max(estimate, side_est)
            converged = converged and side_est <= tolerance
            used += sum(1 for x in side.samples[1:] if not x.filled)
            lam, labs = side.interpolate(s_req)
            h = _hz(lam)
            hz[sel] = h[:, :n_rep]
            lab_arr = np.array(labs, dtype=object)
            labels[sel] = lab_arr[:, :n_rep]
            is_par = lab_arr == "parasitic"
            par[sel] = np.where(is_par.any(axis=1), np.where(is_par, h, np.inf).min(axis=1), np.nan)
    except _Fallback:
        return None
    return HermiteResult(hz, labels, par, estimate, used, converged, filled=filled)


def hermite_frequency_curve(
    an: MeshAnalysis, values: np.ndarray, tolerance: float, max_samples: int | None = None, fill: bool = False
):
    """The ``hermite`` method as a :class:`~model.results.FrequencyCurve`; the exact curve when a sample fails.

    ``solver`` reports the exact samples used, the estimated max relative error (of the interpolated
    intervals) and whether the adaptive refinement met ``tolerance``; with ``fill`` (see
    :func:`hermite_curve`) also ``exact_points``, the requested points computed exactly.
    """
    t0 = time.perf_counter()
    spec = an.stroke
    internal = np.asarray(spec.to_internal(values), dtype=float)
    res = hermite_curve(an, internal, tolerance, max_samples, fill=fill)
    if res is None:
        ex = an.frequency_curve(values)
        return ex, {"fallback": "exact (a sample's equilibrium could not be computed)"}
    if not np.all(np.isfinite(res.hz)):
        raise FlexoptError("the hermite interpolation produced non-finite frequencies; use method 'exact'")
    extra: dict[str, float | int | bool | str] = {
        "samples": res.samples,
        "estimated_error": res.estimate,
        "tolerance": tolerance,
        "converged": res.converged,
    }
    if fill:
        extra["exact_points"] = res.filled
    if res.mirrored is not None:
        extra["mirrored"] = f"negative strokes from positive ones by the design's symmetry ({res.mirrored})"
    conv = {
        "method": "hermite: exact equilibria, eigenpairs and d(lambda)/ds at the samples, cubic Hermite "
        "interpolation of each tracked branch's 1/omega^2 between them"
        + (
            f"; {res.filled} requested points in intervals that missed the tolerance computed exactly"
            if res.filled
            else ""
        ),
        "drive_reaction": "not computed by this method (NaN)",
    }
    curve = _curve_from(an, "hermite", values, res.hz, res.labels, res.parasitic, time.perf_counter() - t0, extra, conv)
    return curve, extra
