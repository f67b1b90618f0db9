"""Where the course files are and which ones visla-edu knows (recognised by sha256), and their labels.

Nothing here reads a file.
"""

import os
import re
from pathlib import Path

from visla_edu._files import expand_user
from visla_edu.data._format import FORMAT_2019, FORMAT_2021

__all__ = [
    "ENV_VAR",
    "REGISTRY",
    "SIMULATED",
    "COURSE_NAMES",
    "COURSE2025_NAME",
    "STANDIN_INPUTS",
    "data_dir",
    "resolve_dir",
    "available",
    "missing_standin_inputs",
    "identify",
    "ground_truth_files",
    "course2025_files",
]

#: Environment variable naming the folder with the course files.
ENV_VAR = "VISLA_EDU_DATA"

#: Names that :func:`~visla_edu.data.load` answers with a simulated drive, and their preset.
SIMULATED = {"sim": "course", "sim-small": "small", "sim-tiny": "tiny"}

#: Known course files: name -> sha256, format and a description (used as ``Dataset.label``);
#: ``"ground_truth"`` names the drive's KITTI odometry pose and times files, when it has them.
REGISTRY = {
    "03": {
        "sha256": "fdfd30237cb0a5697625af7392acc2a241c2be299a7d5cf2d0e189fa95a1f0c9",
        "format": FORMAT_2021,
        "description": "dataset 3: KITTI-360 drive 2013_05_28_drive_0003, "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "10": {
        "sha256": None,  # no public copy of the full file was available to hash
        "format": FORMAT_2021,
        "description": "dataset 10: KITTI-360 drive 2013_05_28_drive_0010, "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "0022": {
        "sha256": "f190bd587bb8178185cae90113b51601caf66b81a6173032dbd5a450ca0e8c8b",
        "format": FORMAT_2019,
        "description": "KITTI raw 2011_09_26_drive_0022 (2019/2020 course format), "
        "10 Hz stereo feature tracks + IMU velocities",
    },
    "0020": {
        "sha256": "df224984db4668f1ca386f3e4025b9cd0a5d09a83c5837730d3f9107c15c76fc",
        "format": FORMAT_2019,
        "description": "KITTI raw 2011_09_30_drive_0020 = KITTI odometry sequence 06 (2019/2020 course format), "
        "10 Hz stereo feature tracks + IMU velocities",
        # KITTI odometry poses/06.txt and sequences/06/times.txt, renamed: looked for beside the npz
        "ground_truth": {"poses": "kitti_odometry_06_poses.txt", "times": "kitti_odometry_06_times.txt"},
    },
    "0042": {
        "sha256": "379f3c8f80adf918e67ddd72c3c716923c6a19fd37d972d6f5345ee07e3d5590",
        "format": FORMAT_2019,
        "description": "KITTI raw 2011_10_03_drive_0042 = the first 500 frames of KITTI odometry sequence 01 "
        "(2019/2020 course format), 10 Hz stereo feature tracks + IMU velocities",
        # KITTI odometry poses/01.txt and sequences/01/times.txt (the whole sequence, 1101 rows), renamed
        "ground_truth": {"poses": "kitti_odometry_01_poses.txt", "times": "kitti_odometry_01_times.txt"},
    },
    "10_imu_only": {
        "sha256": "5543a9f404a80564b1ea382b7c2101652f3ef0829aa53fe16f0bbd93257018aa",
        "format": "2021+ (IMU only)",
        "description": "dataset 10: KITTI-360 drive 2013_05_28_drive_0010, IMU velocities only "
        "(no features); the input of the stand-in load('10')",
    },
}
#: Course names :func:`~visla_edu.data.load` finds as ``<data dir>/<name>.npz``.
COURSE_NAMES = ("03", "10", "0022", "0020", "0042")
#: Files the dataset-10 stand-in is built from when ``10.npz`` is absent.
STANDIN_INPUTS = ("10_imu_only.npz", "03.npz")
#: Names of the 2025+ course files (``datasetNN``): found as ``<data dir>/datasetNN/datasetNN.npy``
#: (the course's layout), else ``<data dir>/datasetNN.npy``; none is registered (no known copy).
COURSE2025_NAME = re.compile(r"^dataset\d+$")


def resolve_dir(path=None):
    """``(directory, how)``: :func:`data_dir`'s folder and where it came from (``"VISLA_EDU_DATA=/data"``)."""
    if path is not None:
        return expand_user(path).resolve(), "the data_dir argument"
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return expand_user(env).resolve(), f"{ENV_VAR}={env}"
    return (Path.cwd() / "data").resolve(), f"the default ./data ({ENV_VAR} is not set)"


def data_dir(path=None):
    """The folder with the course files, absolute and not checked to exist.

    ``path`` if given, else ``VISLA_EDU_DATA`` if set and not empty, else ``./data`` under the current working
    directory.
    """
    return resolve_dir(path)[0]


def available(data_dir=None):
    """Names (list of str) :func:`~visla_edu.data.load` can answer now, for menus in the CLI and widgets.

    Course names whose files exist (``"10"`` also with only the stand-in inputs), the 2025+ ``datasetNN``
    found (either place of :func:`course2025_files`), then ``"sim"``.
    """
    directory, _ = resolve_dir(data_dir)
    names = [name for name in COURSE_NAMES
             if (directory / f"{name}.npz").is_file() or (name == "10" and not missing_standin_inputs(directory))]
    candidates = [*directory.glob("dataset*/dataset*.npy"), *directory.glob("dataset*.npy")] if directory.is_dir() \
        else []
    found = {p.stem for p in candidates if COURSE2025_NAME.match(p.stem) and p in course2025_files(p.stem, directory)
             and p.is_file()}
    return names + sorted(found) + ["sim"]


def course2025_files(name, directory):
    """``[<directory>/datasetNN/datasetNN.npy, <directory>/datasetNN.npy]``: where ``datasetNN`` is looked for."""
    return [directory / name / f"{name}.npy", directory / f"{name}.npy"]


def missing_standin_inputs(directory):
    """The :data:`STANDIN_INPUTS` that are not regular files (links followed) in ``directory``, in order."""
    return [f for f in STANDIN_INPUTS if not (directory / f).is_file()]


def identify(path, sha, stored_name=None, stored_label=None):
    """``(name, label, known)`` of a loaded file; ``known`` is its :data:`REGISTRY` name, or None.

    A file whose sha256 (hex) is registered gets that entry's name and description. Other files
    keep the ``stored_name`` and ``stored_label`` :func:`~visla_edu.data.save` wrote, else are named
    after the file; a file named like a known one but with another hash says so in its label.
    """
    known = next((n for n, entry in REGISTRY.items() if entry["sha256"] == sha), None)
    if known is not None:
        return known, REGISTRY[known]["description"], known
    name = stored_name if stored_name is not None else path.stem
    if stored_label is not None:
        return name, stored_label, None
    entry = REGISTRY.get(path.stem)
    if entry is None:
        return name, f"{path.name} (not a known course file)", None
    if entry["sha256"] is None:
        return name, f"{entry['description']} (sha256 {sha} not on record)", None
    return name, f"{entry['description']} -- but this copy's sha256 differs from the known file (modified?)", None


def ground_truth_files(name, directory):
    """``(poses, times)`` paths the registry names for drive ``name``, if its poses file is in ``directory``.

    ``times`` is None when absent (the times are then not checked); the result is None when the drive has no
    registered ground truth or its poses file is absent.
    """
    files = REGISTRY.get(name, {}).get("ground_truth")
    if files is None or not (directory / files["poses"]).is_file():
        return None
    times = directory / files["times"]
    return directory / files["poses"], times if times.is_file() else None
