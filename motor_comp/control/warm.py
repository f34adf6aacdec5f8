"""Fill numba's cache with the loop and the step: ``python -m motor_comp.control.warm``.

The simulator's closed loop and the controller's step (each one compiled function for
every law, plant and compensation) are JIT-compiled on their first call in a process
and cached on disk (``cache=True``).  From a fresh clone that first call costs about 17 s
(the loop) and 13 s (the step): inside the first test or the first node that needs them,
or in several at once when processes start together.  ``make setup`` runs this beside
the ahead-of-time build (:mod:`motor_comp.physics.aot_build`), whose compiler keeps one
core busy for about a minute, so the second core fills the cache meanwhile.  A failure
says so in one line and exits 1; nothing depends on it but start-up times.
"""
from __future__ import annotations

import argparse
import sys
import time


def warm() -> None:
    """Run each cached kernel once: a short closed-loop run, and a node's controller step."""
    from motor_comp.control import compensation, simulator
    from motor_comp.control.controller import make_controller
    from motor_comp.control.nominal import derive_nominal
    from motor_comp.control.trajectories import default_trajectory
    from motor_comp.physics.config import load_plant
    cfg = load_plant('ballscrew')
    # the controller node's path first: it shares no kernel with the plant step, which
    # the ahead-of-time build is compiling meanwhile (for its anchored runs)
    step = make_controller('npid', plant=cfg)
    step.step(0.0, 0.0, 0.0, 0.0, 0.0, 1.0 / cfg.control_rate)
    step.set_compensation(compensation.from_model(cfg.model, source='warm-up'))
    step.step(0.0, 0.0, 0.0, 0.0, 0.0, 1.0 / cfg.control_rate)
    loop = make_controller('npid', plant=derive_nominal(cfg))
    simulator.simulate(cfg, loop, default_trajectory(cfg), duration=0.05, seed=0)


def main(argv: list[str] | None = None) -> int:
    """``python -m motor_comp.control.warm`` (see the module docstring)."""
    argparse.ArgumentParser(prog='python -m motor_comp.control.warm',
                            description="fill numba's cache of the simulator's loop and "
                                        "the controller's step").parse_args(argv)
    t0 = time.monotonic()
    try:
        warm()
    except Exception as exc:  # noqa: BLE001 - a cache left cold costs time, not results
        print(f'error: filling the kernel cache failed ({type(exc).__name__}); the first '
              f'run compiles instead', file=sys.stderr)
        return 1
    print(f'cached the simulator and controller kernels in {time.monotonic() - t0:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
