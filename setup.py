"""Packaging for motor_comp: ament_python for colcon, plain setuptools for pip."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'motor_comp'

NODES = ('trajectory_node', 'plant_node', 'controller_node', 'recorder_node', 'monitor_node')

setup(
    name=PACKAGE,
    version='0.1.0',
    # config/ holds data (plant defaults, node parameters), not code: named as a package
    # so that setuptools ships it without warning of an importable folder left out
    packages=find_packages(include=[PACKAGE, PACKAGE + '.*']) + [PACKAGE + '.config'],
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.py'))),
    ],
    package_data={PACKAGE + '.config': ['*.yaml']},
    include_package_data=True,
    python_requires='>=3.10,<3.13',
    install_requires=[
        'numpy>=1.24',
        'scipy>=1.10',
        'numba>=0.58',
        'pyyaml>=6.0',
        'mcap>=1.1',
        'mcap-ros2-support>=0.5',
        # robots' rosbag2 bags in sqlite3 storage (and their split/metadata layout)
        'rosbags>=0.9',
        'matplotlib>=3.7',
        'threadpoolctl>=3.1',
        'setuptools',
    ],
    extras_require={
        # PyPI wheels of ROS 2 Jazzy for machines without a system ROS install.
        'ros': [
            'ros-jazzy-rclpy',
            'ros-jazzy-std-msgs',
            'ros-jazzy-sensor-msgs',
            'ros-jazzy-rosgraph-msgs',
            'ros-jazzy-rmw-fastrtps-cpp',
            # managed (lifecycle) nodes and the live model monitor's /diagnostics
            'ros-jazzy-lifecycle-msgs',
            'ros-jazzy-diagnostic-msgs',
        ],
        # Dask cluster sweeps (`motor-comp sweep --scheduler ...`)
        'cluster': [
            'distributed>=2024.1',
        ],
        'test': [
            'pytest>=7',
            'pytest-timeout',
            # `make test` runs the suite on two workers, a test file per worker at a time
            'pytest-xdist>=3.6',   # --no-loadscope-reorder
            'hypothesis>=6',
            'flake8',
            'pydocstyle',
            # ament's flake8 front end, as colcon test runs it (test/test_lint.py)
            'ros-jazzy-ament-flake8',
            'rosbags>=0.9',
            'control>=0.9.4',
            'colcon-common-extensions',
            'distributed>=2024.1',
        ],
        'bench': [
            'rosbags>=0.9',
            'control>=0.9.4',
        ],
    },
    zip_safe=True,
    maintainer='motor_comp developers',
    maintainer_email='motor-comp@example.org',
    description=('Precision servo axis simulation, friction/ripple compensation and '
                 'model workbench'),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'motor-comp = motor_comp.cli.main:main',
        ] + [f'{n} = motor_comp.nodes.{n}:main' for n in NODES],
    },
)
