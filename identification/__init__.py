"""Model identification from a measurement (``labtool fit``; docs/identification.md).

The parameters nobody reads off a drawing (the groove's backlash j, the impacts' restitution k, the
contact damping and length, the chain's true Ka and delay) are found by least squares of a model's
cycle statistics against the measured ones, with 95 % intervals, the correlation matrix, profiles
of the objective and a verdict on what this measurement can identify.

Layer: above ``reports`` (it reuses the report's alignment, conditioning, metrics and events) and
below ``labtool``; nothing else imports it (tests/test_layers.py).

Modules: ``parameters`` (what can be free, bounds and units), ``objective`` (the measurement side,
computed once, and the cached model evaluations), ``search`` (coarse scan and bounded least
squares), ``uncertainty`` (intervals, correlation, profiles, identifiability), ``fit`` (the driver
and its JSON), ``figures``.
"""
