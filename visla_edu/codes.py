"""Names shared by every layer: observation status codes, filter and smoother mode names.

A leaf module (it imports nothing of the package), so views and the command line can use the
codes and the mode names without importing the filters.

Observation status (one code per observation in :class:`visla_edu.filters.StepRecord`)::

    OBS_USED      used in the update
    OBS_GATED     rejected by the Mahalanobis gate (outlier)
    OBS_NEW       first observation: the landmark entered the state here
    OBS_NO_DEPTH  non-positive disparity: a broken stereo match, never used
    OBS_FAR       disparity too small to initialise the landmark (not yet in the state)
    OBS_IGNORED   not used by this mode (dead reckoning, landmark stride, repeated frame)
    OBS_DELAYED   held for its track's multi-frame update (joint SLAM with clones: a landmark
                  outside the state; the track's outcome, used or gated, is counted when the
                  track is used, :attr:`visla_edu.filters.JointSlam.track_counts`)

``STATUS_NAMES[code]`` is the code's name in summaries and per-status counts.
"""

__all__ = [
    "OBS_USED",
    "OBS_GATED",
    "OBS_NEW",
    "OBS_NO_DEPTH",
    "OBS_FAR",
    "OBS_IGNORED",
    "OBS_DELAYED",
    "STATUS_NAMES",
    "DEADRECKON",
    "MAPPING",
    "VIO",
    "SLAM",
    "MODES",
    "SMOOTH",
    "WINDOW",
    "SMOOTHER_MODES",
    "RUN_MODES",
    "RUN_MODES_HELP",
]

OBS_USED = 0  #: used in the update
OBS_GATED = 1  #: rejected by the Mahalanobis gate (outlier)
OBS_NEW = 2  #: first observation: the landmark entered the state here
OBS_NO_DEPTH = 3  #: non-positive disparity: a broken stereo match, never used
OBS_FAR = 4  #: disparity too small to initialise the landmark (not yet in the state)
OBS_IGNORED = 5  #: not used by this mode (dead reckoning, landmark stride, repeated frame)
OBS_DELAYED = 6  #: held for its track's multi-frame update (joint SLAM with clones)
STATUS_NAMES = ("used", "gated", "new", "no depth", "too far", "ignored", "delayed")

DEADRECKON = "deadreckon"  #: IMU prediction only
MAPPING = "mapping"  #: poses from dead reckoning, one 3x3 EKF per landmark
VIO = "vio"  #: pose EKF against landmarks fixed at their first triangulation
SLAM = "slam"  #: joint EKF over the pose and the landmarks (active set or dense)

#: Filter modes by name, in teaching order.
MODES = (DEADRECKON, MAPPING, VIO, SLAM)

SMOOTH = "smooth"  #: batch least squares over the whole drive, started from the joint EKF
WINDOW = "window"  #: fixed-lag sliding-window least squares, frame by frame

#: Smoother modes (:mod:`visla_edu.smoother`); they run over the whole drive, not step by step.
SMOOTHER_MODES = (SMOOTH, WINDOW)
#: Everything ``visla-edu run --mode`` takes: the filters, then the smoothers.
RUN_MODES = MODES + SMOOTHER_MODES
#: ``visla-edu run --mode``'s help: each mode in a few words.
RUN_MODES_HELP = ("deadreckon (IMU only), mapping (landmarks on dead-reckoned poses), vio (pose EKF against "
                  "fixed landmarks), slam (joint EKF, the default), smooth (batch smoother started from the EKF), "
                  "window (sliding-window smoother)")
