"""The rigid model's coefficients for the peer solvers: labtool's plant tables, flattened.

The one place where a peer touches labtool's dynamics code: ``labtool.models.dynamics.rigid.build_plant``
gives the model's piecewise-cubic tables of the mechanism (functions of phi1 and of phi2) and its
numbers (J', motor line, load, backlash, restitution). The equations, events, impacts and the
integration are the peers' own (``rigid_solvers``). If the plant's layout changes, only this
module follows it.
"""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class RigidProblem:
    header: np.ndarray      # the numbers (mode and flank slots first)
    tables: list            # (nodes, inv_h, coef) of the phi1 and the phi2 table
    j: float
    omega1_0: float         # rad/s at phi1 = 0
    phi1_end: float         # rad
    v_settle: float         # m/s
    t_out: np.ndarray       # s

    def data(self, j: float) -> np.ndarray:
        """[mode, flank, phi20, jt, J', 1/J', const, m0, m1, Fu, j, k, (n, nodes, inv_h, coef offsets) x 2, tables]."""
        head = self.header.copy()
        head[10] = j
        parts, offsets, pos = [], [], 20
        for nodes, inv_h, coef in self.tables:
            offsets += [nodes.size, pos, pos + nodes.size, pos + 2 * nodes.size - 1]
            parts += [nodes, inv_h, coef.ravel()]
            pos += nodes.size + inv_h.size + coef.size
        head[12:20] = offsets
        return np.ascontiguousarray(np.concatenate([head] + parts))


def build(scene, t_out=None) -> RigidProblem:
    import math

    from labtool.models.dynamics import rigid
    from labtool.models.dynamics.rigid_tables import cam_table, follower_table

    span = rigid.simulated_span(scene)
    m, info = rigid.build_model(scene)
    omega1_0 = rigid.start_speed(scene, m)
    header = np.zeros(20)
    header[2:12] = [m.phi20, m.jt, m.Jcam, m.inv_Jcam, 1.0 if m.const else 0.0, m.m0, m.m1, m.Fu, m.j, m.k]
    mech, program = scene.mechanism, scene.program
    lo2, hi2 = mech.phiD + mech.psi0 - 0.05, mech.phiD + mech.psi0 + program.stroke + 0.05
    # the model's tables (the same nodes and cubics as its packed ones), unpacked for the peers
    tabs = (cam_table(mech, program, info["sense"], -0.05, span + 0.2), follower_table(mech, lo2, hi2))
    tables = [(np.asarray(t.nodes, float), np.asarray(t.inv_h, float), np.asarray(t.coef, float)) for t in tabs]
    if t_out is None:     # labtool's standard sampling, on the rise duration at the start speed
        t_out = np.linspace(0.0, scene.program.rise_angle / omega1_0, 4001)[:-1]
    # the peers settle an impact below a fixed speed (labtool's rule is the contact's deformation,
    # labtool.models.dynamics.kernels.rigid_nb.settles; no Table 1 impact settles under either)
    return RigidProblem(header, tables, m.j, omega1_0, span, V_SETTLE, np.ascontiguousarray(t_out, dtype=float))


V_SETTLE = 1e-6    # m/s, the former standard preset's grazing speed
