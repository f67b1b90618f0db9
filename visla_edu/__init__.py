"""visla-edu: visual-inertial SLAM with an extended Kalman filter, for teaching.

Modules (import the one you need; nothing runs at import time):
``lie`` SE(3) kinematics, ``camera`` stereo model, ``dataset`` the Dataset class,
``data`` loading the course files, ``simulate`` drives with ground truth, ``motion``
IMU prediction, ``ekf`` the update steps, ``kalman`` the linear Kalman filter of the primer,
``filters`` the filter modes and their settings, ``smoother`` batch and sliding-window least
squares, ``codes`` observation codes and mode names, ``run`` the driver, ``workload`` the cost
estimate before a run, ``capstone`` notebook 12's filter loop, ``metrics`` (ATE, drift, NEES),
``trajectory`` KITTI and TUM trajectory files, ``odometry`` stereo visual odometry,
``diagnostics`` the calibration from the data, ``cache`` the user cache, ``plotting``,
``stepper`` the filter stepper (model, figure, widget, Voila page), ``checks`` the exercise
checks (``numdiff`` their central-difference reference), ``release`` the student notebooks,
``course`` course scaffolding (the student edition, a student's folder), ``cli``.
"""

__version__ = "0.1.0"
