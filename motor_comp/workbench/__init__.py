"""The model workbench (DESIGN.md §6): from a measured run to a better model.

Compare a model with a run, see where it fails, learn which physical effect is
missing, add it and watch the error fall.

Pipeline: :func:`kinematics` (zero-phase derivatives) → :func:`residual` (inverse model
``r = F_in − M·ẍ − Σ F_k``) → :func:`diagnose` (candidate effects ranked on held-out
time blocks) → :func:`fit` (add effects, refit all parameters); :func:`compare` adds the
position view (k-step prediction, closed-loop replay).  Numpy core: no ROS imports.
"""
from __future__ import annotations

from motor_comp.workbench.compare import Comparison, compare, predict
from motor_comp.workbench.derivatives import InputHold, Kinematics, kinematics
from motor_comp.workbench.diagnose import CandidateResult, Diagnosis, diagnose
from motor_comp.workbench.fit import FitResult, FitStep, add_effects, fit, refit_linear
from motor_comp.workbench.residual import Residual, force_nrmse, residual
from motor_comp.workbench.session import Session, load_run, open_session

__all__ = ['CandidateResult', 'Comparison', 'Diagnosis', 'FitResult', 'FitStep', 'InputHold',
           'Kinematics', 'Residual', 'Session', 'add_effects', 'compare', 'diagnose', 'fit',
           'force_nrmse', 'kinematics', 'load_run', 'open_session', 'predict', 'refit_linear',
           'residual']
