"""Load, check, save and summarise the course data files.

The data directory is, in this order: the ``data_dir`` argument, the environment variable
``VISLA_EDU_DATA``, or ``./data`` under the current working directory (course files are never copied
into the project).

    >>> from visla_edu import data
    >>> ds = data.load("03")                # <data dir>/03.npz
    >>> print(data.format_summary(ds))      # what ``visla-edu info 03`` prints
    >>> sim = data.load("sim")              # a simulated drive with ground truth

Throughout, T is the number of frames, M of landmarks and N of observations.

The two npz course formats (2019-2024)
--------------------------------------
Both store ``time_stamps`` (1, T), ``features`` (4, M, T) with ``[uL, vL, uR, vR]``
pixels (all four -1 where landmark m is not seen at frame t), ``linear_velocity``
(3, T), ``K`` (3, 3) and ``b`` (). The 2021+ format adds ``angular_velocity`` (3, T)
and ``imu_T_cam`` (4, 4); the 2019/2020 format has ``rotational_velocity`` (3, T)
and ``cam_T_imu`` (4, 4), the inverse transform. :func:`save` writes the 2021+ format,
plus the ground truth of a simulated drive (:data:`GROUND_TRUTH_KEYS`) and the
:data:`TEXT_KEYS` ``name`` and ``label``. :func:`load` converts both to the time-major
:class:`~visla_edu.dataset.Dataset`, streaming the dense features (never held whole).

The 2025+ format
----------------
``datasetNN/datasetNN.npy``, ``np.save`` of a dict (the course reads it with
``np.load(path, allow_pickle=True).item()``):

==============================  ===========================================================
key                             value
==============================  ===========================================================
``timestamps``                  (T,) UNIX seconds (also (1, T) or (T, 1))
``v_t``, ``w_t``                linear and angular velocity, (T, 3) or (3, T)
``features``                    (4, M, T) pixels ``[uL, vL, uR, vR]``, -1 where unobserved;
                                absent or None in a dataset shipped with images
                                (``datasetNN_imgs.npy``), whose features students track
``K_l``, ``K_r``                the two cameras' intrinsics (3, 3)
``extL_T_imu``, ``extR_T_imu``  the two cameras' extrinsics (4, 4)
==============================  ===========================================================

It is read without unpickling anything but plain arrays (module ``_pickle``); the velocity
layout and the extrinsics' direction and camera frame are decided from the data (module
``_format2025``, :func:`load_course2025`). :func:`save_course2025` writes a drive in it.

When ``10.npz`` is absent, ``load("10")`` builds a stand-in (:func:`standin_dataset10`): dataset 10's
real IMU drive with simulated stereo tracks; :func:`course_standin10` varies its seed and settings.
KITTI odometry ground truth of real drives (``poses/NN.txt``, ``times.txt``) is read, checked and
converted to ``world_T_imu`` by :func:`load_ground_truth` / :func:`attach_ground_truth` (module
``_groundtruth``); a registered drive (``"0020"``) gets its own automatically.

Errors
------
Every problem with a file is a ``FileNotFoundError`` or ``ValueError`` (or, for a folder or an
unreadable file, ``IsADirectoryError`` or ``PermissionError``) whose message names the file, the key,
and the expected and actual shape or value; the functions that read files list only what is particular
to them. A file must also be plausible (:mod:`visla_edu.validation`, :mod:`~visla_edu.data._plausible`),
and the declared array sizes are bounded from the headers before any data is read. In the private
modules ``path`` (pathlib.Path or str) is the file and ``key`` an array's key in it, both only named in
messages.

Modules (private; everything public is re-exported here): ``_load``, ``_registry``, ``_npz``,
``_zip``, ``_format``, ``_features``, ``_plausible``, ``_format2025``, ``_pickle`` (reading);
``_standin``, ``_groundtruth``; ``_save``, ``_save2025`` (writing); ``_summary``.
"""

from visla_edu.data._format import FORMAT_2019, FORMAT_2021, FORMAT_KEYS, GROUND_TRUTH_KEYS, TEXT_KEYS
from visla_edu.data._format2025 import FORMAT_2025, KEYS_2025, NO_FEATURES, READING_ORDER, load_course2025
from visla_edu.data._groundtruth import (
    MIN_POSES,
    TIME_TOLERANCE,
    attach_ground_truth,
    attach_registered_ground_truth,
    check_times,
    imu_poses_from_kitti,
    kitti_poses_from_imu,
    load_ground_truth,
    read_kitti_times,
)
from visla_edu.data._load import input_files, load
from visla_edu.data._plausible import calibration_problems, dataset_problems
from visla_edu.data._registry import ENV_VAR, REGISTRY, SIMULATED, available, data_dir, ground_truth_files
from visla_edu.data._save import save
from visla_edu.data._save2025 import VELOCITY_LAYOUTS, save_course2025
from visla_edu.data._standin import STANDIN_LABEL, STANDIN_NUM_LANDMARKS, course_standin10, standin_dataset10
from visla_edu.data._summary import format_summary, summarize
from visla_edu.dataset import repeated_frames
from visla_edu.validation import RIGID_TOL, magnitude

__all__ = [
    "ENV_VAR",
    "FORMAT_2021",
    "FORMAT_2019",
    "FORMAT_2025",
    "FORMAT_KEYS",
    "KEYS_2025",
    "READING_ORDER",
    "NO_FEATURES",
    "VELOCITY_LAYOUTS",
    "REGISTRY",
    "SIMULATED",
    "GROUND_TRUTH_KEYS",
    "TEXT_KEYS",
    "RIGID_TOL",
    "STANDIN_LABEL",
    "STANDIN_NUM_LANDMARKS",
    "data_dir",
    "load",
    "load_course2025",
    "input_files",
    "dataset_problems",
    "calibration_problems",
    "magnitude",
    "save",
    "save_course2025",
    "available",
    "repeated_frames",
    "standin_dataset10",
    "course_standin10",
    "summarize",
    "format_summary",
    "MIN_POSES",
    "TIME_TOLERANCE",
    "load_ground_truth",
    "attach_ground_truth",
    "attach_registered_ground_truth",
    "read_kitti_times",
    "check_times",
    "imu_poses_from_kitti",
    "kitti_poses_from_imu",
    "ground_truth_files",
]
