"""Compiled (numba, ``cache=True``) integration loops of the dynamic models.

``dopri5``: Dormand-Prince 5(4) helpers (scipy RK45's coefficients, controller and dense output);
``elastic_nb``, ``rigid_nb``: drop-in twins of ``labtool.models.dynamics.elastic.integrate`` and
``labtool.models.dynamics.rigid.integrate``. The scipy ``solve_ivp`` loops in the model modules stay the
independent reference (``accuracy="reference"``, DOP853). ``labtool.models.dynamics.accuracy`` says which runs where.
"""
