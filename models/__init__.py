"""Mechanism geometry, motion laws, kinematics, rigid and elastic dynamic models, DOE/ANOVA.

Imports none of labtool's other layers.
"""
