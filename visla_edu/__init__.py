"""visla-edu: visual-inertial SLAM with an extended Kalman filter, for teaching.

Import the module you need (nothing runs at import time); each module's docstring says what it
holds. The estimator: ``lie``, ``camera``, ``motion``, ``ekf``, ``filters``, ``smoother``, ``run``;
the data: ``dataset``, ``data``, ``simulate``, ``trajectory``, ``validation``; judging and
showing a run: ``metrics``, ``diagnostics``, ``plotting``, ``stepper``; shared pieces: ``codes``,
``settings``, ``cache``; the course's tools: ``course``; the command line: ``cli``.
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
