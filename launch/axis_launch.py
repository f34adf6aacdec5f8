"""Launch the four motor_comp nodes (needs a full ROS 2 install with ``ros2 launch``).

    ros2 launch motor_comp axis_launch.py plant:=ballscrew mode:=npid \
        feedforward:=static+gms timing:=lockstep duration:=10.0 output:=/tmp/run.mcap

Each node reads its YAML from ``share/motor_comp/config/<node>.yaml`` first, then the
launch arguments on top.  When the plant finishes ``duration`` (> 0) of sim time it
exits and the whole launch shuts down (the recorder finalises its MCAP on the SIGINT).
Without ``ros2 launch`` (e.g. the PyPI wheels) use ``motor-comp run`` instead.
"""
from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = 'motor_comp'
ARGS = {
    'namespace': ('axis', 'namespace of the axis topics'),
    'plant': ('pmlm', 'pmlm | ballscrew | plant YAML path'),
    'mode': ('pid', 'controller: pid | adaptive_sliding | npid'),
    'feedforward': ('none', 'none | static | gms | static+gms'),
    'trajectory': ('p2p', 'sine | p2p | cv | chirp'),
    'timing': ('lockstep', 'lockstep | realtime'),
    'control_rate': ('1000.0', 'control rate [Hz]'),
    'duration': ('0.0', 'sim time [s] before the plant exits; 0 = until Ctrl-C'),
    'output': ('run.mcap', 'new MCAP file written by the recorder (an existing file is '
               'refused, never overwritten)'),
    'model_dir': ('', 'directories the nodes may read files from, ":"-separated (a plant '
                  'file must be inside); empty = the working directory and config/'),
    'autostart': ('true', 'plant, controller, recorder configure and activate themselves; '
                  'false = they wait unconfigured for a lifecycle manager '
                  '(ros2 lifecycle set /axis/<node> configure|activate …)'),
}


def _config(node: str) -> str:
    return os.path.join(get_package_share_directory(PACKAGE), 'config', f'{node}.yaml')


def _arg(name: str, kind: type = str) -> ParameterValue:
    return ParameterValue(LaunchConfiguration(name), value_type=kind)


def generate_launch_description() -> LaunchDescription:
    """The four nodes in one namespace, shut down together when the plant is done."""
    timing = {'timing': _arg('timing'), 'control_rate': _arg('control_rate', float)}
    overrides = {
        'plant_node': {**timing, 'plant': _arg('plant'), 'duration': _arg('duration', float),
                       'autostart': _arg('autostart', bool), 'model_dir': _arg('model_dir')},
        'trajectory_node': {**timing, 'trajectory': _arg('trajectory')},
        'controller_node': {**timing, 'plant': _arg('plant'), 'mode': _arg('mode'),
                            'feedforward': _arg('feedforward'),
                            'autostart': _arg('autostart', bool), 'model_dir': _arg('model_dir')},
        'recorder_node': {'timing': _arg('timing'), 'output': _arg('output'),
                          'autostart': _arg('autostart', bool), 'model_dir': _arg('model_dir')},
    }
    actions = [DeclareLaunchArgument(name, default_value=default, description=text)
               for name, (default, text) in ARGS.items()]
    nodes = {}
    for name, params in overrides.items():
        nodes[name] = Node(package=PACKAGE, executable=name, name=name,
                           namespace=LaunchConfiguration('namespace'),
                           parameters=[_config(name), params], output='screen',
                           sigterm_timeout='10')
        actions.append(nodes[name])
    actions.append(RegisterEventHandler(OnProcessExit(
        target_action=nodes['plant_node'],
        on_exit=[EmitEvent(event=Shutdown(reason='plant finished its run'))])))
    return LaunchDescription(actions)
