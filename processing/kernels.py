"""Compiled (numba) chunk kernels: the per-sample work of the chain fused into few passes.

Each kernel computes exactly what the pure numpy/scipy functions of filters.py, cam_angle.py and
follower.py compute (tests/test_proc_kernels.py compares them on the same input); those functions
stay the readable definition, these are the fast path the pipeline runs. Why: the numpy chain
makes a dozen full-size temporaries per chunk and sosfiltfilt pads and copies; here one window is
filtered forward-backward in place and turned into epsilon2, omega2 and the normal-axis check in
three loops.

Everything here is self-contained (no numba function from another module, no module constant read
at compile time from elsewhere), so numba's on-disk cache, keyed on this file, cannot serve stale
code after an edit of another file.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

TWO_PI = 2.0 * math.pi


@nb.njit(cache=True, nogil=True)
def _sos_pass(sos, zi, x, out, reverse):
    """Direct-form-II-transposed SOS pass over the columns of ``x`` (m, nch) into ``out``, all
    channels per sample (independent recursions side by side), initial state zi * first sample."""
    ns = sos.shape[0]
    m, nch = x.shape
    z = np.empty((nch, ns, 2))
    i0 = m - 1 if reverse else 0
    for c in range(nch):
        for s in range(ns):
            z[c, s, 0] = zi[s, 0] * x[i0, c]
            z[c, s, 1] = zi[s, 1] * x[i0, c]
    for t in range(m):
        i = m - 1 - t if reverse else t
        for c in range(nch):
            v = x[i, c]
            for s in range(ns):
                y = sos[s, 0] * v + z[c, s, 0]
                z[c, s, 0] = sos[s, 1] * v - sos[s, 4] * y + z[c, s, 1]
                z[c, s, 1] = sos[s, 2] * v - sos[s, 5] * y
                v = y
            out[i, c] = v


@nb.njit(cache=True, nogil=True)
def sosfiltfilt(sos, zi, x, padlen):
    """scipy.signal.sosfiltfilt(sos, x, axis=0, padtype='odd', padlen=padlen) for x (n, nch).

    zi: scipy.signal.sosfilt_zi(sos), the steady state for a unit step, shape (n_sections, 2).
    """
    n, nch = x.shape
    m = n + 2 * padlen
    ext = np.empty((m, nch))
    fwd = np.empty((m, nch))
    for c in range(nch):
        x0, x1 = x[0, c], x[n - 1, c]
        for k in range(padlen):  # odd extension at both ends
            ext[k, c] = 2.0 * x0 - x[padlen - k, c]
            ext[padlen + n + k, c] = 2.0 * x1 - x[n - 2 - k, c]
    ext[padlen:padlen + n] = x
    _sos_pass(sos, zi, ext, fwd, False)
    _sos_pass(sos, zi, fwd, ext, True)
    return ext[padlen:padlen + n].copy()


@nb.njit(cache=True, nogil=True)
def residual(phys, lp, valid):
    """(phys - lp) where valid, else 0: the content above the processing band, per channel (n, nch)."""
    n, nch = phys.shape
    out = np.zeros((n, nch))
    for i in range(n):
        if valid[i]:
            for c in range(nch):
                out[i, c] = phys[i, c] - lp[i, c]
    return out


@nb.njit(cache=True, nogil=True)
def phi1_from_marks(first, n, marks, fallback_period):
    """cam_angle.phi1_from_marks for the contiguous samples first..first+n-1: (phi1 rad, revolution)."""
    nm = marks.shape[0]
    phi1 = np.empty(n)
    rev = np.empty(n, np.int64)
    if nm >= 2:
        p_first, p_last = marks[1] - marks[0], marks[nm - 1] - marks[nm - 2]
    else:
        p_first = p_last = fallback_period
    k = -1
    for i in range(n):
        idx = float(first + i)
        while k + 1 < nm and marks[k + 1] <= idx:
            k += 1
        if k < 0:
            origin, per = marks[0], p_first
        elif k < nm - 1:
            origin, per = marks[k], marks[k + 1] - marks[k]
        else:
            origin, per = marks[nm - 1], p_last
        a = (idx - origin) * (TWO_PI / per)
        phi1[i] = a - TWO_PI * math.floor(a / TWO_PI)
        rev[i] = k
    return phi1, rev


@nb.njit(cache=True, nogil=True)
def _runs(mask):
    """[start, stop) of every run of True: (starts, stops)."""
    n = mask.shape[0]
    starts = np.empty(n // 2 + 1, np.int64)
    stops = np.empty(n // 2 + 1, np.int64)
    r = 0
    i = 0
    while i < n:
        if mask[i]:
            j = i
            while j < n and mask[j]:
                j += 1
            starts[r], stops[r] = i, j
            r += 1
            i = j
        else:
            i += 1
    return starts[:r], stops[:r]


@nb.njit(cache=True, nogil=True)
def _subtract_dwell_baseline(acc, moving, middle, min_len):
    """follower.dwell_baseline(acc, ~moving, middle, min_len), subtracted from acc in place."""
    n, nch = acc.shape
    st, sp = _runs(~moving)
    full = (st > 0) & (sp < n) & (sp - st >= min_len)
    use = full if full.any() else (sp - st >= min_len)
    st, sp = st[use], sp[use]
    nr = st.shape[0]
    if nr == 0:
        for c in range(nch):
            acc[:, c] -= acc[:, c].mean()
        return
    centres = 0.5 * (st + sp - 1)
    levels = np.empty((nr, nch))
    for r in range(nr):
        cut = int((sp[r] - st[r]) * (1.0 - middle) / 2.0)
        lo, hi = st[r] + cut, sp[r] - cut
        for c in range(nch):
            s = 0.0
            for i in range(lo, hi):
                s += acc[i, c]
            levels[r, c] = s / (hi - lo)
    r = 0
    for i in range(n):  # np.interp: constant beyond the first and last centre
        while r + 1 < nr and centres[r + 1] <= i:
            r += 1
        for c in range(nch):
            if i <= centres[0]:
                b = levels[0, c]
            elif r >= nr - 1:
                b = levels[nr - 1, c]
            else:
                w = (i - centres[r]) / (centres[r + 1] - centres[r])
                b = levels[r, c] + w * (levels[r + 1, c] - levels[r, c])
            acc[i, c] -= b


@nb.njit(cache=True, nogil=True)
def _integrate_motion(eps, moving, bad, fs, margin, out):
    """follower.integrate_motion(nan_to_num(eps), moving, fs, margin, bad) into ``out`` (zeros)."""
    n = eps.shape[0]
    st, sp = _runs(moving)
    nr = st.shape[0]
    a0 = np.maximum(st - margin, 0)
    b0 = np.minimum(sp + margin, n)
    for r in range(nr - 1):  # widened runs may meet: each keeps its samples up to the midpoint
        mid = (sp[r] + st[r + 1]) // 2
        b0[r] = min(b0[r], mid)
        a0[r + 1] = max(a0[r + 1], mid)
    for r in range(nr):
        lo, hi = a0[r], b0[r]
        ok = st[r] > 0 and sp[r] < n and lo > 0 and hi < n
        for i in range(lo, hi):
            if bad[i]:
                ok = False
        if not ok:
            for i in range(lo, hi):
                out[i] = np.nan
            continue
        c = 0.0
        out[lo] = 0.0
        for i in range(lo + 1, hi):
            c += 0.5 * (eps[i] + eps[i - 1]) / fs
            out[i] = c
        end, span = c, max(hi - 1 - lo, 1)
        for i in range(lo, hi):
            out[i] -= (i - lo) / span * end


@nb.njit(cache=True, nogil=True)
def follower_chain(lp, phi1, rev, irregular, clipped, gravity, moving_table, DE, fs, middle, min_len, margin):
    """The chain after the low-pass, on one window (pipeline._process_window's definition).

    lp (n, 2) low-passed aE_t, aE_n (m/s^2); phi1 (n,) rad (set to NaN in irregular revolutions);
    gravity (N, 2) and moving_table (N,) tabulated over one revolution. Returns (acc (n, 2) with
    gravity and dwell reference removed, epsilon2, omega2, |omega2| from aE_n, moving), NaN at the
    bad samples (clipped, or in an irregular revolution).
    """
    n = lp.shape[0]
    N = gravity.shape[0]
    acc = np.empty((n, 2))
    moving = np.empty(n, np.bool_)
    scale = N / TWO_PI
    for i in range(n):
        k = int(phi1[i] * scale + 0.5) & (N - 1)
        acc[i, 0] = lp[i, 0] - gravity[k, 0]
        acc[i, 1] = lp[i, 1] - gravity[k, 1]
        moving[i] = moving_table[k]
    _subtract_dwell_baseline(acc, moving, middle, min_len)
    nirr = irregular.shape[0]
    bad = clipped.copy()
    eps = np.empty(n)
    for i in range(n):
        r = rev[i]
        if r >= 0 and r < nirr and irregular[r] and not clipped[i]:
            bad[i] = True
            phi1[i] = np.nan
        if bad[i]:
            acc[i, 0] = np.nan
            acc[i, 1] = np.nan
            eps[i] = 0.0
        else:
            eps[i] = acc[i, 0] / DE
    omega = np.zeros(n)
    _integrate_motion(eps, moving, bad, fs, margin, omega)
    absn = np.empty(n)
    for i in range(n):
        if bad[i]:
            eps[i] = np.nan
            omega[i] = np.nan
            absn[i] = np.nan
        else:
            absn[i] = math.sqrt(max(acc[i, 1], 0.0) / DE)
    return acc, eps, omega, absn, moving


@nb.njit(cache=True, nogil=True)
def clip_mask(volts, lo, hi, rail, min_run):
    """pipeline._clipped without the recorder's events: |v| >= rail (rail <= 0: none), or runs of
    >= min_run samples at a channel's extreme value (lo, hi per channel)."""
    n, nch = volts.shape
    out = np.zeros(n, np.bool_)
    if rail > 0:
        for i in range(n):
            for c in range(nch):
                if abs(volts[i, c]) >= rail:
                    out[i] = True
    for c in range(nch):
        if not hi[c] > lo[c]:
            continue
        i = 0
        while i < n:
            v = volts[i, c]
            if v == hi[c] or v == lo[c]:
                j = i
                while j < n and (volts[j, c] == hi[c] or volts[j, c] == lo[c]):
                    j += 1
                if j - i >= min_run:
                    out[i:j] = True
                i = j
            else:
                i += 1
    return out


@nb.njit(cache=True, nogil=True)
def extremes(block, vmin, vmax):
    """Per-channel running min and max over a (n, nch) block, updated in place."""
    n, nch = block.shape
    for i in range(n):
        for c in range(nch):
            v = block[i, c]
            if v < vmin[c]:
                vmin[c] = v
            if v > vmax[c]:
                vmax[c] = v
