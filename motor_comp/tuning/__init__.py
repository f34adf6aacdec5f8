"""``motor-comp autotune``: from a start model to a compensated axis, through the nodes.

:mod:`~motor_comp.tuning.plan` (the task, the limits, the segments' tables, the scores;
no rclpy), :mod:`~motor_comp.tuning.session` (the node processes and this process's ROS
client), :mod:`~motor_comp.tuning.autotune` (the stages) and
:mod:`~motor_comp.tuning.report` (``index.html``, ``autotune.json``).  Above the core:
it drives the ROS nodes, the workbench and the experiment design.
"""
