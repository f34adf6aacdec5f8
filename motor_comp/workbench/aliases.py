"""Which effects this run cannot tell apart: near-collinear forces, said out loud.

An effect found is only one reading of the data when another effect's columns give the
same force over the positions, speeds and times this run visits — a ripple whose period
is longer than the travel is a spring over it (or an offset), a speed dependence is a
drift in time when the speeds rise over the run, a spring is gravity over a short swing
(``../shared/IDENTIFICATION.md`` §6).  Judged from the columns, for every term of the
final model: the part of its fitted force the rest of the model cannot carry is regressed
on the columns of each absent library term — at the term's own parameters, and at the
values a term declares it can take outside its fitting space
(:meth:`~motor_comp.physics.effects.identification.Term.aliases`: a ripple longer than
the travel) — and on a drift in time (a polynomial of time, the usual confounder of a
time-ordered experiment).  When one of them reproduces that part (a share ≥
:data:`ALIAS_R2`), both are named with the experiment that would separate them, and the
finding is marked as one of several readings.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from motor_comp.physics.effects import TERMS
from motor_comp.physics.effects.identification import MASS
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import context, design, view_for
from motor_comp.workbench.lsq import solve_gram
from motor_comp.workbench.wording import SEPARATE, TITLES

#: share of a term's force another reading must reproduce to be named beside it
ALIAS_R2 = 0.95
#: least share of the drive force's RMS a term's force must have to be judged
MIN_FORCE = 0.01


@dataclasses.dataclass(frozen=True)
class Alias:
    """A term of the model and another reading of the same force on this run."""

    effect: str
    other: str
    r2: float
    experiment: str

    def sentence(self) -> str:
        """Return the note in plain words."""
        other = TITLES.get(self.other, self.other)
        if self.other == 'ripple':
            other = 'a force ripple longer than the travel'
        elif self.other == 'time':
            other = 'a drift over time'
        return (f'{self.effect} and {self.other} cannot be told apart on this run: '
                f'{other} gives {100 * self.r2:.0f} % of the '
                f'{TITLES.get(self.effect, self.effect)} force found; {self.experiment}')


def _r2(f: np.ndarray, cols: list[np.ndarray]) -> float:
    A = np.column_stack([np.ones(len(f))] + list(cols))
    G = np.column_stack([A, f])
    th, sse = solve_gram(G.T @ G)
    den = float(np.sum((f - f.mean()) ** 2))
    return 1.0 - sse / den if den > 0 else 0.0


def _share(f: np.ndarray, rest: list[np.ndarray], cols: list[np.ndarray]) -> float:
    """Return the share of ``f`` the model's other columns leave that ``cols`` reproduce."""
    r0 = _r2(f, rest)
    return (_r2(f, rest + list(cols)) - r0) / (1.0 - r0) if r0 < 1.0 else 0.0


def ambiguities(data: Dataset, est: Any) -> list[Alias]:
    """Return the other readings of each term of ``est``'s model (see the module doc)."""
    spec = est.spec
    d = design(data, spec, est.model)
    th, _ = solve_gram(d.gram(), d.bounds)
    X = d.X
    y = d.view.y()
    scale = float(np.sqrt(np.mean((y - y.mean()) ** 2)))
    view = view_for(data, spec, est.model)
    t = view.gather(lambda p, mo: p.kin.t - p.kin.t[0])
    tn = (t - t.mean()) / (np.ptp(t) or 1.0)
    sgn = view.gather(lambda p, mo: np.sign(mo.v))
    # a drift in time: of a force, or of a friction (flipping with the motion)
    drift = [tn, tn * tn, sgn * tn, sgn * tn * tn]
    out: list[Alias] = []
    for n in spec.names:
        idx = [i for i, lab in enumerate(d.labels) if lab[0] == n and lab != MASS]
        if not idx:
            continue
        f = X[:, idx] @ th[idx]
        if float(np.sqrt(np.mean((f - f.mean()) ** 2))) < MIN_FORCE * scale:
            continue
        # what the rest of the model (without the term, its replaced terms back) carries
        d_rest = design(data, spec.without(n), est.model)
        rest = list(d_rest.cols)
        readings: list[tuple[str, list[np.ndarray]]] = [('time', drift)]
        for m, t2 in TERMS.items():
            if m in spec.names or t2.applicable(data.summary) is not None:
                continue
            for eta in t2.aliases(data.summary):
                s2 = spec.without(n).with_(m, eta)
                if any(r not in s2.names for r in t2.requires):
                    continue
                cols = view.columns(t2.columns(eta, context(s2, data)))
                if cols:
                    readings.append((m, cols))
        best: dict[str, float] = {}
        for m, cols in readings:
            r2 = _share(f, rest, cols)
            if r2 >= ALIAS_R2 and r2 > best.get(m, 0.0):
                best[m] = r2
        for m, r2 in sorted(best.items(), key=lambda kv: -kv[1]):
            how = SEPARATE.get(frozenset((n, m)), 'an experiment that excites them '
                                                  'differently')
            out.append(Alias(n, m, r2, how))
    return out


__all__ = ['ALIAS_R2', 'Alias', 'ambiguities']
