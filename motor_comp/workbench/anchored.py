"""The model simulated from the measured state: prediction windows and anchored runs.

Both the k-step position prediction of ``compare`` and the noise floor of ``diagnose``
and ``fit`` run the compiled plant kernel (:func:`motor_comp.physics.kernel.
plant_advance`, the simulator's own law) on the logged input from many origins, each
started from the measured state *including* every history-dependent state (DESIGN.md
§6): the GMS element forces and phases from the element law run along the measured path
up to the origin, the motor position across a backlash gap reconstructed from the load,
the dead-time buffer from the commands held before the origin.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.physics import aot
from motor_comp.physics import kernel as K
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects.presliding import gms_update
from motor_comp.physics.effects.stribeck import stribeck_curve
from motor_comp.physics.plant import Sensors, initial_state, pack_params
from motor_comp.workbench.derivatives import InputHold, Kinematics
from motor_comp.workbench.motion import motor_position
from motor_comp.workbench.processing import gms_position, point_position, point_velocity


@aot.ahead(*(aot.F8_1D,) * 4, *(aot.F8,) * 6)
@njit(cache=True)
def gms_states(x, alpha, k, sigma, C, fc, fs, vs, delta, dt):
    """Return the element forces and phases of a GMS along a measured path ``x`` [m].

    The element law of the effect (:func:`~motor_comp.physics.effects.presliding.
    gms_update`) run from relaxed elements at the first sample; two ``(n, elements)``
    arrays: spring forces [N] and phases (0 sticking, ±1 slipping).
    """
    n, m = x.shape[0], alpha.shape[0]
    F = np.zeros((n, m))
    Z = np.zeros((n, m))
    forces = np.zeros(m)
    slip = np.zeros(m)
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        gms_update(forces, slip, alpha, k, sigma, C, dx, v,
                   stribeck_curve(v, fc, fs, vs, delta), dt)
        for e in range(m):
            F[j, e] = forces[e]
            Z[j, e] = slip[e]
    return F, Z


@njit(cache=True)
def _seed(S, S0, k0, xm, xl, vm, u, n_sub, gf, gz):
    # the kernel's state at origin k0 from the measurement (see the module docstring)
    nbuf = S0.shape[0] - K.S_DBUF
    S[:] = S0
    S[K.S_X] = xm[k0]
    S[K.S_XL] = xl[k0]
    S[K.S_V] = vm[k0]
    S[K.S_STUCK] = 1.0 if vm[k0] == 0.0 else 0.0
    for e in range(gf.shape[1]):
        S[K.S_GMS_F + e] = gf[k0, e]
        S[K.S_GMS_SLIP + e] = gz[k0, e]
    if nbuf > 0:
        S[K.S_DHEAD] = 0.0
        for m in range(1, nbuf + 1):
            kk = k0 - 1 - (m - 1) // n_sub
            S[K.S_DBUF + (1 - m) % nbuf] = u[max(kk, 0)]


@njit(cache=True)
def _advance(P, S, u, k, n_sub, interp):
    # one sample period from sample k: a held command, or a sampled input (a measured
    # current) interpolated to each sub-step's middle
    if not interp or k + 1 >= u.shape[0]:
        K.plant_advance(P, S, u[k], 0.0, n_sub)
        return
    for s in range(n_sub):
        w = (s + 0.5) / n_sub
        # np.int64, not the literal 1: a literal is typed Literal[int](1) and compiled
        # the whole kernel twice more (30 of a fresh build's 60 s), for the same code
        K.plant_advance(P, S, (1.0 - w) * u[k] + w * u[k + 1], 0.0, np.int64(1))


@aot.ahead(*(aot.F8_1D,) * 6, aot.I8_1D, aot.I8, aot.I8, aot.F8_2D, aot.F8_2D, aot.BOOL)
@njit(cache=True)
def _kstep(P, S0, xm, xl, vm, u, origins, horizon, n_sub, gf, gz, interp):
    # every origin restarts the kernel from the measured state and runs it `horizon`
    # control periods on the logged input; returns the load position at the horizon
    n = origins.shape[0]
    out = np.empty(n)
    S = S0.copy()
    for j in range(n):
        k0 = origins[j]
        _seed(S, S0, k0, xm, xl, vm, u, n_sub, gf, gz)
        for i in range(horizon):
            _advance(P, S, u, k0 + i, n_sub, interp)
        out[j] = S[K.S_XL]
    return out


@aot.ahead(*(aot.F8_1D,) * 6, aot.I8_1D, aot.I8, aot.F8_2D, aot.F8_2D, aot.BOOL)
@njit(cache=True)
def _windows(P, S0, xm, xl, vm, u, origins, n_sub, gf, gz, interp):
    # the load position of the model run from each origin to the next (a run made of
    # windows anchored to the measurement)
    n = xl.shape[0]
    out = xl.copy()
    S = S0.copy()
    for j in range(origins.shape[0]):
        k0 = origins[j]
        k1 = origins[j + 1] if j + 1 < origins.shape[0] else n
        _seed(S, S0, k0, xm, xl, vm, u, n_sub, gf, gz)
        out[k0] = S[K.S_XL]
        for k in range(k0 + 1, k1):
            _advance(P, S, u, k - 1, n_sub, interp)
            out[k] = S[K.S_XL]
    return out


@dataclasses.dataclass(frozen=True)
class Anchor:
    """What the kernel needs to start ``model`` from any sample of a run."""

    P: np.ndarray
    S0: np.ndarray
    xm: np.ndarray
    xl: np.ndarray
    vm: np.ndarray
    u: np.ndarray
    n_sub: int
    gf: np.ndarray
    gz: np.ndarray
    interp: bool


def anchor(kin: Kinematics, model: AxisModel, *, n_sub: int = 10) -> Anchor:
    """Return the packed model and the measured states of every sample of ``kin``."""
    bl, dly = model.get('backlash'), model.get('delay')
    xm_raw = kin.position if bl is None or bl.width <= 0 else motor_position(
        kin, bl.width, model.without('backlash', 'delay'), kin.u,
        tau=dly.tau if dly is not None else 0.0)
    # explicit RK4 needs the physics step well inside the fastest mechanical time
    # constant M/(damping terms): a light, heavily damped model gets more sub-steps
    damp = (model.input_gain * model.back_emf + model.damping + model.fv
            + (abs(model.get('asymmetry').dfv) if model.has('asymmetry') else 0.0))
    n_sub = int(min(max(n_sub, np.ceil(kin.dt * damp / model.mass / 0.5)), 5000))
    P = pack_params(model, Sensors(encoder_resolution=0.0), kin.dt / n_sub)
    gms = model.get('presliding')
    if gms is not None:
        fc, fs, vs, dl = model.stribeck_curve_params()
        gf, gz = gms_states_entry(np.ascontiguousarray(gms_position(kin, xm_raw)),
                                  np.array(gms.alpha), np.array(gms.k), np.array(gms.sigma),
                                  float(gms.C), fc, fs, vs, dl, kin.dt)
    else:
        gf = gz = np.zeros((len(kin), 0))
    return Anchor(P, initial_state(P, 0.0), np.ascontiguousarray(point_position(kin, xm_raw)),
                  np.ascontiguousarray(kin.x), np.ascontiguousarray(point_velocity(kin, xm_raw)),
                  np.ascontiguousarray(kin.u, dtype=float), n_sub, gf, gz,
                  kin.hold is InputHold.SAMPLE)


def kstep(a: Anchor, origins: np.ndarray, horizon: int) -> np.ndarray:
    """Return the load position ``horizon`` samples after each origin [m]."""
    return _kstep_entry(a.P, a.S0, a.xm, a.xl, a.vm, a.u, origins, horizon, a.n_sub, a.gf, a.gz,
                        a.interp)


def windows(a: Anchor, origins: np.ndarray) -> np.ndarray:
    """Return the run the model makes from each origin to the next, at every sample [m]."""
    return _windows_entry(a.P, a.S0, a.xm, a.xl, a.vm, a.u, origins.astype(np.int64), a.n_sub,
                          a.gf, a.gz, a.interp)


__all__ = ['Anchor', 'anchor', 'gms_states', 'kstep', 'windows']


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
gms_states_entry = aot.entry(gms_states)
_kstep_entry = aot.entry(_kstep)
_windows_entry = aot.entry(_windows)
