"""The measured part of the project's rubric, its one home: the bands, :func:`rubric_table` (PROJECT.md's
table, kept equal by a test) and :func:`measured_points`.
"""

from visla_edu.codes import DEADRECKON, SLAM, VIO

__all__ = ["COMPLETES_POINTS", "ACCURACY_BANDS", "CONSISTENCY_BANDS", "MEASURED_TOTAL", "rubric_table",
           "accuracy_unscored", "measured_points"]

#: Points for completing the drive (every frame, valid records, in time, no hidden call).
COMPLETES_POINTS = 10
#: Accuracy bands ``(points, reference mode, factor)``: earned when the aligned ATE is at most
#: ``factor`` times that reference's on the same drive (the best band earned counts).
ACCURACY_BANDS = ((25, SLAM, 1.25), (18, VIO, 1.25), (10, DEADRECKON, 1.05))
#: Consistency bands ``(points, low, high)``: earned when the mean pose NEES per degree of freedom
#: lies in ``[low, high]``. Scored on simulated drives only, whose noise is what a filter assumes
#: (on the KITTI drives even the library's joint SLAM shows NEES/dof in the tens: the truth and the
#: noise are not the model's); reported on every drive with ground truth.
CONSISTENCY_BANDS = ((5, 0.1, 3.0), (2, 0.02, 10.0))
#: The grader's part of the rubric; the report's part is PROJECT.md's.
MEASURED_TOTAL = COMPLETES_POINTS + ACCURACY_BANDS[0][0] + CONSISTENCY_BANDS[0][0]
_LABELS = {SLAM: "joint SLAM (`slam`)", VIO: "VIO (`vio`)", DEADRECKON: "dead reckoning (`deadreckon`)"}


def rubric_table():
    """The measured part of the rubric as a Markdown table (PROJECT.md holds this very text)."""
    rows = ["| criterion | points | earned when |", "|---|---|---|",
            f"| completes | {COMPLETES_POINTS} | every frame of the drive within the time limit, each record a "
            "`StepRecord` with a finite SE(3) pose and covariance, no hidden library call |"]
    for k, (points, mode, factor) in enumerate(ACCURACY_BANDS):
        name = "| accuracy |" if k == 0 else "| |"
        rows.append(f"{name} {points} | completes, aligned ATE at most {factor:g} x the library's "
                    f"{_LABELS[mode]} on the same drive |")
    rows.append("| | 0 | otherwise (not scored without ground truth, or where dead reckoning alone earns the top "
                "band) |")
    for k, (points, low, high) in enumerate(CONSISTENCY_BANDS):
        name = "| consistency (simulated drives) |" if k == 0 else "| |"
        rows.append(f"{name} {points} | completes, mean pose NEES per degree of freedom in [{low:g}, {high:g}] |")
    rows.append("| | 0 | otherwise (or a real drive: reported, not scored) |")
    rows.append(f"| **measured total** | **{MEASURED_TOTAL}** | |")
    return "\n".join(rows)


def accuracy_unscored(references):
    """Why accuracy is not scored on a drive (``""`` when it is): no ground truth, or dead reckoning earns the top band.

    ``references``: dict of mode (``slam``, ``vio``, ``deadreckon``) to the library's
    :class:`visla_edu.course.project.Measures` on the drive.
    """
    if references[SLAM].evaluation is None:
        return "the drive has no ground truth"
    _, mode, factor = ACCURACY_BANDS[0]
    top, dead_reckoning = references[mode].evaluation.ate_aligned, references[DEADRECKON].evaluation.ate_aligned
    if dead_reckoning <= factor * top:
        return (f"dead reckoning alone earns the top band here ({dead_reckoning:.3f} m <= {factor:g} x {top:.3f} m): "
                "the drive cannot show what the camera adds")
    return ""


def measured_points(measures, references, completed, simulated):
    """The grader's points of one submission: ``{"completes": p, "accuracy": p, "consistency": p}``.

    ``measures`` (or None) and ``references`` as :func:`accuracy_unscored`; ``completed``: status ``ok``;
    ``simulated``: the ground truth is a simulation's. A value is None where that criterion is not scored
    on this drive (accuracy: :func:`accuracy_unscored`; consistency: no ground truth, or a real drive).
    """
    has_truth = references[SLAM].evaluation is not None
    scored = not accuracy_unscored(references)
    points = {"completes": COMPLETES_POINTS if completed else 0, "accuracy": 0 if scored else None,
              "consistency": 0 if has_truth and simulated else None}
    if not completed or not has_truth:
        return points
    ate = measures.evaluation.ate_aligned
    if scored:
        points["accuracy"] = max([p for p, mode, factor in ACCURACY_BANDS
                                  if ate <= factor * references[mode].evaluation.ate_aligned], default=0)
    if simulated:
        points["consistency"] = max([p for p, low, high in CONSISTENCY_BANDS if low <= measures.nees_per_dof <= high],
                                    default=0)
    return points
