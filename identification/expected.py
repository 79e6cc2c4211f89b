"""The 95 % interval a joint fit would give after one more recording (``labtool suggest --goal
identify``; docs/identification.md, "The next experiment").

A fit's interval (labtool.identification.uncertainty) is the measurement's part, the model's
discrepancy, the objective's roughness and the numerical parts in quadrature. A recording at a
candidate point c changes each:

* **the measurement's part**: its information J_c^T J_c / (s^2 x inflation) joins the fit's
  (Ds-optimal design: the shared parameters' information with every other profiled out);
* **the model's discrepancy**: its half-width is t(K - p) sqrt((J^T J)^-1_ii (S - N) / (K - p)),
  S - N the objective beyond the noise, K its independent features (the residuals' participation
  ratio (sum r^2)^2 / sum r^4 over the correlation inflation). A recording adds its own misfit
  beyond the noise E_c and its features: with residuals e + noise (unit variance), sum r^4 grows
  by sum e^4 + 6 E_c + 3 N_c, with sum e^4 = E_c^2 / k, k the participation ratio a recording's
  misfit (without its noise) has today, per file; the residuals' correlation inflation is the
  misfit's (the noise is white), so it grows with the misfit's share of S. A point where the
  model misses many times more than today raises S - N more than it adds features: its interval
  widens although its information is large;
* **the roughness**: sqrt(R (J^T J)^-1_ii), R the rms of the objective's departures from its
  quadratic (the models change in discrete steps: an impact more or less). The new recording's own
  R_c is measured at c by the caller as the fit would measure it (labtool.identification.design:
  the model's residuals at the fit's own points u +- FD_STEP e_i, their second difference; where
  impacts are violent the objective's steps are large); without it, R_c = R x its information on
  the shared parameters over a measured recording's (the mean). Independent recordings' steps add
  in quadrature: sqrt(R^2 + R_c^2) (a recording like the ones measured: R sqrt(2), its part of the
  interval x 2^(-1/4));
* **the numerical parts** (the model's revolutions, the solver preset, the convergence): today's
  are Gauss-Newton steps (J^T J)^-1 J^T dr of the residuals' numerical changes dr, so they shrink
  as (J^T J)^-1 does; the new recording adds its own steps: from its residuals' change to the other
  solver preset at c (``shift_c`` = J_c^T dr_c) and, as the fit's ``model_revolutions`` part, 2 x
  the spread of the steps each of the model run's steady revolutions at c asks for (``rev_c``, one
  column J_c^T dr_k per revolution): where the impacts are violent the model resolves them less
  well and repeats itself less, and a recording there brings numerical error with its information.

What the recording at c would miss is not known before it is made; ``excess`` is the caller's
prediction of it (labtool.identification.design: the measured misfit, scaled by how far the
candidate models' predictions lie apart at c against at the measured speeds).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from labtool.identification.uncertainty import MIN_FEATURE_DOF


@dataclasses.dataclass
class Today:
    """The fit's interval, in parts (unit box, joint layout: the shared parameters first, then
    each file's own), with a padding for the new recording's own parameters (``n_own``)."""

    M: np.ndarray            # (P, P) the measurement's information (cov^-1), padded
    A: np.ndarray            # (P, P) J^T J, padded
    t: float                 # the measurement's t quantile
    half: np.ndarray         # (ns,) today's 95 % half-widths of the shared parameters
    other: np.ndarray        # (ns,) the numerical parts other than the roughness, in quadrature
    excess: float            # S - N
    objective: float         # S
    features: float          # K
    inflation: float         # the residuals' mean correlation inflation (>= 1)
    rough: float             # R (objective units)
    n_files: int
    ns: int


def combine(today: Today, pos: np.ndarray, JtJ_scaled: np.ndarray, JtJ: np.ndarray, excess_c: float,
            n_c: int, shift_c: np.ndarray | None = None, rev_c: np.ndarray | None = None,
            rough_c: float | None = None) -> dict:
    """The shared parameters' expected 95 % half-widths (unit box) after a recording whose
    information (``JtJ_scaled`` for the measurement's part, ``JtJ`` unscaled) enters at ``pos``,
    whose misfit beyond the noise is ``excess_c`` (sum e^2), over ``n_c`` residuals, whose
    residuals' change to the other preset gives J_c^T dr_c = ``shift_c``, whose model revolutions'
    changes give ``rev_c`` (p_c, revolutions: J_c^T dr_k each; fewer than two: none) and whose
    objective's roughness is ``rough_c`` (objective units; None: today's R scaled by the
    information). Returns each part (``measurement``, ``discrepancy``, ``roughness``,
    ``numerical``) and their ``total``."""
    keep = np.zeros(today.M.shape[0], bool)
    keep[:today.ns] = True
    M = today.M.copy()
    M[np.ix_(pos, pos)] += JtJ_scaled
    A = today.A.copy()
    A[np.ix_(pos, pos)] += JtJ
    var = np.diag(np.linalg.pinv(M, rcond=1e-12, hermitian=True))[:today.ns]
    G = np.linalg.pinv(A, rcond=1e-12, hermitian=True)
    g = np.diag(G)[:today.ns]
    g0 = np.diag(np.linalg.pinv(today.A, rcond=1e-12, hermitian=True))[:today.ns]
    var, g = np.clip(var, 0.0, None), np.clip(g, 0.0, None)
    shrink = np.where(g0 > 0, g / np.where(g0 > 0, g0, 1.0), 1.0)
    numerical2 = today.other ** 2 * shrink
    if shift_c is not None:
        b = np.zeros(A.shape[0])
        b[pos] = shift_c
        numerical2 = numerical2 + (G @ b)[:today.ns] ** 2
    if rev_c is not None and rev_c.shape[1] >= 2:
        # its own revolutions' steps, as the fit's model_revolutions part takes them: 2 x their spread
        b = np.zeros((A.shape[0], rev_c.shape[1]))
        b[pos] = rev_c
        numerical2 = numerical2 + (2.0 * (G @ b)[:today.ns].std(axis=1, ddof=1)) ** 2
    meas = today.t * np.sqrt(var)
    excess = today.excess + excess_c
    S = today.objective + n_c + excess_c
    q0 = today.objective ** 2 / max(today.features * today.inflation, 1.0)     # sum r^4 today
    # today's misfit alone: sum e^4 without the noise's 6 sum e^2 + 3 N; a recording's misfit is
    # shaped as today's are (per file), so sum e^4 grows as its misfit squared
    e4_now = q0 - 6.0 * today.excess - 3.0 * (today.objective - today.excess)
    e4_now = e4_now if e4_now > 0 else q0
    e4 = e4_now * today.n_files * (excess_c / today.excess) ** 2 if today.excess > 0 else 0.0
    q = q0 + e4 + 6.0 * excess_c + 3.0 * n_c
    p = M.shape[0]
    # the misfit is what correlates the residuals (the noise is white): the inflation grows with its share
    share_now = today.excess / today.objective if today.objective > 0 else 0.0
    inflation = (1.0 + (today.inflation - 1.0) * (excess / S) / share_now) if share_now > 0 else today.inflation
    features = max(S * S / q / inflation, p + MIN_FEATURE_DOF)
    dof = features - p
    disc = float(stats.t.ppf(0.975, dof)) * np.sqrt(excess / dof * g)
    shared_pos = pos < today.ns
    per_file = float(np.trace(today.A[:today.ns, :today.ns])) / today.n_files
    if rough_c is None:
        r_c = today.rough * float(np.trace(JtJ[np.ix_(shared_pos, shared_pos)])) / per_file if per_file > 0 else 0.0
    else:
        r_c = rough_c
    rough = np.sqrt(math.hypot(today.rough, r_c) * g)
    return {"measurement": meas, "discrepancy": disc, "roughness": rough, "numerical": np.sqrt(numerical2),
            "total": np.sqrt(meas ** 2 + disc ** 2 + rough ** 2 + numerical2)}
