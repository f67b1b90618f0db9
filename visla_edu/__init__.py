"""visla-edu: visual-inertial SLAM with an extended Kalman filter, for teaching.

Modules (import the one you need; nothing runs at import time):
``lie`` SE(3) kinematics, ``camera`` stereo model, ``dataset`` the Dataset class,
``data`` loading the course files, ``simulate`` drives with ground truth, ``motion``
IMU prediction, ``ekf`` the update steps, ``filters`` the filter modes and their settings,
``smoother`` batch and sliding-window least squares, ``codes`` observation codes and mode
names, ``settings`` the declared settings, ``validation`` calibration and rigidity checks,
``run`` the driver (and ``run.workload`` the cost estimate before a run), ``metrics`` (ATE,
drift, NEES), ``trajectory`` KITTI and TUM trajectory files, ``diagnostics`` the calibration
from the data (and ``diagnostics.odometry`` stereo visual odometry), ``cache`` the user cache,
``plotting``, ``stepper`` the filter stepper (model, figure, widget, Voila page), ``course``
course scaffolding (``course.checks`` the exercise checks, ``course.capstone`` notebook 12's
filter loop, ``course.kalman`` the primer's linear Kalman filter, ``course.numdiff``
central differences, ``course.release`` the student notebooks, the student's folder, the
project grader, the site), ``cli`` the command line.
"""

__version__ = "0.1.0"

#: Modules that moved, and where they are now: notebooks written for an earlier version import
#: them from here (``from visla_edu import checks``), so they get a message saying what to write.
MOVED = {"checks": "visla_edu.course", "capstone": "visla_edu.course", "kalman": "visla_edu.course",
         "numdiff": "visla_edu.course", "release": "visla_edu.course", "odometry": "visla_edu.diagnostics",
         "workload": "visla_edu.run"}


def __getattr__(name):
    """A moved module's name (:data:`MOVED`): ImportError saying where it is now; others: AttributeError."""
    if name in MOVED:
        raise ImportError(f"visla_edu.{name} moved to {MOVED[name]}.{name}: write `from {MOVED[name]} import {name}` "
                          f"(a notebook from an earlier version of the course: take the new one from "
                          f"`visla-edu student DIR` into a new folder and copy your answers over)")
    raise AttributeError(f"module 'visla_edu' has no attribute {name!r}")
