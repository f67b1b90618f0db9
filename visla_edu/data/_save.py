"""Write a Dataset as a course file that :func:`~visla_edu.data.load` reads back exactly."""


import numpy as np

from visla_edu._files import atomic_write, expand_user
from visla_edu.camera import same_intrinsics
from visla_edu.data._format import GROUND_TRUTH_FIELDS

__all__ = ["save"]


def save(dataset, path):
    """Write a dataset as a 2021+ course file ``path`` (``.npz`` appended if missing); return the absolute path.

    A simulated drive's ground truth, name and label are written with it, a real drive's KITTI poses are not;
    a 2025+ drive keeps its one reading of the extrinsics (``imu_T_cam``), and one with two intrinsics is refused
    (``ValueError``: the format has one ``K``). Written atomically, the dense features ``(4, M, T)`` built in memory;
    :func:`~visla_edu.data.load` on the file gives back identical arrays.
    """
    if not same_intrinsics(dataset.K, dataset.K_right):
        raise ValueError(f"save: {dataset.name} has two intrinsics (K_l != K_r), but the 2021+ format holds one K; "
                         "write it in the 2025+ format with data.save_course2025")
    path = expand_user(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays = _course_arrays(dataset)
    arrays.update(_ground_truth_arrays(dataset))
    arrays["name"] = np.array(str(dataset.name))
    arrays["label"] = np.array(str(dataset.label))
    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path.resolve()


def _course_arrays(dataset):
    """The 2021+ keys in the course layout: ``(k, T)`` rows and dense ``(4, M, T)`` features."""
    return {
        "time_stamps": np.asarray(dataset.time_stamps, dtype=float)[None, :],
        "features": dataset.to_dense_features(),
        "linear_velocity": np.asarray(dataset.linear_velocity, dtype=float).T,
        "angular_velocity": np.asarray(dataset.angular_velocity, dtype=float).T,
        "K": np.asarray(dataset.K, dtype=float),
        "b": np.array(float(dataset.b)),
        "imu_T_cam": np.asarray(dataset.imu_T_cam, dtype=float),
    }


def _ground_truth_arrays(dataset):
    """The ground-truth keys :func:`save` writes: a simulated drive's, complete for every frame; else none."""
    gt = dataset.ground_truth
    if gt is None or not gt.simulated or gt.num_frames != dataset.num_frames:
        return {}
    return {key: np.asarray(getattr(gt, field), dtype=dtype) for key, (field, dtype) in GROUND_TRUTH_FIELDS.items()}
