"""Import hygiene: the numpy core never pulls in ROS (DESIGN.md §2).

Offline tools (simulate, analyze, compare, diagnose, fit) must run on a laptop without
ROS, so importing any core module must not import ``rclpy``, a ``*_msgs`` package or
another ROS-runtime-only module.  The check runs in a fresh interpreter: other tests'
imports would otherwise already sit in ``sys.modules``.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the core packages of DESIGN.md §2 (must exist and import cleanly)
CORE = ('motor_comp', 'motor_comp.errors', 'motor_comp.physics', 'motor_comp.control',
        'motor_comp.logs', 'motor_comp.analysis', 'motor_comp.workbench', 'motor_comp.design',
        'motor_comp.cli')
#: the ROS adapters, and the CLI subcommands that start nodes: allowed to use rclpy
ROS_SIDE = ('motor_comp.nodes', 'motor_comp.cli.run', 'motor_comp.cli.replay',
            'motor_comp.cli.demo')

PROBE = textwrap.dedent('''
    import importlib, json, pkgutil, sys

    CORE, ROS_SIDE = json.loads(sys.argv[1])

    def ros_modules():
        return {m for m in sys.modules
                if m.split('.')[0] in ('rclpy', 'builtin_interfaces', 'rosidl_runtime_py')
                or m.split('.')[0].endswith('_msgs')}

    def ros_side(name):
        return any(name == r or name.startswith(r + '.') for r in ROS_SIDE)

    culprits, imported = {}, []
    seen = set(ros_modules())

    def load(name):
        """Import ``name``; record a failure or any ROS module it pulled in."""
        global seen
        try:
            mod = importlib.import_module(name)
        except Exception as exc:  # report, do not hide: a core module must import
            culprits[name] = 'import failed: ' + repr(exc)
            return None
        if name not in imported:
            imported.append(name)
        new = ros_modules() - seen
        if new:
            culprits[name] = sorted({m.split('.')[0] for m in new})
            seen |= new
        return mod

    def failed(name):
        culprits[name] = 'import failed while walking: ' + repr(sys.exc_info()[1])

    # top level without importing anything (motor_comp.nodes must never be imported)
    top = [i.name for i in pkgutil.iter_modules(load('motor_comp').__path__, 'motor_comp.')]
    names = list(CORE) + [n for n in top if n not in CORE and not ros_side(n)]
    for pkg in list(names):
        mod = load(pkg)
        if pkg != 'motor_comp' and hasattr(mod, '__path__'):
            # walk_packages imports only sub-packages (to recurse), never the ROS side:
            # motor_comp.nodes is filtered out above and cli.run/replay/demo are modules
            names += [i.name for i in pkgutil.walk_packages(mod.__path__, pkg + '.',
                                                            onerror=failed)]
            new = ros_modules() - seen      # a sub-package imported by the walk itself
            if new:
                culprits[pkg + '.*'] = sorted({m.split('.')[0] for m in new})
                seen |= new
    for name in names:
        if not ros_side(name):
            load(name)
    print(json.dumps({'imported': imported, 'culprits': culprits}))
''')


def test_core_modules_do_not_import_ros():
    proc = subprocess.run([sys.executable, '-c', PROBE, json.dumps([CORE, ROS_SIDE])],
                          cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report['culprits'] == {}, report['culprits']
    imported = set(report['imported'])
    # the walk really reached the leaves (not a vacuous pass)
    for leaf in ('motor_comp.physics.kernel', 'motor_comp.physics.effects.presliding',
                 'motor_comp.logs.run', 'motor_comp.cli.main'):
        assert leaf in imported
    assert not any(n.startswith('motor_comp.nodes') for n in imported)
