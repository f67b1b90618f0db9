"""Names shared by every layer: observation status codes, filter and smoother mode names.

A leaf module (it imports nothing of the package), so views and the command line can use the
codes and the mode names without importing the filters. The observation status is one
vocabulary for every mode: one code per observation in a filter's
:class:`visla_edu.filters.StepRecord` and in a smoother's ``SmootherResult.obs_status``, and a
column per code, named ``STATUS_NAMES[code]``, in ``RunResult.status_counts``. Codes are only
ever appended, so a count saved with fewer columns is the first columns of today's.
"""

__all__ = [
    "OBS_USED",
    "OBS_GATED",
    "OBS_NEW",
    "OBS_NO_DEPTH",
    "OBS_FAR",
    "OBS_IGNORED",
    "OBS_DELAYED",
    "OBS_DROPPED",
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

#: Used in the update (a smoother: in the final solution).
OBS_USED = 0
#: Rejected as an outlier by a chi-square test of its Mahalanobis distance: the filters' gate on the
#: innovation, the smoothers' test of the residual at their solution (rounds of rejection).
OBS_GATED = 1
#: First observation: the landmark entered the state here (filters).
OBS_NEW = 2
#: Non-positive disparity: a broken stereo match, never used.
OBS_NO_DEPTH = 3
#: Disparity too small to initialise the landmark (not yet in the state; filters).
OBS_FAR = 4
#: Not used by this mode (dead reckoning, landmark stride, repeated frame, stale copy).
OBS_IGNORED = 5
#: Held for its track's multi-frame update (joint SLAM with clones: a landmark outside the state);
#: the track's outcome, used or gated, is counted when the track is used
#: (:attr:`visla_edu.filters.JointSlam.track_counts`).
OBS_DELAYED = 6
#: Usable, but its landmark was left out of the estimate (smoothers: too few observations, behind a
#: camera, too far, no position; ``SmootherResult.rejected`` counts the landmarks by reason).
OBS_DROPPED = 7
STATUS_NAMES = ("used", "gated", "new", "no depth", "too far", "ignored", "delayed", "dropped")

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
