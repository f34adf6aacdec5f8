"""Experiment design above the workbench: identification runs chosen for what they teach.

``excite`` (:mod:`.excite`) designs an identification trajectory from a start model and
the axis limits and predicts the standard errors a fit will report on its run.  The
package uses the control layer (trajectories, simulator) and only the workbench's
public entry points (``fit.fit``, ``derivatives.kinematics``); it never imports rclpy.
"""
