"""Friction feedforward driven by the *reference* velocity (Chiew et al. Fig. 9).

Modes (:class:`Feedforward`):

* ``static`` — the static model of Chiew eq. 2,
  ``F = [fc + (fs−fc)·e^{−|v/vs|^δ}]·sgn(v) + σ·v``, built from the effect modules' own
  laws (:func:`~motor_comp.physics.effects.stribeck.stribeck_curve` for Coulomb +
  Stribeck, :func:`~motor_comp.physics.effects.viscous.viscous_force` for σ·v);
* ``gms`` — the Generalized Maxwell-Slip elements (Chiew eq. 3–5) driven by the reference
  displacement, stepped by the physics kernel's own
  :func:`~motor_comp.physics.effects.presliding.gms_step` (no second copy);
* ``static+gms`` — both, without counting sliding friction twice: the GMS elements carry
  the Coulomb + Stribeck level (in sliding they converge to the Stribeck curve ``s(v)``),
  so the static model contributes only what the elements do not model, the viscous
  ``σ·v`` term.  Hence ``static+gms = Σ F_i + σ·v`` (Chiew eq. 5 with σ present), while
  ``gms`` alone is ``Σ F_i`` and ``static`` alone jumps at every reversal.

The force [N] is converted to the command unit through the nominal ``input_gain``
[N/V] (the ball-screw's ``k_f``): ``u_ff = F/k_f``.
"""
from __future__ import annotations

import enum

from numba import njit

from motor_comp.control._jitcache import JIT_INLINE
from motor_comp.errors import ParameterError
from motor_comp.physics.effects.presliding import gms_step
from motor_comp.physics.effects.stribeck import stribeck_curve
from motor_comp.physics.effects.viscous import viscous_force


class Feedforward(enum.IntEnum):
    """Friction feedforward mode; bit 1 = static model, bit 2 = GMS elements."""

    NONE = 0
    STATIC = 1
    GMS = 2
    STATIC_GMS = 3

    @property
    def label(self) -> str:
        """The CLI/ROS spelling."""
        return FEEDFORWARD_LABELS[self]

    @classmethod
    def parse(cls, value: 'str | Feedforward') -> 'Feedforward':
        """From ``none | static | gms | static+gms`` (or an existing member)."""
        if isinstance(value, Feedforward):
            return value
        for member, label in FEEDFORWARD_LABELS.items():
            if value == label:
                return member
        raise ParameterError(f'feedforward must be one of '
                             f'{", ".join(FEEDFORWARD_LABELS.values())}, got {value!r}')


FEEDFORWARD_LABELS = {Feedforward.NONE: 'none', Feedforward.STATIC: 'static',
                      Feedforward.GMS: 'gms', Feedforward.STATIC_GMS: 'static+gms'}


@njit(**JIT_INLINE)
def static_feedforward(v, fc, fs, vs, delta, fv):
    """Return the static-model friction [N] at reference velocity ``v`` [m/s] (Chiew eq. 2)."""
    return stribeck_curve(v, fc, fs, vs, delta) + viscous_force(v, fv)


@njit(**JIT_INLINE)
def friction_feedforward(mode, v, dx, dt, fc, fs, vs, delta, fv, st, i_f, i_s, q, i_a, i_k,
                         i_g, n, C):
    """Feedforward friction force [N] for ``mode`` (0 none, 1 static, 2 gms, 3 both).

    Returns ``(force of the mode, static-model force, GMS element force)`` [N]; the last
    two let a driver switch modes without a bump.

    Parameters
    ----------
    mode : int
        :class:`Feedforward` code.
    v : float
        Reference velocity [m/s].
    dx : float
        Reference displacement since the previous control step [m] (drives the GMS).
    dt : float
        Control period [s].
    fc, fs, vs, delta, fv : float
        Nominal static model: Coulomb [N], breakaway [N], Stribeck velocity [m/s],
        shape [-], viscous σ [N·s/m].
    st, i_f, i_s : ndarray, int, int
        GMS element state: forces ``st[i_f + i]`` [N] and phases ``st[i_s + i]``
        (updated in place whenever a GMS mode is active, so that a switch to it is
        bumpless).
    q, i_a, i_k, i_g, n, C : ndarray, int, int, int, int, float
        Nominal GMS elements: slip limits ``q[i_a + i]`` [-], stiffnesses ``q[i_k + i]``
        [N/m], micro-damping ``q[i_g + i]`` [N·s/m], ``i < n``; constant attraction ``C``
        [N/s] (Lampaert 2003: slip relaxation rate ``C/|s(v)|``).
    """
    f_el = 0.0
    if n > 0:
        s_v = stribeck_curve(v, fc, fs, vs, delta)
        f_el = gms_step(st, i_f, st, i_s, q, i_a, q, i_k, q, i_g, n, C, dt, dx, v, s_v)
    f_static = static_feedforward(v, fc, fs, vs, delta, fv)
    if mode == 1:
        return f_static, f_static, f_el
    if mode == 2:
        return f_el, f_static, f_el
    if mode == 3:
        return f_el + viscous_force(v, fv), f_static, f_el
    return 0.0, f_static, f_el
