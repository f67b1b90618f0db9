"""Which way a 2025+ file's extrinsics point and which camera frame they use, decided from evidence.

The file's ``extL_T_imu``, ``extR_T_imu`` may be read four ways
(:func:`visla_edu.camera.extrinsic_readings`). :func:`choose_reading` takes the only reading under
which the rig is rectified (the right camera on the left camera's x axis); among several, the one
the track reprojection chooses (:class:`~._tracks.TrackScorer`); else the loader's (the first
rectified one of :data:`visla_edu.data.READING_ORDER`), with a warning. Geometry comes first, as
a file's IMU axes may be flipped (dataset 03's are), which the motion would read as another
reading; the flips are decided afterwards. The motion evidence only checks the choice
(:func:`_motion_warning`).
"""

from dataclasses import asdict, dataclass

import numpy as np

from visla_edu.diagnostics._tracks import TrackChoice, TrackScorer
from visla_edu.diagnostics._vo import AGREES, DISAGREES, check_extrinsics

__all__ = ["ReadingEvidence", "choose_reading"]


@dataclass
class ReadingEvidence:
    """The evidence on the reading of a file's extrinsics, and the decision (JSON-safe).

    Attributes
    ----------
    names : list of str
        The four readings, in :func:`visla_edu.camera.extrinsic_readings`'s order.
    geometry : dict
        Name -> ``{"offset": [x, y, z], "rotation_deg": angle, "problem": text}``: the right camera
        in the left camera frame (m), the angle between the cameras, ``""`` or why not rectified.
    loader, chosen : str
        The reading the loader started from, and the one used.
    track : TrackChoice
        Among the readings (each at its best lag).
    track_scores : dict
        Name -> median left-image error (px) per lag of :data:`~._vo.LAGS` (None without pairs).
    rotation_slope, translation_slope, vo_verdict : dict
        Name -> :class:`~._vo.ExtrinsicCheck`'s slopes at lag ``slope_lag`` (None without pairs), verdict.
    reason, warning : str
        Why, in one line; ``""`` or what the user should check.
    """

    names: list
    geometry: dict
    loader: str
    track: TrackChoice
    track_scores: dict
    slope_lag: int
    rotation_slope: dict
    translation_slope: dict
    vo_verdict: dict
    chosen: str
    reason: str
    warning: str

    def to_dict(self):
        """JSON-safe dict; :meth:`from_dict` inverts it."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d):
        """A :class:`ReadingEvidence` from :meth:`to_dict`'s output; ValueError if it is malformed."""
        fields = dict(d)
        fields["track"] = TrackChoice(**fields["track"])
        evidence = cls(**fields)
        texts = [evidence.loader, evidence.chosen, evidence.reason, evidence.warning]
        if evidence.chosen not in evidence.names or not all(isinstance(t, str) for t in texts):
            raise ValueError(f"malformed reading evidence (chosen {evidence.chosen!r} of {evidence.names!r})")
        return evidence


def _finite_or_none(x):
    """A float, or None for NaN and infinity (JSON has neither)."""
    x = float(x)
    return x if np.isfinite(x) else None


def _decide(readings, loader, track):
    """``(chosen name, reason)``: geometry first, the track reprojection among several rectified readings."""
    rectified = [r.name for r in readings if r.rectified]
    if len(rectified) == 1:
        return rectified[0], "the only reading under which the right camera lies on the left camera's x axis"
    if track.chosen in rectified:
        return track.chosen, (f"the right camera lies on the left camera's x axis under {rectified}; track "
                              "reprojection: every other reading has a larger error with 95% confidence")
    return loader, (f"the right camera lies on the left camera's x axis under {rectified}, and the track reprojection "
                    f"cannot tell them apart ({track.verdict}); kept the loader's {loader!r} (the course's order)")


def _motion_warning(chosen, rectified, track, vo_verdict):
    """``""``, or a warning when the motion evidence contradicts the chosen reading or matches no reading."""
    others_agree = [k for k, v in vo_verdict.items() if v == AGREES and k != chosen]
    if len(rectified) > 1 and track.chosen not in rectified:
        return (f"warning: the data cannot tell the readings {rectified} of extL_T_imu, extR_T_imu apart; visla-edu "
                f"uses {chosen!r}. Check the course's documentation of the extrinsics")
    if track.chosen not in (None, chosen) or (vo_verdict[chosen] == DISAGREES and others_agree):
        motion = track.chosen if track.chosen not in (None, chosen) else others_agree[0]
        return (f"warning: the extrinsics match neither reading consistently: the rig geometry reads them as "
                f"{chosen!r}, the motion the IMU and the camera see as {motion!r}. Are extL_T_imu and extR_T_imu from this drive's "
                "rig and written the same way? Expect a poor estimate")
    if all(v == DISAGREES for v in vo_verdict.values()) and track.chosen != chosen:
        return ("warning: the extrinsics match none of the four readings: the visual odometry contradicts every one "
                "and the track reprojection does not confirm the chosen one. Are extL_T_imu, extR_T_imu from this "
                "drive's rig (or the angular velocity in deg/s)? Expect a poor estimate")
    return ""


def _motion_words(chosen, track, vo_verdict):
    """What the motion evidence says of the chosen reading, for the reason line."""
    if track.chosen == chosen:
        tracks = "track reprojection confirms it (every other reading worse with 95% confidence)"
    elif track.chosen is None:
        tracks = f"track reprojection: {track.verdict}"
    else:
        tracks = f"track reprojection prefers {track.chosen!r}"
    return f"{tracks}; visual odometry: {vo_verdict[chosen]}"


def choose_reading(dataset):
    """The reading of a 2025+ ``dataset``'s ``extrinsic_readings`` to use, and its :class:`ReadingEvidence`.

    Returns
    -------
    reading : visla_edu.camera.RigReading
    evidence : ReadingEvidence
    """
    readings = dataset.extrinsic_readings
    loader = next((r.name for r in readings if np.array_equal(r.imu_T_left, dataset.imu_T_cam)),
                  next((r.name for r in readings if r.rectified), readings[0].name))
    scorer = TrackScorer(dataset, {r.name: r.imu_T_left for r in readings})
    track = scorer.choose_correction()
    slope_lag = scorer.best_lag(track.best) if track.best is not None else 0
    check = check_extrinsics(dataset, slope_lag, {r.name: r.imu_T_left for r in readings})
    chosen, reason = _decide(readings, loader, track)
    reason = f"{reason}; {_motion_words(chosen, track, check.verdict)}"
    warning = _motion_warning(chosen, [r.name for r in readings if r.rectified], track, check.verdict)
    rotation = {k: _finite_or_none(v) for k, v in check.rotation_slope.items()}
    evidence = ReadingEvidence(
        names=[r.name for r in readings],
        geometry={r.name: {"offset": [float(x) for x in r.offset], "rotation_deg": float(np.degrees(r.rotation)),
                           "problem": r.problem} for r in readings},
        loader=loader, track=track, track_scores=scorer.evidence(track, None).scores, slope_lag=int(slope_lag),
        rotation_slope=rotation, translation_slope={k: _finite_or_none(v) for k, v in check.translation_slope.items()},
        vo_verdict=dict(check.verdict), chosen=chosen, reason=reason, warning=warning)
    return next(r for r in readings if r.name == chosen), evidence
