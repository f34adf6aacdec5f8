"""Spectra of a residual over a dataset's rows: Welch densities of its contiguous stretches.

The rows of a :class:`~motor_comp.workbench.dataset.Dataset` are a run's sliding samples,
decimated; stops cut them into stretches.  A spectrum is estimated on each stretch long
enough for one segment and averaged with the stretch lengths as weights (used by the
structure scan's tone search and by the noise floor's input-noise estimate).
"""
from __future__ import annotations

import numpy as np

from motor_comp.workbench.dataset import Dataset


def welch(seg: np.ndarray, fs: float, nper: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density of ``seg`` [unit²/Hz] at frequencies [Hz].

    scipy.signal.welch's defaults (periodic Hann window, half overlap, each window's
    mean removed, one-sided density), written here because importing ``scipy.signal``
    costs every diagnosis ~0.45 s of CPU (see :mod:`motor_comp.workbench.savgol`); the
    tests compare the two.
    """
    win = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nper) / nper)
    step = nper - nper // 2
    starts = np.arange(0, len(seg) - nper + 1, step)
    frames = seg[starts[:, None] + np.arange(nper)[None, :]]
    frames = (frames - frames.mean(axis=1, keepdims=True)) * win
    p = np.mean(np.abs(np.fft.rfft(frames, axis=1)) ** 2, axis=0) / (fs * float(win @ win))
    p[1:None if nper % 2 else -1] *= 2.0      # one-sided: all but DC and Nyquist doubled
    return np.fft.rfftfreq(nper, 1.0 / fs), p


def stretches(data: Dataset, r: np.ndarray, min_len: int, part: int | None = None) \
        -> tuple[list[np.ndarray], float]:
    """Return the contiguous stretches of ``r`` (one value per row) and their rate [Hz].

    A stretch is a run of rows one decimation step apart; those shorter than ``min_len``
    rows are left out.  ``part``: only the rows of that run of the dataset.
    """
    ends = np.append(np.cumsum([len(p.rows) for p in data.parts]), 0)
    if part is not None:
        lo, hi = (0 if part == 0 else int(ends[part - 1])), int(ends[part])
        parts, r = [data.parts[part]], r[lo:hi]
    else:
        parts = data.parts
    rows = np.concatenate([p.rows + 10 ** 9 * i for i, p in enumerate(parts)])
    step = int(np.median(np.diff(rows))) if len(rows) > 1 else 1
    fs = 1.0 / (parts[0].kin.dt * step)
    segs = []
    start = 0
    gaps = np.flatnonzero(np.diff(rows) != step) + 1
    for g in list(gaps) + [len(rows)]:
        if g - start >= min_len:
            segs.append(r[start:g])
        start = g
    return segs, fs


def density(segs: list[np.ndarray], fs: float, nper: int) \
        -> tuple[np.ndarray, np.ndarray] | None:
    """Return the length-weighted mean Welch density of ``segs`` (None without one)."""
    psd, n, f = None, 0, np.zeros(0)
    for seg in segs:
        if len(seg) < nper:
            continue
        f, p = welch(seg - seg.mean(), fs, nper)
        psd = p * len(seg) if psd is None else psd + p * len(seg)
        n += len(seg)
    return None if psd is None else (f, psd / n)


__all__ = ['density', 'stretches', 'welch']
