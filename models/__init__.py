"""The physics: ``mechanism`` (geometry, motion laws, kinematics), ``dynamics`` (rigid and elastic
models and their solvers) and ``study`` (the paper's DOE, ANOVA and table comparisons).

Imports only the bottom layer ``common``; none of labtool's other layers.
"""
