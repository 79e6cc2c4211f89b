"""The mechanism and its kinematics: parameters, motion laws, linkage, cam profile, cam-angle tables.

``Mechanism`` (the STB-216 parameters) is re-exported here because every layer names it.
"""
from labtool.models.mechanism.parameters import Mechanism

__all__ = ["Mechanism"]
