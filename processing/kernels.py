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

import numpy as np

from labtool.models.dynamics.jit import jit

TWO_PI = 2.0 * math.pi


@jit(nogil=True)
def sos_pass_state(sos, z, x, out, reverse):
    """Direct-form-II-transposed SOS pass over the columns of ``x`` (m, nch) into ``out``, all
    channels per sample (independent recursions side by side), from the state z (nch, ns, 2),
    which is left as the state after the last sample (scipy.signal.sosfilt with zi)."""
    ns = sos.shape[0]
    m, nch = x.shape
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


@jit(nogil=True)
def _sos_pass_2x2(sos, zi, x, mid, pad, out, reverse, skip=0):
    """sos_pass_state for 2 sections and 2 channels (order 4, aE_t and aE_n: the chain's case)
    with the eight state values in registers; the same operations in the same order (2.4x faster).

    The input is x (m, 2), except rows pad .. pad + len(mid) - 1 taken from ``mid`` when pad >= 0
    (the zero-phase extension's middle, not copied); output rows skip .. m - skip - 1 are written,
    to out[i - skip] (the backward pass keeps only the middle).
    """
    m = x.shape[0]
    nmid = mid.shape[0] if pad >= 0 else 0
    i0 = m - 1 if reverse else 0
    b00, b01, b02, a01, a02 = sos[0, 0], sos[0, 1], sos[0, 2], sos[0, 4], sos[0, 5]
    b10, b11, b12, a11, a12 = sos[1, 0], sos[1, 1], sos[1, 2], sos[1, 4], sos[1, 5]
    u, w = (mid[i0 - pad, 0], mid[i0 - pad, 1]) if pad <= i0 < pad + nmid else (x[i0, 0], x[i0, 1])
    p00, p01, p10, p11 = zi[0, 0] * u, zi[0, 1] * u, zi[1, 0] * u, zi[1, 1] * u
    q00, q01, q10, q11 = zi[0, 0] * w, zi[0, 1] * w, zi[1, 0] * w, zi[1, 1] * w
    for t in range(m):
        i = m - 1 - t if reverse else t
        if pad <= i < pad + nmid:
            u, w = mid[i - pad, 0], mid[i - pad, 1]
        else:
            u, w = x[i, 0], x[i, 1]
        y = b00 * u + p00
        p00 = b01 * u - a01 * y + p01
        p01 = b02 * u - a02 * y
        v = y
        y = b10 * v + p10
        p10 = b11 * v - a11 * y + p11
        p11 = b12 * v - a12 * y
        yu = y
        y = b00 * w + q00
        q00 = b01 * w - a01 * y + q01
        q01 = b02 * w - a02 * y
        v = y
        y = b10 * v + q10
        q10 = b11 * v - a11 * y + q11
        q11 = b12 * v - a12 * y
        if skip <= i < m - skip:
            out[i - skip, 0] = yu
            out[i - skip, 1] = y


@jit(nogil=True)
def _sos_pass(sos, zi, x, out, reverse):
    """sos_pass_state from the steady state of the first sample in the pass's direction (zi * x0)."""
    ns = sos.shape[0]
    m, nch = x.shape
    z = np.empty((nch, ns, 2))
    i0 = m - 1 if reverse else 0
    for c in range(nch):
        for s in range(ns):
            z[c, s, 0] = zi[s, 0] * x[i0, c]
            z[c, s, 1] = zi[s, 1] * x[i0, c]
    sos_pass_state(sos, z, x, out, reverse)


def sosfiltfilt_into(sos, zi, x, padlen, ext, out):
    """scipy.signal.sosfiltfilt(sos, x, axis=0, padtype='odd', padlen=padlen) for x (n, nch) into
    ``out`` (n, nch); ``ext`` (2, >= n + 2 padlen, nch) scratch. zi: sosfilt_zi(sos) (n_sections, 2).

    Two compiled kernels, chosen here: the chain's case (2 sections, 2 channels, ``_filtfilt_2x2``)
    and any other (``_filtfilt_any``), so that a process compiles the one it runs."""
    if sos.shape[0] == 2 and x.shape[1] == 2:
        _filtfilt_2x2(sos, zi, x, padlen, ext, out)
    else:
        _filtfilt_any(sos, zi, x, padlen, ext, out)


@jit(nogil=True)
def _odd_extension(x, padlen, e):
    """e[:n + 2 padlen] = x with its odd extension of padlen samples at both ends (the middle
    rows left as they are: the caller writes or reads them itself)."""
    n, nch = x.shape
    for c in range(nch):
        x0, x1 = x[0, c], x[n - 1, c]
        for k in range(padlen):
            e[k, c] = 2.0 * x0 - x[padlen - k, c]
            e[padlen + n + k, c] = 2.0 * x1 - x[n - 2 - k, c]


@jit(nogil=True)
def _filtfilt_2x2(sos, zi, x, padlen, ext, out):
    """sosfiltfilt_into for 2 sections and 2 channels: the middle read from x and written to out,
    not copied (``_sos_pass_2x2``)."""
    m = x.shape[0] + 2 * padlen
    e, f = ext[0, :m], ext[1, :m]
    _odd_extension(x, padlen, e)
    _sos_pass_2x2(sos, zi, e, x, padlen, f, False, 0)
    _sos_pass_2x2(sos, zi, f, f, -1, out, True, padlen)


@jit(nogil=True)
def _filtfilt_any(sos, zi, x, padlen, ext, out):
    """sosfiltfilt_into for any number of sections and channels (element loops: a slice copy
    compiles numba's shape checks and their messages, a second or more of a first run)."""
    n, nch = x.shape
    m = n + 2 * padlen
    e, f = ext[0, :m], ext[1, :m]
    _odd_extension(x, padlen, e)
    for i in range(n):
        for c in range(nch):
            e[padlen + i, c] = x[i, c]
    _sos_pass(sos, zi, e, f, False)
    _sos_pass(sos, zi, f, e, True)
    for i in range(n):
        for c in range(nch):
            out[i, c] = e[padlen + i, c]


def sosfiltfilt(sos, zi, x, padlen):
    """sosfiltfilt_into with its own arrays."""
    n, nch = x.shape
    out = np.empty((n, nch))
    sosfiltfilt_into(sos, zi, x, padlen, np.empty((2, n + 2 * padlen, nch)), out)
    return out


@jit(nogil=True)
def phi1_from_marks_into(first, n, marks, fallback_period, phi1, rev):
    """cam_angle.phi1_from_marks for the contiguous samples first..first+n-1 into phi1 (rad) and
    rev (revolution index, int64)."""
    nm = marks.shape[0]
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


@jit(nogil=True)
def phi1_from_marks(first, n, marks, fallback_period):
    """phi1_from_marks_into with its own arrays: (phi1 rad, revolution)."""
    phi1 = np.empty(n)
    rev = np.empty(n, np.int64)
    phi1_from_marks_into(first, n, marks, fallback_period, phi1, rev)
    return phi1, rev


@jit(nogil=True)
def _runs(mask, value, starts, stops):
    """[start, stop) of every run of mask == value: (starts, stops), views of the scratch arrays
    ``starts``, ``stops`` (>= n // 2 + 1 each)."""
    n = mask.shape[0]
    r = 0
    i = 0
    while i < n:
        if mask[i] == value:
            j = i
            while j < n and mask[j] == value:
                j += 1
            starts[r], stops[r] = i, j
            r += 1
            i = j
        else:
            i += 1
    return starts[:r], stops[:r]


@jit(nogil=True)
def _subtract_dwell_baseline(acc, moving, middle, min_len, starts, stops):
    """follower.dwell_baseline(acc, ~moving, middle, min_len), subtracted from acc in place."""
    n, nch = acc.shape
    st, sp = _runs(moving, False, starts, stops)
    # the dwells long enough, inside the window if any is (element loops, not numpy's masks: their
    # broadcasting checks compile numba's error messages, ~1 s of a first run)
    inside = False
    for r in range(st.shape[0]):
        inside = inside or (st[r] > 0 and sp[r] < n and sp[r] - st[r] >= min_len)
    nr = 0
    for r in range(st.shape[0]):
        if sp[r] - st[r] >= min_len and (not inside or (st[r] > 0 and sp[r] < n)):
            st[nr], sp[nr] = st[r], sp[r]           # in place: the kept runs keep their order
            nr += 1
    if nr == 0:
        for c in range(nch):
            mean = acc[:, c].mean()
            for i in range(n):
                acc[i, c] -= mean
        return
    centres = np.empty(nr)
    for r in range(nr):
        centres[r] = 0.5 * (st[r] + sp[r] - 1)
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


@jit(nogil=True)
def _integrate_motion(eps, moving, bad, fs, margin, out, starts, stops):
    """follower.integrate_motion(nan_to_num(eps), moving, fs, margin, bad) into ``out`` (zeros)."""
    n = eps.shape[0]
    st, sp = _runs(moving, True, starts, stops)
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


@jit(nogil=True)
def follower_chain_into(lp, phi1, rev, irregular, clipped, gravity, moving_table, DE, fs, middle, min_len, margin,
                        acc, moving, bad, eps, omega, absn, starts, stops):
    """The chain after the low-pass, on one window (pipeline._process_window's definition).

    lp (n, 2) low-passed aE_t, aE_n (m/s^2); phi1 (n,) rad (set to NaN in irregular revolutions);
    gravity (N, 2) and moving_table (N,) tabulated over one revolution. Fills acc (n, 2) with
    gravity and dwell reference removed, moving, bad, epsilon2, omega2 and |omega2| from aE_n, NaN
    at the bad samples (clipped, or in an irregular revolution); starts, stops (>= n // 2 + 1) scratch.
    """
    n = lp.shape[0]
    N = gravity.shape[0]
    scale = N / TWO_PI
    for i in range(n):
        k = int(phi1[i] * scale + 0.5) & (N - 1)
        acc[i, 0] = lp[i, 0] - gravity[k, 0]
        acc[i, 1] = lp[i, 1] - gravity[k, 1]
        moving[i] = moving_table[k]
    _subtract_dwell_baseline(acc, moving, middle, min_len, starts, stops)
    nirr = irregular.shape[0]
    for i in range(n):
        r = rev[i]
        bad[i] = clipped[i]
        if r >= 0 and r < nirr and irregular[r] and not clipped[i]:
            bad[i] = True
            phi1[i] = np.nan
        if bad[i]:
            acc[i, 0] = np.nan
            acc[i, 1] = np.nan
            eps[i] = 0.0
        else:
            eps[i] = acc[i, 0] / DE      # sensor_point.epsilon2_from_tangential, inline: compiled loop
        omega[i] = 0.0
    _integrate_motion(eps, moving, bad, fs, margin, omega, starts, stops)
    for i in range(n):
        if bad[i]:
            eps[i] = np.nan
            omega[i] = np.nan
            absn[i] = np.nan
        else:
            absn[i] = math.sqrt(max(acc[i, 1], 0.0) / DE)   # sensor_point.omega2_abs_from_normal


@jit(nogil=True)
def follower_chain(lp, phi1, rev, irregular, clipped, gravity, moving_table, DE, fs, middle, min_len, margin):
    """follower_chain_into with its own arrays: (acc, epsilon2, omega2, |omega2| from aE_n, moving)."""
    n = lp.shape[0]
    acc, eps, omega, absn = np.empty((n, 2)), np.empty(n), np.empty(n), np.empty(n)
    moving, bad = np.empty(n, np.bool_), np.empty(n, np.bool_)
    starts, stops = np.empty(n // 2 + 1, np.int64), np.empty(n // 2 + 1, np.int64)
    follower_chain_into(lp, phi1, rev, irregular, clipped, gravity, moving_table, DE, fs, middle, min_len, margin,
                        acc, moving, bad, eps, omega, absn, starts, stops)
    return acc, eps, omega, absn, moving


@jit(nogil=True)
def clip_mask(block, cols, lo, hi, rail, min_run, min_drop, out):
    """pipeline._clipped without the recorder's events, on the columns ``cols`` of ``block`` (n, nch)
    (any float dtype), into out (n,) bool: |v| >= rail (rail <= 0: none), or runs of >= min_run
    samples at a channel's extreme value (lo, hi per selected channel) entered or left by a step of
    at least ``min_drop`` volts (or at the block's edge): a quantised smooth peak holds its top level
    for a few samples too, but its neighbours lie one level below, not a saturation's many."""
    n = block.shape[0]
    out[:] = False
    if rail > 0:
        for i in range(n):
            for j in range(cols.shape[0]):
                if abs(block[i, cols[j]]) >= rail:
                    out[i] = True
    for j in range(cols.shape[0]):
        c = cols[j]
        if not hi[j] > lo[j]:
            continue
        i = 0
        while i < n:
            v = block[i, c]
            if v == hi[j] or v == lo[j]:
                k = i
                while k < n and (block[k, c] == hi[j] or block[k, c] == lo[j]):
                    k += 1
                steep = (i == 0 or k == n or abs(block[i - 1, c] - v) >= min_drop
                         or abs(block[k, c] - v) >= min_drop)
                if k - i >= min_run and steep:
                    out[i:k] = True
                i = k
            else:
                i += 1


@jit(nogil=True)
def scaled_columns(block, cols, factors, out):
    """block[:, cols] * factors as float64 into out (n, len(cols)): the Ka-scaled channels of a window."""
    n = block.shape[0]
    for i in range(n):
        for j in range(cols.shape[0]):
            out[i, j] = float(block[i, cols[j]]) * factors[j]


@jit(nogil=True)
def core_outputs(acc, eps, omega, phi1, rev, absn, moving, clipped, c0, c1, rev_offset, t_first, fs,
                 out_f, out_rev, out_clip, out_time, normal):
    """The per-sample outputs of a window's core [c0, c1) in the file's types, and the normal check.

    out_f (5, >= c1 - c0) float32: aE_t, aE_n, epsilon2, omega2, phi1; out_rev int32 (revolution +
    rev_offset, -1 before the first mark); out_clip int8; out_time float64 (t_first + j) / fs
    (t_first: the core's first row plus the samples lost before it). normal (3,): the sum of
    (|omega2| - |omega2| from aE_n)^2, the count and the largest |omega2| over the finite motion
    samples (accumulators.NormalCheck.feed's sums), updated in place.
    """
    for j in range(c1 - c0):
        i = c0 + j
        out_f[0, j] = acc[i, 0]
        out_f[1, j] = acc[i, 1]
        out_f[2, j] = eps[i]
        out_f[3, j] = omega[i]
        out_f[4, j] = phi1[i]
        out_rev[j] = rev[i] + rev_offset if rev[i] >= 0 else -1
        out_clip[j] = 1 if clipped[i] else 0
        out_time[j] = (t_first + j) / fs
        w = omega[i]
        if moving[i] and np.isfinite(w):
            d = abs(w) - absn[i]
            normal[0] += d * d
            normal[1] += 1.0
            normal[2] = max(normal[2], abs(w))


@jit(nogil=True)
def resample_cycles(acc, eps, omega, absn, clipped, m0, m1, frac, rows):
    """pipeline._add_cycles' resampling, compiled: each revolution [m0[k], m1[k]) (window sample
    positions) that is free of clipped and NaN samples, interpolated linearly at m0 + frac (m1 - m0)
    (frac = grid / 2 pi), written to rows[used] (rows: (len(m0), 5, n_grid)) in the order aE_t,
    aE_n, epsilon2, omega2, |omega2| from aE_n (pipeline.CYCLE_NAMES); cycles.CycleAccumulator
    averages them. Returns (revolutions used, rejected)."""
    n = eps.shape[0]
    ng = frac.shape[0]
    used, rejected = 0, 0
    for k in range(m0.shape[0]):
        if not (m0[k] >= 0 and math.floor(m1[k]) + 1 < n):
            continue
        good = True
        for i in range(int(math.floor(m0[k])), int(math.floor(m1[k])) + 2):
            if clipped[i] or not (np.isfinite(acc[i, 0]) and np.isfinite(acc[i, 1]) and np.isfinite(eps[i])
                                  and np.isfinite(omega[i]) and np.isfinite(absn[i])):
                good = False
                break
        if not good:
            rejected += 1
            continue
        span = m1[k] - m0[k]
        for q in range(ng):
            x = m0[k] + frac[q] * span
            i0 = int(math.floor(x))
            w = x - i0
            for v in range(5):
                if v < 2:
                    y = acc[i0, v] * (1.0 - w) + acc[i0 + 1, v] * w
                elif v == 2:
                    y = eps[i0] * (1.0 - w) + eps[i0 + 1] * w
                elif v == 3:
                    y = omega[i0] * (1.0 - w) + omega[i0 + 1] * w
                else:
                    y = absn[i0] * (1.0 - w) + absn[i0 + 1] * w
                rows[used, v, q] = y
        used += 1
    return used, rejected


@jit(nogil=True)
def spikes(phys, lp, clipped, c, k_sigma, floor_fraction, distance, mag):
    """events.detect_spikes on channel c of the window's residual (phys - lp, 0 where clipped),
    compiled: (peak indices, signed residual at them, threshold); mag (>= n) scratch. The scale
    comes from every 8th sample (all of them up to 4096), the full residual is only scanned
    against the threshold."""
    n = phys.shape[0]
    step = 8 if n > 4096 else 1
    m = (n + step - 1) // step
    sub = np.empty(m)
    for j in range(m):
        i = j * step
        sub[j] = 0.0 if clipped[i] else phys[i, c] - lp[i, c]
    med = np.median(sub)
    sigma = 1.4826 * np.median(np.abs(sub - med))
    peak = 0.0
    big = 0.0  # the largest deviation, without writing anything: usually nothing reaches thr
    for i in range(n):
        a = abs(lp[i, c])
        d = abs((0.0 if clipped[i] else phys[i, c] - lp[i, c]) - med)
        peak = a if a > peak else peak
        big = d if d > big else big
    thr = max(k_sigma * sigma, floor_fraction * peak)
    none = np.empty(0, np.int64)
    if thr <= 0 or n < 3:
        return none, np.empty(0), thr
    if not big > thr:  # the usual case: nothing to look for
        return none, np.empty(0), thr
    mag = mag[:n]
    for i in range(n):
        mag[i] = abs((0.0 if clipped[i] else phys[i, c] - lp[i, c]) - med)
    pk = find_peaks(mag, thr, distance)
    amp = np.empty(pk.shape[0])
    for j in range(pk.shape[0]):
        i = pk[j]
        amp[j] = 0.0 if clipped[i] else phys[i, c] - lp[i, c]
    return pk, amp, thr


@jit(nogil=True)
def welch_accumulate(spec, means, wfft, sum_amp, sum_pow):
    """spectra.WelchAccumulator.feed after the transforms, compiled: X = spec - mean W (each
    segment's mean removed, float32 as the transforms), |X| and |X|^2 summed over the segments in
    float64 into sum_amp and sum_pow (n_freq, nch). spec (nch, nseg, n_freq) complex64."""
    nch, nseg, nf = spec.shape
    a = np.empty(nf)
    p = np.empty(nf)
    for c in range(nch):
        a[:] = 0.0
        p[:] = 0.0
        for s in range(nseg):  # the segments in order for each frequency, as numpy's sum over them
            m = means[c, s]
            for f in range(nf):
                x = spec[c, s, f] - m * wfft[f]
                re, im = float(x.real), float(x.imag)
                mag = np.float32(math.sqrt(re * re + im * im))  # hypotf, as numpy's abs of complex64
                a[f] += mag
                p[f] += mag * mag
        for f in range(nf):
            sum_amp[f, c] += a[f]
            sum_pow[f, c] += p[f]


@jit(nogil=True)
def find_peaks(x, height, distance):
    """scipy.signal.find_peaks(x, height=height, distance=distance)[0] (indices, int64).

    Local maxima (a flat top gives its middle sample, rounded down) at least ``height``; then, from
    the highest down, every peak closer than ``distance`` samples to a kept higher one is dropped.
    Equal heights are taken in the order of a stable sort (scipy's quicksort may order ties of more
    than 16 peaks otherwise).
    """
    n = x.shape[0]
    peaks = np.empty(n // 2 + 1, np.int64)
    m = 0
    i = 1
    while i < n - 1:
        if x[i - 1] < x[i]:
            ahead = i + 1
            while ahead < n - 1 and x[ahead] == x[i]:
                ahead += 1
            if x[ahead] < x[i]:
                mid = (i + ahead - 1) // 2
                if x[mid] >= height:
                    peaks[m] = mid
                    m += 1
                i = ahead
        i += 1
    peaks = peaks[:m]
    dist = int(math.ceil(distance))
    if m < 2 or dist <= 1:
        return peaks
    keep = np.ones(m, np.bool_)
    order = np.argsort(x[peaks], kind="mergesort")
    for r in range(m - 1, -1, -1):
        j = order[r]
        if not keep[j]:
            continue
        k = j - 1
        while k >= 0 and peaks[j] - peaks[k] < dist:
            keep[k] = False
            k -= 1
        k = j + 1
        while k < m and peaks[k] - peaks[j] < dist:
            keep[k] = False
            k += 1
    return peaks[keep]


@jit(nogil=True)
def scan_block(block, vmin, vmax):
    """Per-channel running min and max of a (n, nch) block, updated in place; returns the flat
    (row-major) index of the first NaN/Inf sample, or -1 (the extremes are then incomplete)."""
    n, nch = block.shape
    for i in range(n):
        for c in range(nch):
            v = block[i, c]
            if not np.isfinite(v):
                return i * nch + c
            if v < vmin[c]:
                vmin[c] = v
            if v > vmax[c]:
                vmax[c] = v
    return -1


@jit(nogil=True)
def tacho_edges(x, start, state, min_range):
    """cam_angle.TachoEdges.feed(start, x), compiled: rising edges (sub-sample positions) of the
    pulse channel ``x`` (n,), any float dtype. ``state`` (float64, 5): lo, hi, armed (0/1), the
    last sample's value, whether there was one (0/1); updated in place."""
    n = x.shape[0]
    if n == 0:
        return np.empty(0)
    lo, hi = state[0], state[1]
    for i in range(n):
        v = float(x[i])
        lo = min(lo, v)
        hi = max(hi, v)
    state[0], state[1] = lo, hi
    rng = hi - lo
    if rng < min_range:
        state[3], state[4] = float(x[n - 1]), 1.0
        return np.empty(0)
    mid = 0.5 * (hi + lo)
    low_level, high_level = mid - 0.1 * rng, mid + 0.1 * rng
    edges = np.empty(n // 2 + 1)
    m = 0
    armed = state[2] != 0.0
    for i in range(n):
        v = float(x[i])
        if v <= low_level:
            armed = True
        elif v >= high_level:
            if armed:  # a passage from below the band to above it: the edge is the mid crossing
                j = i
                while j > 0 and float(x[j - 1]) >= mid:
                    j -= 1
                if j == 0:
                    x0 = state[3] if state[4] != 0.0 else float(x[0])
                    i0, x1 = -1, float(x[0])
                else:
                    i0, x0, x1 = j - 1, float(x[j - 1]), float(x[j])
                frac = (mid - x0) / (x1 - x0) if x1 != x0 else 0.0
                edges[m] = start + i0 + min(max(frac, 0.0), 1.0)
                m += 1
            armed = False
    state[2] = 1.0 if armed else 0.0
    state[3], state[4] = float(x[n - 1]), 1.0
    return edges[:m]
