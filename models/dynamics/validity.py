"""Each dynamic model checks its own validity and says so.

Where an answer is doubtful the model returns it with a warning (one sentence, printed by
``labtool simulate`` and stored in the dataset's ``validity_warnings`` attribute as a JSON list);
where it would be meaningless it refuses with one line (InputError for a scene no cam can realise,
SolverError for a run whose physics leaves the model's ground). The thresholds and their reasons:

- the groove must exist: a pitch curve whose convex radius of curvature falls below the roller
  radius R (or, concave, below R + j) is undercut, the roller cannot follow the motion law and the
  contact normal is undefined at its cusps (a 5 deg rise: 0.27 mm, the impacts' moment arms 1e-16 m).
  Refused.
- the pressure angle: the cam drives the follower through l cos(alpha); above PRESSURE_ANGLE_WARN
  the drive is poor (designers keep oscillating followers below ~45 deg); at PRESSURE_ANGLE_LIMIT and
  above the mechanism self-locks and the models' reduced masses and impulses diverge. Refused there.
- the backlash against the groove's curvature: the rigid model's gap is linearised to first order
  in j / rho (rho the pitch curve's smallest radius of curvature), the elastic model maps x to the
  follower angle through x / (l cos alpha); above GAP_WARN = 5 % the geometry of the gap is off by
  that fraction (j = 5 mm on the STB-216 cam: 34 %).
- the contact law (elastic): Palmgren's line-contact fit holds for deformations small against the
  roller and the flank's curvature; above DEFORMATION_WARN of the smaller of R and the flank's radius
  of curvature the contact force is extrapolated; a deformation reaching R (the roller sunk into the
  flank by its own radius) is refused.
- the motor (omega1 var): the elastic model turns the cam at a constant speed; an energy bound on
  the speed drop the follower's inertia and load would cause (``speed_drop``, the motor's response
  left out) is warned above SPEED_DROP_WARN (Table 1's runs reach 7 %; the rigid model, which
  integrates the speed, finds 3.5 % there); when the load takes more work than the flywheel and the
  motor at standstill torque (eq. 3) can give, the cam stops and the constant speed is meaningless:
  refused. The rigid model integrates omega1 and
  warns when the motor's slip leaves the neighbourhood of its rated point (eq. 3 is a straight line
  through the synchronous and the nominal point: SLIP_WARN times the nominal slip).
- the elastic energy balance of an undamped run (labtool.models.dynamics.elastic.energy_error) above the
  project's ENERGY_BOUND: the output samples miss part of the contact dynamics.
"""
from __future__ import annotations

import json
import math

import numpy as np

from labtool.common.errors import InputError, SolverError
from labtool.models.dynamics.jit import jit
from labtool.models.mechanism.cam_profile import contact_geometry
from labtool.models.mechanism.memo import cached
from labtool.models.mechanism.motor import cam_inertia, motor_moment_on_cam, transmission_ratio

PRESSURE_ANGLE_WARN = 60.0     # deg
PRESSURE_ANGLE_LIMIT = 80.0    # deg
GAP_WARN = 0.05                # j / rho_min
DEFORMATION_WARN = 0.01        # of min(R, flank radius)
SPEED_DROP_WARN = 0.20         # relative (Table 1's runs: at most 0.07)
SLIP_WARN = 3.0                # times the nominal slip
ENERGY_BOUND = 5e-3
GROOVE_POINTS = 2880


def attribute(warnings: list[str]) -> str:
    """The dataset attribute: a JSON list of the sentences (``[]`` when none)."""
    return json.dumps(list(warnings))


def _groove(mech, program) -> dict:
    """Facts of the groove over one revolution (cached per mechanism and program)."""
    def build():
        phi1 = np.linspace(0.0, 2.0 * math.pi, GROOVE_POINTS, endpoint=False)
        g = contact_geometry(mech, program, phi1)
        rho, alpha = g["rho_pitch"], np.degrees(np.abs(g["pressure_angle"]))
        rho_inner, rho_outer = np.abs(g["rho_inner"]), np.abs(g["rho_outer"])
        convex, concave = rho > 0, rho < 0
        return dict(phi1=phi1, rho_inner=rho_inner, rho_outer=rho_outer,
                    rho_flank_min=float(min(rho_inner.min(), rho_outer.min())),
                    alpha_max=float(alpha.max()), alpha_at=float(phi1[alpha.argmax()]),
                    rho_min=float(np.abs(rho).min()), rho_at=float(phi1[np.abs(rho).argmin()]),
                    convex_min=float(rho[convex].min()) if convex.any() else math.inf,
                    concave_min=float(-rho[concave].max()) if concave.any() else math.inf)
    return cached(("validity_groove", mech.cache_key, program), build)


def check_scene(scene, gap: float | None = None, refuse: bool = True) -> list[str]:
    """The scene's geometry (every model level): refuse a groove that cannot exist or a
    self-locking pressure angle; warn about a poor pressure angle or a gap large against the
    groove's curvature. ``gap`` (m): the gap the model crosses (default the scene's backlash).
    ``refuse=False`` (the kinematic level, which only evaluates the motion law) turns the
    refusals into warnings."""
    mech = scene.mechanism
    g = _groove(mech, scene.program)
    j = scene.backlash if gap is None else gap
    deg = math.degrees
    warnings = []

    def meaningless(message: str):
        if refuse:
            raise InputError(message)
        warnings.append(message)

    if g["convex_min"] < mech.R or g["concave_min"] < mech.R + scene.backlash:
        meaningless(
            f"the groove is undercut: the pitch curve's radius of curvature falls to {g['rho_min'] * 1e3:.3g} mm at "
            f"phi1 = {deg(g['rho_at']):.1f} deg, below the roller radius {mech.R * 1e3:g} mm (+ backlash on the "
            "outer flank); no cam realises this motion law; lengthen the rise or shorten the stroke")
    elif g["alpha_max"] >= PRESSURE_ANGLE_LIMIT:
        meaningless(f"the pressure angle reaches {g['alpha_max']:.1f} deg at phi1 = {deg(g['alpha_at']):.1f} deg "
                    f"(limit {PRESSURE_ANGLE_LIMIT:g} deg): the cam cannot drive the follower; "
                    "lengthen the rise or shorten the stroke")
    if PRESSURE_ANGLE_WARN < g["alpha_max"] < PRESSURE_ANGLE_LIMIT:
        warnings.append(f"the pressure angle reaches {g['alpha_max']:.1f} deg at phi1 = {deg(g['alpha_at']):.1f} deg: "
                        f"the cam drives the follower poorly (above {PRESSURE_ANGLE_WARN:g} deg)")
    if j / g["rho_min"] > GAP_WARN:
        warnings.append(f"the backlash {j * 1e3:g} mm is {100 * j / g['rho_min']:.0f} % of the groove's smallest "
                        f"radius of curvature ({g['rho_min'] * 1e3:.3g} mm): the models' linear gap geometry is "
                        "off by about that fraction")
    return warnings


def speed_drop(scene, tab) -> tuple[float, np.ndarray]:
    """(relative speed drop, slack in J) of the cam under the follower's demand, from energy alone:
    with Jred = J' + J'' psi'^2 (eq. 2) and W_s(phi1) the work of the follower's static moments
    (gravity, load: the kinetostatic MR13D's work minus the follower's kinetic energy), a cam left to
    itself turns at omega^2 = (Jred(0) omega1^2 - 2 W_s) / Jred. The drop is its largest deficit on
    omega1 (an upper bound: the motor's response is left out). The slack adds the most the motor can
    give, its standstill torque (eq. 3) over the angle turned; below zero the cam stops."""
    mech = scene.mechanism
    it = transmission_ratio(mech, scene.omega1_nominal)
    J_cam = cam_inertia(mech, it)
    slack = np.empty(tab.t.size)
    lowest = _energy_budget(tab.t, tab.phi1, tab.M2, tab.Db2, tab.omega2, tab.MR13D, float(J_cam), float(tab.omega1),
                            float(motor_moment_on_cam(mech, 0.0, it)), slack)
    drop = 1.0 - float(np.sqrt(max(lowest, 0.0))) / tab.omega1
    return drop, slack


@jit
def _energy_budget(t, phi1, M2, Db2, omega2, MR13D, J_cam, omega1, motor0, slack, lowest_too=True):
    """``speed_drop``'s balance in one pass (the numpy expressions' arithmetic, in their order):
    the work W of the trapezoidal MR13D omega2 integral, J'' = M2 Db2^2 / 4 (eq. 16 inverted),
    energy = Jred(0) omega1^2 - 2 (W - (T'' - T''(0))); writes slack = energy / 2 + motor0 (phi1 -
    phi1(0)) and returns min(energy / Jred) (NaN if any is), or inf without ``lowest_too`` (the
    stall check alone reads the slack: two divisions an angle saved)."""
    n = t.size
    J0 = M2[0] * Db2[0] ** 2 / 4.0
    T0 = 0.5 * J0 * omega2[0] ** 2
    J_red0 = J_cam + J0 * (omega2[0] / omega1) ** 2
    e_start = J_red0 * omega1 ** 2
    W = 0.0
    lowest = np.inf
    for i in range(n):
        J = M2[i] * Db2[i] ** 2 / 4.0
        if i > 0:
            W += 0.5 * (MR13D[i] * omega2[i] + MR13D[i - 1] * omega2[i - 1]) * (t[i] - t[i - 1])
        W_static = W - (0.5 * J * omega2[i] ** 2 - T0)
        energy = e_start - 2.0 * W_static
        if lowest_too:
            r = energy / (J_cam + J * (omega2[i] / omega1) ** 2)
            if r < lowest or r != r:
                lowest = r
        slack[i] = 0.5 * energy + motor0 * (phi1[i] - phi1[0])
    return lowest


def elastic_before(scene, tab) -> list[str]:
    """The motor against the elastic model's constant cam speed (omega1 var only)."""
    if scene.omega1_mode != "var":
        return []
    drop, slack = speed_drop(scene, tab)
    k = stall_index(slack)
    if k >= 0:
        raise motor_stall(float(tab.phi1[k]))
    if drop > SPEED_DROP_WARN:
        return [f"the follower's demand could slow the cam by up to {100 * drop:.0f} % (an energy bound, the "
                "motor's response left out); the elastic model holds the cam speed constant: --model rigid "
                "computes its variation"]
    return []


@jit
def stall_index(slack) -> int:
    """The first angle index where ``speed_drop``'s slack is below zero (the motor stalls), or -1."""
    for i in range(slack.size):
        if slack[i] < 0.0:
            return i
    return -1


def motor_stall(phi1: float) -> SolverError:
    """The refusal of a run whose motor stalls by the cam angle phi1 (rad): ``speed_drop``'s slack
    below zero there."""
    return SolverError(
        f"the motor stalls: by phi1 = {math.degrees(phi1):.1f} deg the follower's load has taken more "
        "work than the cam's kinetic energy and the motor's standstill torque (eq. 3) can give; the elastic "
        "model's constant cam speed is meaningless here (--model rigid integrates the speed)")


def deformation_range(scene, d_max: float, phase: int, phi1: float) -> list[str]:
    """The contact law's range in an elastic run whose largest deformation is d_max (m), first
    reached in contact phase ``phase`` (0 interior flank) at the cam angle phi1 (rad): refused at the
    roller radius, warned above DEFORMATION_WARN of the roller's or that flank's radius there."""
    mech = scene.mechanism
    if d_max >= mech.R:
        raise SolverError(f"the contact deformation reaches {d_max * 1e3:.3g} mm, at least the roller radius "
                          f"{mech.R * 1e3:g} mm: the contact law is meaningless there; check the contact "
                          "stiffness (--kc-factor, --contact-length-mm) and the load")
    g = _groove(mech, scene.program)
    # the bound is the smallest radius of either flank: below it no scale can make the warning
    if not d_max > DEFORMATION_WARN * min(mech.R, g["rho_flank_min"]):
        return []
    flank = g["rho_inner"] if phase == 0 else g["rho_outer"]
    rho = float(np.interp(np.mod(phi1, 2.0 * math.pi), g["phi1"], flank, period=2.0 * math.pi))
    scale = min(mech.R, rho)
    if d_max > DEFORMATION_WARN * scale:
        return [f"the contact deformation reaches {d_max * 1e3:.3g} mm, {100 * d_max / scale:.1f} % of "
                f"the roller radius or the flank's radius of curvature ({scale * 1e3:.3g} mm): "
                "Palmgren's line-contact law is extrapolated"]
    return []


def elastic_after(scene, cols, ind) -> list[str]:
    """The contact law's range and the energy balance of an elastic run (``cols``: the dataset or
    its columns: deformation, contact_phase, phi1)."""
    deformation = np.asarray(cols["deformation"])
    k = int(np.argmax(deformation))             # the first largest (NaN first, as max() reads it)
    warnings = deformation_range(scene, float(deformation.max()), int(np.asarray(cols["contact_phase"])[k]),
                                 float(np.asarray(cols["phi1"])[k]))
    err = ind.get("energy_error")
    if err is not None and err > ENERGY_BOUND:
        warnings.append(f"the energy balance closes to {err:.1e} only (bound {ENERGY_BOUND:g}): the output "
                        "samples miss part of the contact dynamics; try --accuracy reference")
    return warnings


def rigid_after(scene, cols, ind) -> list[str]:
    """The motor's operating range in a rigid run (omega1 var); ``cols``: the dataset or its
    columns (omega1)."""
    if scene.omega1_mode != "var":
        return []
    mech = scene.mechanism
    it = transmission_ratio(mech, scene.omega1_nominal)
    omega1 = np.asarray(cols["omega1"])
    if np.nanmin(omega1) <= 0:
        raise SolverError("rigid model: the cam stopped (omega1 <= 0): the motor stalls under this load")
    slip = 1.0 - float(np.nanmin(omega1)) * it / mech.omega_sync_motor
    nominal = 1.0 - mech.omega_nominal_motor / mech.omega_sync_motor
    if slip > SLIP_WARN * nominal:
        return [f"the motor's slip reaches {100 * slip:.0f} % ({slip / nominal:.1f}x its nominal "
                f"{100 * nominal:.0f} %): its linear characteristic (eq. 3) is used far from its rated point"]
    return []
