"""Execution of many independent computations (sweeps, designs, scans): chunks of items on this
process, local worker processes or a Dask cluster, results streamed to disk and resumable.

A layer above ``models`` (which must not import it) and beside ``acquisition``/``processing``:
the physics stays pure (``labtool.models.study.doe.Design.row`` simulates one run); what runs where, in
which chunks, and how the results reach the disk is decided here. ``labtool`` (and any layer above)
uses :func:`labtool.execution.chunked.map_chunked` for a pure function over a list of items and
:func:`labtool.execution.design.run_design` for a factorial design.
"""
