"""The elastic model's equations (paper eqs 12-19), set up for the peer solvers from the mechanism.

Written from the paper and docs/models.md, not from labtool's dynamics code: only the mechanism
layer (kinematic terms on the cam-angle grid, motor, inertias) is shared, as any user of labtool's
mechanism would share it. One degree of freedom x (m) along the contact normal, positive towards
the exterior flank:

    M(t) x'' = F(x) - R31(t)
    F = Kc (-x)^(10/9) on the interior flank (x <= 0), 0 in flight (0 < x < j),
        -Kc (x - j)^(10/9) on the exterior flank (x >= j)
    R31 = MR13D_kin / (l cos alpha)         M = M1 M2 / (M1 + M2), M1 = 4 Jcam/Db1^2, M2 = 4 J''/Db2^2
    Kc = 8.05e4 lw[mm]^(8/9) N/mm^(10/9) (eq. 15), in SI x 1e3^(10/9)
    omega2 = omega2_kin + x' / (l cos alpha)  (eq. 19)

R31 and M are tabulated on 4001 uniform cam angles over the rise and interpolated linearly in time
(the model's own discretisation of its coefficients, so that all solvers integrate the same ODE).
The state is scaled, u = x / x_s, w = x' / v_s (x_s the static deflection under the largest |R31|,
v_s = x_s 2 pi / T, T the linearised contact period), so one absolute tolerance fits both.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from labtool.models.mechanism.cam_tables import angle_terms, grid_terms
from labtool.models.mechanism.motor import cam_inertia, no_load_cam_speed, transmission_ratio

GRID_POINTS = 4001          # cam angles of the coefficient tables over the rise
OUTPUT_STEP = 2e-5          # s, the output instants (uniform), as the model's datasets
PALMGREN_N_MM = 8.05e4      # N / mm^(10/9) per mm^(8/9) of contact length, eq. (15)
NUDGE = 1e-13               # m, a restart begins this far inside the new phase
INTERIOR, FLIGHT, EXTERIOR = 0, 1, 2


@dataclasses.dataclass
class ElasticProblem:
    t0: float               # s, first grid instant (0)
    dt: float               # s, grid step
    R31: np.ndarray         # N
    M: np.ndarray           # kg
    kc: float               # N / m^(10/9)
    gap: float              # m
    xs: float               # m, scale of x
    vs: float               # m/s, scale of x'
    t_end: float            # s
    t_out: np.ndarray       # s, output instants
    omega1: float           # rad/s
    scene: object

    def data(self) -> np.ndarray:
        """Flat array for compiled right-hand sides: [phase, kc, gap, xs, vs, t0, dt, n, R31..., M...]."""
        n = self.R31.size
        head = np.array([0.0, self.kc, self.gap, self.xs, self.vs, self.t0, self.dt, float(n)])
        return np.concatenate([head, self.R31, self.M])

    def initial_state(self):
        """(t_start, u0, w0, phase): static equilibrium on the flank R31(0) loads; a zero R31 at the
        start waits at rest until the drive departs from zero (then sits on the flank it loads)."""
        r0 = float(self.R31[0])
        if r0 == 0.0:
            nz = np.flatnonzero(self.R31)
            if nz.size:
                phase = INTERIOR if self.R31[nz[0]] > 0 else EXTERIOR
                x0 = -NUDGE if phase == INTERIOR else self.gap + NUDGE
                return self.t0 + (nz[0] - 1) * self.dt, x0 / self.xs, 0.0, phase
            return 0.0, 0.0, 0.0, FLIGHT if self.gap > 0 else INTERIOR
        if r0 > 0:
            return 0.0, -(r0 / self.kc) ** 0.9 / self.xs, 0.0, INTERIOR
        return 0.0, (self.gap + (-r0 / self.kc) ** 0.9) / self.xs, 0.0, EXTERIOR


def build(scene) -> ElasticProblem:
    """The problem of a Scene (sine law etc.; contact damping must be 0, as the paper's)."""
    if scene.contact_damping != 0:
        raise ValueError("the peers model the paper's undamped contact only")
    mech, program = scene.mechanism, scene.program
    omega1 = no_load_cam_speed(mech, scene.omega1_nominal) if scene.omega1_mode == "var" else scene.omega1_nominal
    span = program.rise_angle
    load_until = float(np.nextafter(span, 0.0))     # the rise's load up to its last instant
    terms = grid_terms(mech, program, span, GRID_POINTS, load_until)
    op = terms.at_speed(omega1, scene.Fu, scene.jt_factor)
    arm = mech.l * np.cos(terms.alpha)
    R31 = op["MR13D"] / arm
    Jcam = cam_inertia(mech, transmission_ratio(mech, scene.omega1_nominal))
    with np.errstate(divide="ignore"):
        M1 = np.where(terms.Db1 > 0, 4.0 * Jcam / np.where(terms.Db1 > 0, terms.Db1, 1.0) ** 2, np.inf)
    M2 = 4.0 * op["J_follower"] / terms.Db2 ** 2
    M = M2 / (1.0 + M2 / M1)
    kc = scene.kc_factor * PALMGREN_N_MM * (scene.contact_length * 1e3) ** (8.0 / 9.0) * 1e3 ** (10.0 / 9.0)
    gap = 0.0 if scene.elastic_gap == "closed" else scene.backlash
    f = max(float(np.max(np.abs(R31))), 1.0)
    xs = (f / kc) ** 0.9
    k_lin = (10.0 / 9.0) * f / xs
    period = 2.0 * math.pi * math.sqrt(float(np.min(M)) / k_lin)
    t_end = span / omega1
    n_out = max(int(math.ceil(t_end / OUTPUT_STEP)) + 1, 2)
    return ElasticProblem(0.0, t_end / (GRID_POINTS - 1), np.ascontiguousarray(R31), np.ascontiguousarray(M),
                          kc, gap, xs, xs * 2.0 * math.pi / period, t_end, np.linspace(0.0, t_end, n_out),
                          omega1, scene)


def outputs(prob: ElasticProblem, u: np.ndarray, w: np.ndarray, phase: np.ndarray) -> dict:
    """omega2 (eq. 19) and the contact-force moment at the output instants, from the scaled state."""
    mech, program, scene = prob.scene.mechanism, prob.scene.program, prob.scene
    terms = angle_terms(mech, program, prob.omega1 * prob.t_out, float(np.nextafter(program.rise_angle, 0.0)),
                        linkage="spline")
    op = terms.at_speed(prob.omega1, scene.Fu, scene.jt_factor)
    arm = mech.l * np.cos(terms.alpha)
    x, v = u * prob.xs, w * prob.vs
    F = np.where(phase == INTERIOR, prob.kc * np.clip(-x, 0.0, None) ** (10.0 / 9.0),
                 np.where(phase == EXTERIOR, -prob.kc * np.clip(x - prob.gap, 0.0, None) ** (10.0 / 9.0), 0.0))
    return {"omega2": op["omega2"] + v / arm, "MR13D": F * arm, "x_el": x}
