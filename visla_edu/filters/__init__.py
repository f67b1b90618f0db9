"""The four filter modes as small state machines that advance one frame per ``step()``.

:class:`DeadReckoning`, :class:`LandmarkMapping`, :class:`VisualInertialOdometry` and
:class:`JointSlam` (on the active set, :class:`ActiveSet`, or dense); :mod:`visla_edu.codes` says
each mode in a line. Each ``step()`` returns a :class:`StepRecord`, its observations marked with
the status codes of :mod:`visla_edu.codes` (re-exported here). :class:`FilterConfig` holds the
modes' settings; :func:`visla_edu.run.make_filter` builds a mode by name.

Where each piece lives: ``_config`` the settings, ``_base`` the step loop, its hooks, the record and
the divergence error, ``_state`` the joint covariance's bookkeeping, ``_maps`` dead reckoning,
mapping and VIO, ``_slam`` joint SLAM, ``_clones`` its clone window, ``_tracks`` the track updates.
"""

from visla_edu.codes import (
    OBS_DELAYED,
    OBS_FAR,
    OBS_GATED,
    OBS_IGNORED,
    OBS_NEW,
    OBS_NO_DEPTH,
    OBS_USED,
    STATUS_NAMES,
)
from visla_edu.filters._base import MAX_DISTANCE, MIN_DEPTH, FilterBase, FilterDivergedError, StepRecord
from visla_edu.filters._config import AUTO, AUTO_FIELDS, MAX_IMU_LAG, FilterConfig
from visla_edu.filters._maps import DeadReckoning, LandmarkMapping, VisualInertialOdometry
from visla_edu.filters._slam import DENSE_PLACEHOLDER_VARIANCE, MAX_DENSE_BYTES, JointSlam
from visla_edu.filters._state import ActiveSet

__all__ = [
    "FilterConfig",
    "AUTO",
    "AUTO_FIELDS",
    "MAX_IMU_LAG",
    "FilterBase",
    "FilterDivergedError",
    "StepRecord",
    "OBS_USED",
    "OBS_GATED",
    "OBS_NEW",
    "OBS_NO_DEPTH",
    "OBS_FAR",
    "OBS_IGNORED",
    "OBS_DELAYED",
    "STATUS_NAMES",
    "DeadReckoning",
    "LandmarkMapping",
    "VisualInertialOdometry",
    "JointSlam",
    "ActiveSet",
    "MAX_DISTANCE",
    "MIN_DEPTH",
    "DENSE_PLACEHOLDER_VARIANCE",
    "MAX_DENSE_BYTES",
]
