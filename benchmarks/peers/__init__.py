"""Peer solvers for the benchmarks: the same equations as labtool, written independently."""
