"""The arrays of one processing window, allocated once for the longest window and reused.

Allocated per window, pass 2's arrays would be some 25 MB of fresh memory each time (the Ka-scaled
channels, the filter's extension, the chain's outputs, ...); glibc hands allocations that large back
to the kernel on free, so each window would pay page faults again: 0.4 s of system time on a 1-hour
recording. Here they are made once (about 20 MB for the default 2^17-sample chunks) and every
kernel writes into views of them, as nidaqmx's stream readers read into preallocated arrays.
"""
from __future__ import annotations

import numpy as np


class Workspace:
    """Buffers for windows of up to ``n`` samples (2 channels, zero-phase padding ``padlen``)."""

    def __init__(self, n: int, padlen: int, n_channels: int, raw_dtype):
        self.n = n
        self.block = np.empty((n, n_channels), dtype=raw_dtype)   # the samples as read
        self.phys = np.empty((n, 2))                               # Ka-scaled aE_t, aE_n (m/s^2)
        self.clipped = np.empty(n, dtype=np.bool_)
        self.ext = np.empty((2, n + 2 * padlen, 2))                # zero-phase filter's scratch (kernels.sosfiltfilt_into)
        self.lp = np.empty((n, 2))                                 # low-passed
        self.phi1 = np.empty(n)
        self.rev = np.empty(n, dtype=np.int64)
        self.acc = np.empty((n, 2))
        self.moving = np.empty(n, dtype=np.bool_)
        self.bad = np.empty(n, dtype=np.bool_)
        self.eps = np.empty(n)
        self.omega = np.empty(n)
        self.absn = np.empty(n)
        self.starts = np.empty(n // 2 + 1, dtype=np.int64)        # run boundaries (scratch)
        self.stops = np.empty(n // 2 + 1, dtype=np.int64)
        self.mag = np.empty(n)                                     # spike detection's scratch

    def window(self, m: int) -> dict:
        """Views of the first m samples of every per-sample buffer."""
        return {k: v[:m] for k, v in vars(self).items() if isinstance(v, np.ndarray) and k not in ("ext",)}
