"""A term's claim to repeat along the travel, held to it on stretches it was not fitted on.

A term that declares a period (``Term.repeats_every``: the ripple) claims that a force
fitted on some periods of the travel predicts the others; a shape at one place (a bump
the library lacks, drawn by harmonics) does not.  :func:`block_cv` measures the claim
for :func:`.heldout.cv_candidate`, from the term's declaration alone.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects.identification import MASS
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, design
from motor_comp.workbench.lsq import solve_gram, solve_grams, sse_with


#: partitions of the travel into blocks, each shifted by 1/BLOCK_SHIFTS of a block: a
#: shape cut by a block's edge in one partition is whole in another
BLOCK_SHIFTS = 4
#: share of what a term explains on the stretches it was fitted on that it must also
#: explain on stretches it did not see, to count as repeating along the travel.  On the
#: generator's runs: the true ripples 95–100 % (13 complete cases, at their final fit);
#: bumps the library lacks drawn by harmonics 23 % (linear) and 52 % (rotary, with
#: gravity's sin/cos helping)
REPEATS = 0.75


@dataclasses.dataclass(frozen=True)
class BlockCV:
    """A term's SSE on position blocks: held out, seen (fitted on all), and without it."""

    held: float
    seen: float
    nothing: float

    @property
    def repeats(self) -> bool:
        """Whether the held-out gain is at least :data:`REPEATS` of the seen gain."""
        return self.nothing - self.held >= REPEATS * (self.nothing - self.seen) > 0.0


def block_cv(data: Dataset, spec: Spec, name: str, model: AxisModel | None,
             length: float) -> BlockCV:
    """Return how well term ``name`` predicts blocks of ``length`` along the travel.

    The spec is fitted on all rows and the other terms' share is taken off the target;
    the term's own columns, fitted to that on all blocks but one, predict that one,
    over :data:`BLOCK_SHIFTS` partitions of the travel shifted by a fraction of a block
    (:class:`BlockCV`: the mean held-out SSE, the SSE fitted on all, and the SSE of
    predicting nothing).  A force periodic in position fitted on some periods predicts
    the others; a shape at one place (a bump) does not.  The other terms are not
    refitted per block: a spring fitted without the end of the travel would mispredict
    it for reasons of its own.  All ``inf`` under two blocks.
    """
    d = design(data, spec, model)
    x = d.view.gather(lambda p, mo: mo.x)
    th, _ = solve_gram(d.gram(), d.bounds)
    own = np.array([lab != MASS and lab[0] == name for lab in d.labels], dtype=bool)
    r = d.y - d.X[:, ~own] @ th[~own]
    Z = np.column_stack([d.X[:, own], r])
    total = Z.T @ Z
    held = []
    for shift in np.arange(BLOCK_SHIFTS) / BLOCK_SHIFTS:
        block = np.floor((x - x.min()) / max(length, 1e-300) + shift)
        # the rows grouped by block (in their order within each): one slice per block,
        # not a mask over every row per block (a rotary axis has hundreds of blocks)
        order = np.argsort(block, kind='stable')
        blocks, first = np.unique(block[order], return_index=True)
        if len(blocks) < 2:
            return BlockCV(math.inf, math.inf, math.inf)
        Zs = Z[order]
        ends = np.append(first[1:], len(order))
        G = np.stack([Zs[a:b].T @ Zs[a:b] for a, b in zip(first, ends)])
        th = solve_grams(total - G)
        held.append(sum(sse_with(g, t) for g, t in zip(G, th)))
    return BlockCV(held=float(np.mean(held)), seen=float(solve_gram(total)[1]),
                   nothing=float(total[-1, -1]))


__all__ = ['BLOCK_SHIFTS', 'BlockCV', 'REPEATS', 'block_cv']
