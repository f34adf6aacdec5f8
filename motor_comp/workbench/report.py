"""Where does the model fail?  Residual views, whiteness test, PNG figures and one HTML page.

Views of the force residual ``r`` (sliding samples only):

* over time, next to the drive force for scale;
* against position, with its spatial spectrum (a peak names a ripple period);
* against velocity, binned (the friction curve the model misses);
* against time since each reversal (pre-sliding, backlash, quadrant glitches);
* whiteness, as MATLAB ``resid``: autocorrelation of ``r`` and cross-correlation with
  the input, with a 99 % band ``±2.58/√N_eff`` for a white residual.  The residual is
  smoothed by the derivative filter, so it is decimated to one sample per half window
  before the test (``N_eff`` is the decimated length) — otherwise the filter's own
  correlation would fail every model.
"""
from __future__ import annotations

import dataclasses
import html
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from motor_comp.errors import MotorCompError
from motor_comp.physics.effects.ripple import spatial_spectrum
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.residual import Residual, reversals

#: 99 % two-sided normal quantile of the whiteness band
Z99 = 2.576


@dataclasses.dataclass(frozen=True)
class Whiteness:
    """Residual correlation test (MATLAB ``resid`` style), per contiguous segment.

    Parameters
    ----------
    lags : ndarray
        Lags [s].
    autocorr, crosscorr : ndarray
        Normalised autocorrelation of ``r`` and cross-correlation ``r(t + lag)·u(t)``.
    band : float
        99 % confidence half-width for a white residual.
    auto_outside, cross_outside : float
        Fraction of non-zero lags outside the band (cross: of the lags it is judged
        on — only ``lag >= 0`` on closed-loop data).
    segments : int
        Contiguous sliding segments the correlations were summed over (the gaps of
        removed rest samples are never bridged).
    closed_loop : bool
        The input was computed from the measured output (feedback): the residual
        feeds back into later inputs, so negative lags of the cross-correlation are
        correlated by construction and are not judged.
    """

    lags: np.ndarray
    autocorr: np.ndarray
    crosscorr: np.ndarray
    band: float
    auto_outside: float
    cross_outside: float
    segments: int = 1
    closed_loop: bool = False

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {'band': self.band, 'autocorr_outside': self.auto_outside,
                'crosscorr_outside': self.cross_outside,
                'white': bool(self.auto_outside <= 0.05),
                'independent_of_input': bool(self.cross_outside <= 0.05),
                'segments': int(self.segments), 'closed_loop': bool(self.closed_loop),
                'crosscorr_lags': 'lag >= 0 only (closed loop)' if self.closed_loop
                else 'all'}

    def sentence(self) -> str:
        """One line for the terminal."""
        cross = (f'{100 * self.cross_outside:.0f} % of input cross-correlation lags '
                 + ('(closed-loop data: judged on lags where the input precedes the '
                    'residual only; the feedback correlates the others by construction)'
                    if self.closed_loop else ''))
        return (f'whiteness: {100 * self.auto_outside:.0f} % of autocorrelation lags outside '
                f'the 99 % band (over {self.segments} contiguous segments), {cross}').rstrip()


def is_closed_loop(run: Any) -> bool:
    """Whether a run was recorded under feedback (a reference or a controller is logged)."""
    meta = getattr(run, 'metadata', {}) or {}
    return bool(getattr(run, 'reference', None) is not None or 'controller' in meta)


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of the runs of True in ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def whiteness(kin: Kinematics, res: Residual, *, max_lag_s: float | None = None,
              closed_loop: bool = False) -> Whiteness:
    """Auto- and cross-correlation of the (decimated) residual with a 99 % band.

    Correlations are summed inside each contiguous sliding segment and normalised
    once: lags never reach across the gap of removed rest samples (a product of two
    samples on either side of a stop would test nothing).
    """
    step = max(1, kin.window // 2)
    m = res.mask[::step]
    r_all = np.nan_to_num(res.r[::step])
    u_all = kin.u[::step]
    segs = [(a, b) for a, b in _segments(m) if b - a >= 3]
    n = sum(b - a for a, b in segs)
    if n < 20:
        raise MotorCompError(f'{kin.name}: too few sliding samples for a whiteness test')
    mu_r = float(np.mean(r_all[m]))
    mu_u = float(np.mean(u_all[m]))
    max_lag = 25 if max_lag_s is None else int(max_lag_s / (step * kin.dt))
    max_lag = int(np.clip(max_lag, 5, max(5, n // 4)))
    lags = np.arange(-max_lag, max_lag + 1)
    acf = np.zeros(len(lags))
    ccf = np.zeros(len(lags))
    srr = suu = 0.0
    for a, b in segs:
        r = r_all[a:b] - mu_r
        u = u_all[a:b] - mu_u
        srr += float(r @ r)
        suu += float(u @ u)
        L = b - a
        nfft = 1 << int(np.ceil(np.log2(2 * L)))
        fr = np.fft.rfft(r, nfft)
        fu = np.fft.rfft(u, nfft)
        ac = np.fft.irfft(fr * np.conj(fr), nfft)
        cc = np.fft.irfft(fr * np.conj(fu), nfft)
        ok = np.abs(lags) < L
        acf[ok] += ac[np.abs(lags[ok])]
        ccf[ok] += cc[lags[ok] % nfft]
    ac = acf / (srr if srr > 0 else 1.0)
    cc = ccf / (np.sqrt(srr * suu) or 1.0)
    band = Z99 / np.sqrt(n)
    nz = lags != 0
    judged = lags >= 0 if closed_loop else np.ones(len(lags), dtype=bool)
    return Whiteness(lags=lags * step * kin.dt, autocorr=ac, crosscorr=cc, band=band,
                     auto_outside=float(np.mean(np.abs(ac[nz]) > band)),
                     cross_outside=float(np.mean(np.abs(cc[judged]) > band)),
                     segments=len(segs), closed_loop=closed_loop)


def binned(xv: np.ndarray, yv: np.ndarray, bins: int = 40) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bin centres, means and standard deviations of ``yv`` in equal bins of ``xv``."""
    edges = np.linspace(np.min(xv), np.max(xv), bins + 1)
    idx = np.clip(np.digitize(xv, edges) - 1, 0, bins - 1)
    cnt = np.bincount(idx, minlength=bins)
    s1 = np.bincount(idx, weights=yv, minlength=bins)
    s2 = np.bincount(idx, weights=yv * yv, minlength=bins)
    ok = cnt > 0
    mean = np.where(ok, s1 / np.maximum(cnt, 1), np.nan)
    std = np.sqrt(np.maximum(np.where(ok, s2 / np.maximum(cnt, 1), np.nan) - mean ** 2, 0))
    return 0.5 * (edges[1:] + edges[:-1]), mean, std


def since_reversal(kin: Kinematics, res: Residual, *, window_s: float = 0.2) \
        -> tuple[np.ndarray, np.ndarray, int]:
    """Mean |residual| [N] against time since the last reversal (sign of motion)."""
    q = max(3 * kin.noise_std(), 1e-9)
    rev = reversals(kin.x, max(10 * q, 1e-3 * float(np.ptp(kin.x))))
    n = max(2, int(round(window_s / kin.dt)))
    acc = np.zeros(n)
    cnt = np.zeros(n)
    for k, _ in rev:
        seg = res.r[k:k + n]
        ok = np.isfinite(seg)
        acc[:len(seg)] += np.where(ok, np.abs(seg), 0.0)
        cnt[:len(seg)] += ok
    mean = np.where(cnt > 0, acc / np.maximum(cnt, 1), np.nan)
    return np.arange(n) * kin.dt, mean, len(rev)


def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def residual_figures(out: Path, kin: Kinematics, res: Residual, *, label: str = '',
                     rotary: bool = False, closed_loop: bool = False) \
        -> list[tuple[str, str]]:
    """Write the residual views as PNGs in ``out``; return ``(file, caption)`` pairs.

    With ``rotary`` the position is an angle [rad] and the spectrum is drawn against
    cycles per revolution.
    """
    plt = _plt()
    m = res.mask
    figs: list[tuple[str, str]] = []
    t = kin.t - kin.t[0]
    fu, vu = ('N·m', 'rad/s') if rotary else ('N', 'mm/s')
    vk = 1.0 if rotary else 1e3

    fig, ax = plt.subplots(figsize=(8, 3.2), dpi=90)
    ax.plot(t, res.f_in, color='0.75', lw=0.6, label='drive force F_in')
    r_plot = np.where(m, res.r, np.nan)
    ax.plot(t, r_plot, color='C3', lw=0.7, label='residual r')
    ax.set_xlabel('time [s]')
    ax.set_ylabel('torque [N·m]' if rotary else 'force [N]')
    ax.set_title(f'Force residual over time {label}')
    ax.legend(loc='upper right', fontsize=8)
    fig.tight_layout()
    fig.savefig(out / 'residual_time.png')
    plt.close(fig)
    figs.append(('residual_time.png', 'Residual over time, with the drive force for scale '
                 '(gaps: axis at rest, excluded).'))

    spec = spatial_spectrum(res.x[m], res.r[m])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.2), dpi=90)
    c, mu, _ = binned(res.x[m], res.r[m], bins=200)
    k, xlabel = (1.0, 'angle [rad]') if rotary else (1e3, 'position [mm]')
    a1.plot(k * res.x[m][::5], res.r[m][::5], '.', ms=1, color='0.6')
    a1.plot(k * c, mu, color='C3', lw=1.2, label='mean per position bin')
    a1.set_xlabel(xlabel)
    a1.set_ylabel(f'residual [{fu}]')
    a1.set_title('Residual vs position')
    a1.legend(fontsize=8)
    f = spec.frequency[1:]
    keep = f <= 1.0 / (4 * spec.bin_width)
    amp = spec.amplitude[1:][keep]
    i = int(np.argmax(amp))
    if rotary:
        cyc = 2 * np.pi * f[keep]
        a2.semilogx(cyc, amp, color='C0')
        a2.axvline(cyc[i], color='C3', ls='--', lw=0.8)
        a2.annotate(f'{cyc[i]:.3g} cycles/rev', (cyc[i], amp[i]), textcoords='offset points',
                    xytext=(5, -10), fontsize=8, color='C3')
        a2.set_xlabel('cycles per revolution')
    else:
        per = 1e3 / f[keep]
        a2.semilogx(per, amp, color='C0')
        a2.axvline(per[i], color='C3', ls='--', lw=0.8)
        a2.annotate(f'{per[i]:.3g} mm', (per[i], amp[i]), textcoords='offset points',
                    xytext=(5, -10), fontsize=8, color='C3')
        a2.set_xlabel('spatial period [mm]')
    a2.set_ylabel(f'amplitude [{fu}]')
    a2.set_title('Spatial spectrum of the residual')
    fig.tight_layout()
    fig.savefig(out / 'residual_position.png')
    plt.close(fig)
    figs.append(('residual_position.png', 'Residual against position and its spatial '
                 'spectrum: a peak names a ripple/cogging period; a slope is a spring.'))

    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=90)
    vmax = float(np.percentile(np.abs(res.v[m]), 99))
    sel = m & (np.abs(res.v) <= vmax)
    c, mu, sd = binned(res.v[sel], res.r[sel], bins=60)
    ax.plot(vk * res.v[sel][::5], res.r[sel][::5], '.', ms=1, color='0.6')
    ax.fill_between(vk * c, mu - sd, mu + sd, color='C3', alpha=0.2)
    ax.plot(vk * c, mu, color='C3', lw=1.2)
    ax.axhline(0, color='k', lw=0.5)
    ax.set_xlabel(f'velocity [{vu}]')
    ax.set_ylabel(f'residual [{fu}]')
    ax.set_title('Residual vs velocity (missing friction curve)')
    fig.tight_layout()
    fig.savefig(out / 'residual_velocity.png')
    plt.close(fig)
    figs.append(('residual_velocity.png', 'Residual against velocity, mean ± std per bin: '
                 'a step at 0 is Coulomb, a slope viscous, a hump near 0 Stribeck, '
                 'a V shape asymmetry, a constant an offset.'))

    ts, mean, nrev = since_reversal(kin, res)
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=90)
    ax.plot(1e3 * ts, mean, color='C3')
    ax.set_xlabel('time since reversal [ms]')
    ax.set_ylabel(f'mean |residual| [{fu}]')
    ax.set_title(f'Residual after reversals ({nrev} reversals)')
    fig.tight_layout()
    fig.savefig(out / 'residual_reversal.png')
    plt.close(fig)
    figs.append(('residual_reversal.png', 'Mean |residual| against time since each '
                 'reversal: a burst right after reversing is pre-sliding or backlash.'))

    w = whiteness(kin, res, closed_loop=closed_loop)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.2), dpi=90)
    for a, y, title in ((a1, w.autocorr, 'Autocorrelation of r'),
                        (a2, w.crosscorr, 'Cross-correlation r × input')):
        a.vlines(1e3 * w.lags, 0, y, color='C0', lw=0.8)
        a.axhspan(-w.band, w.band, color='C2', alpha=0.2, label='99 % band (white)')
        a.set_xlabel('lag [ms]')
        a.set_title(title)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / 'residual_whiteness.png')
    plt.close(fig)
    figs.append(('residual_whiteness.png', w.sentence() + ' (a good model leaves at most '
                 'a few % outside).'))
    return figs


def prediction_figure(out: Path, kin: Kinematics, prediction: Any) -> tuple[str, str]:
    """k-step prediction error over time."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3.0), dpi=90)
    t = prediction.t - kin.t[0]
    ax.plot(t, 1e6 * (prediction.measured - prediction.predicted), color='C0', lw=0.7)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('error [µm]')
    ax.set_title(f'{1e3 * prediction.horizon:.0f} ms-ahead position prediction error')
    fig.tight_layout()
    fig.savefig(out / 'prediction.png')
    plt.close(fig)
    return ('prediction.png', 'Measured minus predicted position, predicted from the '
            'measured state with the measured input.')


def candidates_figure(out: Path, candidates: Sequence[Any]) -> tuple[str, str]:
    """Bar chart of the held-out explained fraction per candidate."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=90)
    names = [c.effect for c in candidates]
    vals = [100 * max(c.explained, -0.05) for c in candidates]
    colors = ['C2' if c.supported else '0.6' for c in candidates]
    ax.barh(names[::-1], vals[::-1], color=colors[::-1])
    ax.set_xlabel('held-out residual removed [%]')
    ax.set_title('Candidate effects (green: supported)')
    fig.tight_layout()
    fig.savefig(out / 'candidates.png')
    plt.close(fig)
    return ('candidates.png', 'Fraction of the residual each candidate removes on held-out '
            'time blocks.')


def write_html(out: Path, title: str, text: str, figures: Sequence[tuple[str, str]]) -> Path:
    """One self-contained HTML page (text summary + the PNGs next to it)."""
    parts = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{html.escape(title)}'
             '</title><style>body{font-family:sans-serif;max-width:60em;margin:1em auto}'
             'pre{background:#f4f4f4;padding:.6em}img{max-width:100%}</style></head><body>',
             f'<h1>{html.escape(title)}</h1>', f'<pre>{html.escape(text)}</pre>']
    for name, caption in figures:
        parts.append(f'<figure><img src="{html.escape(name)}" alt="{html.escape(caption)}">'
                     f'<figcaption>{html.escape(caption)}</figcaption></figure>')
    parts.append('</body></html>')
    path = out / 'index.html'
    path.write_text('\n'.join(parts), encoding='utf-8')
    return path


def prepare_dir(path: str | Path) -> Path:
    """Create the report directory (one-line error if it cannot be)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MotorCompError(f'{out}: cannot create report directory ({exc.strerror})') \
            from None
    return out
