"""The foreign stand (tests/foreign_stand.py), checked against facts that do not come from it.

It is the yardstick of the fit's coverage (benchmarks/fit_coverage.py), so its physics is checked
the way a model's is: its exact gap against the mechanism's closed-form arm, its energy without
losses, its contact law's restitution, and, in the limit where it must become labtool's rigid
model (stiff elastic flanks, no bending, an exact groove), the rigid model's flight.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests import foreign_stand as fsd


def _at(table, phi1):
    return float(np.interp(phi1, np.linspace(0.0, 2 * math.pi, fsd.N_PHI1, endpoint=False), table))


def test_the_exact_gap_is_the_mechanisms_arm_to_first_order():
    # dg/dq at q = 0 is A2 = l cos(alpha) = Db2 / 2 (docs/rigid_model.md), which labtool computes in
    # closed form; here it comes from Newton's method on a spline of the pitch curve
    from labtool.models.mechanism.cam_profile import contact_geometry

    tb = fsd._tables()
    phi = np.linspace(0.0, 2 * math.pi, fsd.N_PHI1, endpoint=False)
    A2 = contact_geometry(tb["mech"], tb["program"], phi)["Db2"] / 2
    assert np.max(np.abs(tb["gap"]["a1"] / A2 - 1.0)) < 1e-4
    # the second-order term labtool neglects: below 1 % of the gap at j = 0.2 mm (order j / rho)
    q = 0.2e-3 / A2
    share = np.abs(tb["gap"]["a2"] * q) / tb["gap"]["a1"]
    assert 1e-4 < share.max() < 0.01


@pytest.mark.slow
def test_without_losses_and_with_the_cam_standing_the_energy_is_constant():
    st = fsd.ForeignStand(restitution=1.0, width_variation=0.0, mode_zeta=0.0, friction_torque=0.0,
                          friction_viscous=0.0, Fu=0.0, ripple=0.0)
    par, mb = fsd.parameters(st)
    par[0] = 0.0                                  # the cam stands still: nothing does work on the follower
    tb = fsd._tables()
    gap, fol, mech = tb["gap"], tb["fol"], tb["mech"]
    phi1 = 4.5                                    # in the lower dwell
    a1, a2, p2 = _at(gap["a1"], phi1), _at(gap["a2"], phi1), _at(gap["phi2p"], phi1)
    y0 = [phi1, p2 + 0.5 * st.backlash / a1, 0.05 / a1, 1e-6, 0.0]     # 5 cm/s across the gap, the arm bent
    rec, ev = fsd.integrate(par, y0, 40_000)
    assert np.sum(ev[:, 2] > 0) > 30                # it bounces between the flanks
    th, om, u, du = rec[:, 1], rec[:, 2], rec[:, 4], rec[:, 5]
    grid = fol["lo"] + fol["step"] * np.arange(fsd.N_PHI2)
    # gravity's potential from its moment (M = -dV/dtheta), the contacts' from Hertz's law
    v_grav = -np.concatenate([[0.0], np.cumsum(0.5 * (fol["Mg"][1:] + fol["Mg"][:-1]) * fol["step"])])
    q = th - p2
    g = a1 * q + a2 * q * q
    v_contact = 0.4 * st.contact_k * (np.clip(-g, 0, None) ** 2.5 + np.clip(g - st.backlash, 0, None) ** 2.5)
    Jr = np.interp(th, grid, fol["J"]) - mb * mech.DE ** 2
    E = (0.5 * Jr * om ** 2 + 0.5 * mb * (mech.DE * om + du) ** 2 + 0.5 * par[9] * u ** 2
         + np.interp(th, grid, v_grav) + v_contact)
    assert (E.max() - E.min()) < 3e-4 * E.mean(), (E.min(), E.max())


@pytest.mark.parametrize("e", [0.3, 0.5, 0.8])
def test_the_contact_law_rebounds_at_its_restitution_whatever_the_speed(e):
    # Flores et al.'s law: an isolated impact of a mass rebounds at about e (0.26, 0.47, 0.79 for
    # e = 0.3, 0.5, 0.8: the law is approximate at low e), the same at every speed
    m = 2.5
    out = []
    for v0 in (0.01, 0.1, 1.0):
        def rhs(t, y):
            return [y[1], -fsd._flank_force(y[0], y[1], v0, 1e11, e, 1e12) / m]

        def back(t, y):
            return y[0] + 1e-12 if t > 1e-7 else 1.0
        back.terminal, back.direction = True, -1
        sol = solve_ivp(rhs, (0.0, 0.01), [0.0, v0], events=back, rtol=1e-10, atol=1e-14, max_step=2e-6)
        out.append(-sol.y[1, -1] / v0)
    assert np.ptp(out) < 1e-6
    assert abs(out[0] - e) < 0.05


@pytest.mark.slow
def test_stiff_lossless_flanks_land_where_labtools_rigid_model_lands():
    # a different derivation of the same flight: exact gap and compliant flanks against the
    # rigid model's linearised gap and Newton's impacts; with K x 100 and no extras they must agree
    from labtool.common.units import MM, RPM
    from labtool.models.dynamics.scene import Scene
    from labtool.models.dynamics.simulate import simulate
    from labtool.models.mechanism import Mechanism

    st = fsd.ForeignStand(rpm=180.0, backlash=0.128e-3, restitution=0.5, mode_share=0.0, width_variation=0.0,
                          contact_k=1e13, ripple=0.0, friction_torque=0.0, friction_viscous=0.0, duration_s=0.4)
    m = fsd.motion(st)
    ev = m["events"]
    deg = np.degrees(np.interp(ev[:, 0], m["t"], m["phi1"])) % 360
    first = np.flatnonzero((ev[:, 1] < 0) & (ev[:, 2] > 0) & (deg > 20) & (deg < 60))[0]
    sim = simulate(Scene(cam_speed=180 * RPM, backlash=0.128 * MM, restitution=0.5, revolutions=1, rise_only=True,
                         mechanism=Mechanism.default(), accuracy="standard"), "rigid").dataset
    kinds = sim["event_kind"].values.astype(str)
    land = np.flatnonzero(kinds == "contact")[0]
    assert deg[first] == pytest.approx(math.degrees(float(sim["event_phi1"].values[land])), abs=0.05)
    assert ev[first, 3] == pytest.approx(float(sim["event_v_rel"].values[land]), rel=0.02)


@pytest.mark.slow
def test_a_foreign_recording_is_format_v1_that_labtool_processes(tmp_path):
    import labtool

    h5 = tmp_path / "foreign.h5"
    truth = fsd.record(h5, fsd.ForeignStand(rpm=300.0, duration_s=1.5, seed=3))
    assert 0.0 < truth["effective_restitution"] < 1.0 and truth["landings_per_turn"] > 1
    d = labtool.process(h5)
    assert abs(d.attrs["cam_speed_rpm"] - 300.0) < 1.0 and "backlash_mm" not in d.attrs
    assert int(d.attrs["n_revolutions_averaged"]) >= 5
    # the stand's motion, measured: omega2's peak within 3 % of the kinematic one (the cam's law)
    from labtool.models.mechanism.kinematics import analyze
    peak = float(np.abs(analyze(rpm=300.0)["omega2"]).max())
    assert float(np.abs(d["omega2_mean"]).max()) == pytest.approx(peak, rel=0.03)
