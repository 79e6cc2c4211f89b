"""The rigid model's coefficients for the peer solvers: labtool's plant tables, flattened.

The one place where a peer touches labtool's dynamics code: ``models.dynamics.rigid.build_plant``
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
    from models.dynamics.rigid import PRESETS, build_plant, interp, simulated_span

    span = simulated_span(scene)
    P, _ = build_plant(scene, phi1_hi=span)
    omega1_0 = scene.omega1_nominal if P.const else (P.m0 + float(interp(P.tab1, 0.0)[6])) / P.m1
    header = np.zeros(20)
    header[2:12] = [P.phi20, P.jt, P.Jcam, P.inv_Jcam, 1.0 if P.const else 0.0, P.m0, P.m1, P.Fu, P.j, P.k]
    tables = [(np.asarray(t.nodes, float), np.asarray(t.inv_h, float), np.asarray(t.coef, float))
              for t in (P.tab1, P.tab2)]
    if t_out is None:     # labtool's standard sampling, on the rise duration at the start speed
        t_out = np.linspace(0.0, scene.program.rise_angle / omega1_0, 4001)[:-1]
    return RigidProblem(header, tables, P.j, omega1_0, span, PRESETS["standard"]["v_settle"],
                        np.ascontiguousarray(t_out, dtype=float))
