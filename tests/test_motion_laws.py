"""Motion laws: closed-form peak coefficients, boundary conditions, derivatives by finite differences."""
import dataclasses
import math

import numpy as np
import pytest

from labtool.common.errors import InputError
from labtool.models.mechanism.motion_laws import LAWS, CamProgram, get_law

U = np.linspace(0.0, 1.0, 400001)

# (Cv, Ca, Cj): peak |s'|, |s''|, |s'''| of the normalized laws, from the cam-design literature
PEAKS = {
    "sine": (2.0, 2 * math.pi, 4 * math.pi**2),
    "cosine": (math.pi / 2, math.pi**2 / 2, math.pi**3 / 2),
    "poly345": (1.875, 5.7735, 60.0),
    "poly4567": (2.1875, 7.5132, 52.5),
    "modtrap": (2.0, 4.8881, 61.426),
    "modsine": (1.7596, 5.5280, 69.466),
}


@pytest.mark.parametrize("name", sorted(PEAKS))
def test_peak_coefficients(name):
    s, v, a, j = LAWS[name](U)
    cv, ca, cj = PEAKS[name]
    assert np.max(np.abs(v)) == pytest.approx(cv, rel=2e-4)
    assert np.max(np.abs(a)) == pytest.approx(ca, rel=2e-4)
    assert np.max(np.abs(j)) == pytest.approx(cj, rel=2e-4)


@pytest.mark.parametrize("name", sorted(LAWS))
def test_boundary_conditions(name):
    s, v, a, _ = LAWS[name](np.array([0.0, 1.0]))
    assert s[0] == pytest.approx(0.0, abs=1e-12) and s[1] == pytest.approx(1.0, abs=1e-12)
    assert v[0] == pytest.approx(0.0, abs=1e-12) and v[1] == pytest.approx(0.0, abs=1e-12)
    if name not in ("cosine",):  # the harmonic law has acceleration steps at its ends
        assert a[0] == pytest.approx(0.0, abs=1e-9) and a[1] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("name", sorted(LAWS))
def test_derivatives_match_finite_differences(name):
    u = np.linspace(0.01, 0.99, 97)
    h = 1e-6
    f = LAWS[name]
    for order in range(3):
        numeric = (f(u + h)[order] - f(u - h)[order]) / (2 * h)
        exact = f(u)[order + 1]
        scale = max(1.0, np.max(np.abs(exact)))
        # jerk of the piecewise laws jumps at the piece edges; skip points within h of an edge
        ok = np.ones_like(u, dtype=bool)
        for edge in (0.125, 0.375, 0.625, 0.875):
            ok &= np.abs(u - edge) > 2 * h
        assert np.max(np.abs(numeric - exact)[ok]) < 1e-5 * scale


def test_program_is_continuous_and_periodic():
    prog = CamProgram.rise_dwell_return_dwell("sine", math.radians(15), math.radians(58))
    phi = np.linspace(0, 4 * math.pi, 20001)
    psi, dpsi, ddpsi, _ = prog(phi)
    assert np.max(np.abs(np.diff(psi))) < 1e-3
    assert psi.max() == pytest.approx(math.radians(15))
    np.testing.assert_allclose(prog(phi[:100] + 2 * math.pi)[0], prog(phi[:100])[0], atol=1e-12)
    # numerical derivative of psi equals dpsi away from the segment edges
    num = np.gradient(psi, phi)
    assert np.max(np.abs(num - dpsi)) < 1e-3


def test_program_direction_and_peak_follower_rate():
    prog = CamProgram.rise_dwell_return_dwell("sine", math.radians(15), math.radians(58))
    assert prog.direction(math.radians(10)) == 1.0
    assert prog.direction(math.radians(100)) == 0.0
    assert prog.direction(math.radians(200)) == -1.0
    # cycloidal: peak dpsi/dphi1 = 2 psi_a / phi_u
    _, dpsi, _, _ = prog(np.linspace(0, math.radians(58), 10001))
    assert dpsi.max() == pytest.approx(2 * math.radians(15) / math.radians(58), rel=1e-6)


def test_unknown_law_names_the_known_ones():
    with pytest.raises(InputError, match="known laws: sine, cosine"):
        get_law("parabolic")


@pytest.mark.parametrize("kw", [dict(rise=0.0), dict(rise=math.radians(200), ret=math.radians(200)), dict(stroke=-0.1)])
def test_impossible_programs_are_rejected(kw):
    args = dict(law="sine", stroke=math.radians(15), rise=math.radians(58))
    args.update(kw)
    with pytest.raises(InputError):
        CamProgram.rise_dwell_return_dwell(**args)


def test_a_program_keeps_its_hash_but_does_not_pickle_it():
    import pickle

    from labtool.models.study.paper import paper_scene
    program = paper_scene(law="cosine").program
    assert paper_scene(law="cosine").program is program            # one per mechanism and law: found by identity
    h = hash(program)
    assert hash(program) == h == hash(dataclasses.replace(program))
    copy = pickle.loads(pickle.dumps(program))
    assert "_hash" not in copy.__dict__ and copy == program and hash(copy) == h


@pytest.mark.parametrize("law", ["sine", "cosine", "modtrap"])
def test_a_program_gives_each_angle_the_same_value_alone_or_among_others(law):
    # an array within one segment is evaluated without masks, a mixed one through them: the
    # values must not depend on the company an angle keeps (edges, their neighbours, NaN)
    prog = CamProgram.rise_dwell_return_dwell(law, rise=math.radians(70), ret=math.radians(100), upper_dwell=0.3)
    edges = np.cumsum([0.0] + [s.beta for s in prog.segments])
    phi = np.concatenate([edges, np.nextafter(edges, -1), np.nextafter(edges, 9),
                          np.random.default_rng(3).uniform(-7, 14, 200), [np.nan, 2 * math.pi]])
    together = np.array(prog(phi))
    alone = np.array([np.array(prog(np.array([p]))).ravel() for p in phi]).T
    np.testing.assert_array_equal(together, alone)
    np.testing.assert_array_equal(prog.direction(phi), [prog.direction(np.array([p]))[0] for p in phi])
