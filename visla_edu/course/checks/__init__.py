"""Checks for the notebook exercises: compare a student's function with the library.

Every ``check_<name>(fn, hidden=False)`` calls the student's ``fn`` (its signature in the check's
summary line) on random and edge-case inputs, compares with the library version and

* prints one ``✓ ...`` line when everything agrees (``hidden=True`` runs other cases, drawn from
  ``VISLA_EDU_HIDDEN_SEED`` if set, else from a built-in seed, and prints nothing on success; a
  value of that variable that is not a non-negative integer raises ``ValueError``);
* raises ``AssertionError`` otherwise (a wrong type, shape or values, a crash, a call to a hidden
  library function, a change to ``visla_edu``). The message's first line (at most 79 characters,
  :mod:`~visla_edu.course.checks._core`) names the likely mistake, a deliberately wrong variant
  that the output equals (the ``(hint, variant)`` lists beside each check);
* raises ``NotImplementedError`` while the exercise is still the student notebook's stub.

A check's docstring gives its reference, its tolerances (else those of
:func:`~visla_edu.course.checks._core.compare`, ``rtol=1e-7``, ``atol=1e-9``) and what it hides
(:mod:`visla_edu.course.checks._hiding`). Camera checks' hidden cases use another rig
(:func:`~visla_edu.course.checks._inputs.rig`). The visible inputs come from a fixed seed.

Graded cells load a fresh copy, so that nothing an answer cell assigned to the checks counts::

    import importlib, visla_edu.course.checks
    _checks = importlib.reload(visla_edu.course.checks)
    _checks.check_hat(hat)

Conventions (twists ``[v; w]``, the right perturbation): :mod:`visla_edu.lie`; the motion
model: :mod:`visla_edu.motion`.
"""

import importlib as _importlib
import sys as _sys

#: Submodules in dependency order; a reload of this package reloads them all.
_SUBMODULES = ("_hiding", "_core", "_inputs", "_data", "_diagnostics", "_primer", "_kinematics", "_uncertainty", "_camera", "_jacobians", "_filters",
               "_observability", "_consistency", "_smoothing", "_capstone")


def _load_submodules():
    """Import each submodule, or re-execute it if it is loaded (a fresh copy after a reload)."""
    for short in _SUBMODULES:
        full = f"{__name__}.{short}"
        if full in _sys.modules:
            _importlib.reload(_sys.modules[full])
        else:
            _importlib.import_module(full)


_load_submodules()

from visla_edu.course.checks._camera import (check_init_landmark, check_project, check_stereo_matrix,  # noqa: E402
                                      check_triangulate)
from visla_edu.course.checks._capstone import (capstone_steps, check_capstone_landmarks,  # noqa: E402
                                        check_capstone_predict, check_capstone_slam, reference_capstone_steps)
from visla_edu.course.checks._consistency import (check_align_rigid, check_average_nees_bounds, check_gate,  # noqa: E402
                                           check_motion_noise, check_nees)
from visla_edu.course.checks._core import student_or_reference  # noqa: E402
from visla_edu.course.checks._data import check_observations_at, check_track_spans  # noqa: E402
from visla_edu.course.checks._diagnostics import check_white_noise  # noqa: E402
from visla_edu.course.checks._filters import (check_dense_covariance_bytes, check_landmark_observation_noise,  # noqa: E402
                                       check_landmark_update, check_marginalize, check_pose_update,
                                       check_slam_jacobian, reference_dense_covariance_bytes)
from visla_edu.course.checks._hiding import LibraryFunctionHidden, function_label  # noqa: E402
from visla_edu.course.checks._jacobians import (check_landmark_jacobian, check_numerical_jacobian, check_odot,  # noqa: E402
                                         check_pose_jacobian, check_projection_jacobian,
                                         reference_numerical_jacobian)
from visla_edu.course.checks._kinematics import (check_dead_reckon, check_hat, check_se3_exp, check_so3_exp,  # noqa: E402
                                          check_so3_log)
from visla_edu.course.checks._observability import (check_invariant_pose_jacobian, check_slam_null_space,  # noqa: E402
                                             reference_slam_null_space)
from visla_edu.course.checks._primer import check_kalman_predict, check_kalman_update_1d  # noqa: E402
from visla_edu.course.checks._uncertainty import (check_curly_hat, check_left_pose_prediction,  # noqa: E402
                                           check_pose_transition, reference_left_pose_prediction)
from visla_edu.course.checks._smoothing import (check_gauss_newton_step, check_motion_residual,  # noqa: E402
                                         check_pose_marginal_covariance, check_schur_reduce,
                                         reference_gauss_newton_step, reference_pose_marginal_covariance,
                                         reference_schur_reduce)

__all__ = [
    "student_or_reference",
    "reference_numerical_jacobian",
    "reference_dense_covariance_bytes",
    "reference_schur_reduce",
    "reference_pose_marginal_covariance",
    "reference_gauss_newton_step",
    "reference_left_pose_prediction",
    "reference_slam_null_space",
    "LibraryFunctionHidden",
    "function_label",
    # 00 know your data
    "check_observations_at",
    "check_track_spans",
    # 00b Kalman-filter primer
    "check_kalman_update_1d",
    "check_kalman_predict",
    # 01 SE(3) kinematics
    "check_hat",
    "check_so3_exp",
    "check_so3_log",
    "check_se3_exp",
    # 02 stereo camera
    "check_stereo_matrix",
    "check_project",
    "check_triangulate",
    # 03 Jacobians
    "check_projection_jacobian",
    "check_odot",
    "check_numerical_jacobian",
    "check_pose_jacobian",
    # 04 diagnose and calibrate
    "check_dead_reckon",
    "check_white_noise",
    # 05 landmark mapping
    "check_landmark_jacobian",
    "check_init_landmark",
    "check_landmark_update",
    # 06 pose uncertainty
    "check_curly_hat",
    "check_pose_transition",
    "check_left_pose_prediction",
    # 07 visual-inertial odometry
    "check_pose_update",
    "check_landmark_observation_noise",
    # 08 joint SLAM
    "check_slam_jacobian",
    "check_slam_null_space",
    # 09 the active set
    "check_dense_covariance_bytes",
    "check_marginalize",
    # 10 consistency
    "check_motion_noise",
    "check_nees",
    "check_average_nees_bounds",
    "check_invariant_pose_jacobian",
    # 11 outliers and real data
    "check_gate",
    "check_align_rigid",
    # 12 capstone
    "check_capstone_predict",
    "check_capstone_landmarks",
    "check_capstone_slam",
    "capstone_steps",
    "reference_capstone_steps",
    # 13 smoothing
    "check_motion_residual",
    "check_schur_reduce",
    # 14 filter and smoother
    "check_gauss_newton_step",
    "check_pose_marginal_covariance",
]
