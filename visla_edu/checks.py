"""Checks for the notebook exercises: compare a student's function with the library.

Every ``check_<name>(student_fn)`` calls the student's function on random and edge-case
inputs (near the identity, near pi, far points, empty frames...), compares with the library
version and

* prints one ``✓ ...`` line when everything agrees;
* raises ``AssertionError`` otherwise (nbgrader counts the cell as failed), with a message
  that names the likely mistake. Mistakes are recognised by computing deliberately wrong
  variants from the library (twist order ``[w; v]``, a transposed rotation, a missing minus
  sign, ...) and seeing whether the student's output equals one of them;
* raises ``NotImplementedError`` (with a pointer to the cell to fill in) while the exercise
  is still the stub of the student notebook.

Conventions (see DESIGN.md): twist ``u = [v; w]``, ``twist_hat(u) = [[hat(w), v], [0, 0]]``,
pose ``world_T_imu``, motion ``T_{t+1} = T_t exp(tau u^)``, right perturbation
``T = mu exp(delta^)``.

The inputs are drawn from a fixed seed, so a check gives the same verdict every time.
"""

import numpy as np
from scipy import stats

from visla_edu import camera as cam
from visla_edu import lie, metrics, motion

__all__ = [
    "student_or_reference",
    "reference_numerical_jacobian",
    # 00 know your data
    "check_observations_at",
    "check_track_spans",
    # 01 SE(3) kinematics
    "check_hat",
    "check_so3_exp",
    "check_se3_exp",
    "check_dead_reckon",
    # 02 stereo camera
    "check_stereo_matrix",
    "check_project",
    "check_triangulate",
    # 03 Jacobians
    "check_projection_jacobian",
    "check_odot",
    "check_numerical_jacobian",
    "check_pose_jacobian",
    # 04 landmark mapping
    "check_landmark_jacobian",
    "check_init_landmark",
    "check_landmark_update",
    # 05 pose uncertainty
    "check_curly_hat",
    "check_pose_transition",
    "check_pose_update",
    # 06 joint SLAM
    "check_slam_jacobian",
    "check_dense_covariance_bytes",
    "check_marginalize",
    # 07 tuning and consistency
    "check_motion_noise",
    "check_nees",
    "check_average_nees_bounds",
]

_SEED = 276

# ----------------------------------------------------------------------------- machinery


def _ok(message):
    print(f"\u2713 {message}")


def _fmt(x):
    """Short text for an input in a failure message."""
    if callable(x):
        return getattr(x, "__name__", "a function")
    arr = np.asarray(x)
    if arr.dtype == object:
        return repr(x)
    if arr.size <= 8:
        return np.array2string(arr, precision=6, separator=", ", suppress_small=False).replace("\n", "")
    return f"an array of shape {arr.shape}"


def _call(fn, name, *args, **kwargs):
    """Call the student's function, turning its exceptions into readable failures."""
    try:
        return fn(*args, **kwargs)
    except NotImplementedError:
        raise NotImplementedError(
            f"{name} is not implemented yet: replace the `raise NotImplementedError` line in the "
            "exercise cell above with your code, run that cell, then run this check again") from None
    except Exception as err:  # noqa: BLE001 - any crash is a failed exercise with a message
        shown = ", ".join(_fmt(a) for a in args)
        raise AssertionError(
            f"{name}({shown}) raised {type(err).__name__}: {err}") from err


def _array(out, name, shape, what="result"):
    """The student's output as a float array of the expected shape, or a failure with a hint."""
    try:
        arr = np.asarray(out, dtype=float)
    except (TypeError, ValueError) as err:
        raise AssertionError(f"{name}: the {what} is not a numeric array ({type(out).__name__}): {err}") from None
    if arr.shape != tuple(shape):
        hint = ""
        if arr.shape == tuple(shape)[::-1] and len(shape) >= 2:
            hint = " (transposed: visla-edu is time/row-major, one row per point or frame)"
        elif arr.size == int(np.prod(shape)):
            hint = f" (same number of entries: reshape to {tuple(shape)})"
        raise AssertionError(f"{name}: wrong shape of the {what}: got {arr.shape}, expected {tuple(shape)}{hint}")
    return arr


def _close(a, b, rtol, atol):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=rtol, atol=atol, equal_nan=True))


def _compare(name, got, expected, where, variants=(), rtol=1e-7, atol=1e-9, nan_hint="", extra=None):
    """Fail with the most specific message if ``got`` differs from ``expected``.

    Parameters
    ----------
    variants : sequence of (hint, callable)
        Each callable returns the output of one deliberate mistake on the same input; the
        first that matches ``got`` names the mistake.
    extra : callable, optional
        ``extra(got)`` returns a hint (or "") for mistakes found by a property of the
        output (e.g. "not a rotation").
    """
    if _close(got, expected, rtol, atol):
        return
    expected = np.asarray(expected, dtype=float)
    if not np.all(np.isfinite(got)) and np.all(np.isfinite(expected)):
        raise AssertionError(f"{name} returned NaN or inf {where}. {nan_hint}".rstrip())
    for hint, variant in variants:
        try:
            wrong = variant()
        except Exception:  # noqa: BLE001 - a variant that cannot be computed just does not match
            continue
        if _close(got, wrong, max(rtol, 1e-6), max(atol, 1e-8)):
            raise AssertionError(f"{name} is wrong {where}: {hint}")
    if extra is not None:
        hint = extra(got)
        if hint:
            raise AssertionError(f"{name} is wrong {where}: {hint}")
    raise AssertionError(
        f"{name} is wrong {where}.\nexpected:\n{np.array2string(expected, precision=6)}\n"
        f"got:\n{np.array2string(np.asarray(got), precision=6)}")


def _close_nested(got, expected, rtol=1e-5, atol=1e-7):
    """``_close`` that also compares tuples and lists (e.g. ``(mean, covariance)``) entry by entry."""
    if isinstance(expected, (tuple, list)):
        return (isinstance(got, (tuple, list)) and len(got) == len(expected)
                and all(_close_nested(g, e, rtol, atol) for g, e in zip(got, expected)))
    return _close(got, expected, rtol, atol)


def student_or_reference(student_fn, reference_fn, *probe_args, name=None):
    """The student's function if it runs on ``probe_args`` and agrees with the reference.

    Later cells of a notebook use this so that an unfinished exercise never blocks them.

    Returns
    -------
    callable
    """
    name = name or getattr(student_fn, "__name__", "your function")
    try:
        ok = _close_nested(student_fn(*probe_args), reference_fn(*probe_args))
    except Exception:  # noqa: BLE001 - stubs raise NotImplementedError, broken code anything
        ok = False
    if ok:
        print(f"using your {name}")
        return student_fn
    print(f"using the library's {name} (yours is not finished or disagrees)")
    return reference_fn


def _rng():
    return np.random.default_rng(_SEED)


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _rotation_vectors(rng):
    """Rotation vectors over every regime: zero, tiny, at the series switch, generic, near pi."""
    angles = [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05, 0.1, 0.5, 1.0, 2.0, 3.0, np.pi - 1e-6, np.pi]
    return [a * _unit(rng) for a in angles] + [rng.normal(size=3) for _ in range(4)]


def _twists(rng):
    out = []
    for w in _rotation_vectors(rng):
        out.append(np.concatenate([rng.normal(scale=3.0, size=3), w]))
    out.append(np.zeros(6))
    out.append(np.array([2.0, -1.0, 0.5, 0.0, 0.0, 0.0]))
    return out


def _random_pose(rng, scale=10.0):
    u = np.concatenate([rng.normal(scale=scale, size=3), rng.normal(size=3)])
    return lie.se3_exp(u)


def _rig():
    """A KITTI-like stereo rig (the simulator's): K, b, imu_T_cam."""
    from visla_edu.simulate import default_rig

    return default_rig()


def _camera():
    """The :class:`~visla_edu.camera.StereoCamera` of :func:`_rig`."""
    return cam.StereoCamera(*_rig())


def _points_in_view(rng, world_T_imu, imu_T_cam, n, depth=(2.0, 60.0)):
    """World points the left camera sees at depths in ``depth`` (m)."""
    d = rng.uniform(*depth, size=n)
    x = rng.uniform(-0.8, 0.8, size=n) * d
    y = rng.uniform(-0.3, 0.3, size=n) * d
    p_cam = np.stack([x, y, d], axis=1)
    world_T_cam = world_T_imu @ imu_T_cam
    return p_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


_NEAR_ZERO_HINT = (
    "For tiny angles a closed form like sin(t)/t or (1 - cos t)/t^2 divides 0 by 0 (and loses its "
    "digits well before): below a small angle (visla-edu switches at 0.1 rad) use the Taylor series "
    "(sin(t)/t ~ 1 - t^2/6, (1 - cos t)/t^2 ~ 1/2 - t^2/24, (t - sin t)/t^3 ~ 1/6 - t^2/120).")


def _not_rotation(R):
    R = np.asarray(R)
    if not np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-9):
        return "the result is not a rotation (R R^T != I): is a term of Rodrigues' formula missing?"
    if np.linalg.det(R) < 0:
        return "det(R) = -1: a reflection, not a rotation"
    return ""


def _not_se3(T):
    T = np.asarray(T)
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        return "the bottom row of a pose must be [0, 0, 0, 1]: the result is not in SE(3)"
    return _not_rotation(T[:3, :3]).replace("R R^T", "the rotation block R: R R^T")


# ----------------------------------------------------------------------------- 00 data


def _random_dense(rng, M=40, T=25):
    """A small dense course array (4, M, T): contiguous tracks, -1 elsewhere, some unseen."""
    features = np.full((4, M, T), -1.0)
    for i in range(M):
        if i % 7 == 3:
            continue  # never observed
        start = int(rng.integers(0, T))
        stop = int(min(T, start + rng.integers(1, 10)))
        n = stop - start
        uL = rng.uniform(10, 1300, n)
        v = rng.uniform(10, 480, n)
        features[:, i, start:stop] = np.stack([uL, v, uL - rng.uniform(1, 60, n), v])
    features[:, :, 5] = -1.0  # one frame without any observation
    return features


def _observations_reference(features, t):
    ids = np.nonzero(features[0, :, t] != -1)[0]
    return ids, features[:, ids, t].T


def check_observations_at(observations_at):
    """Exercise 00: ``observations_at(features, t) -> (ids (k,), z (k, 4))`` from dense features."""
    name = "observations_at"
    rng = _rng()
    features = _random_dense(rng)
    for t in range(features.shape[2]):
        out = _call(observations_at, name, features, t)
        if not isinstance(out, tuple) or len(out) != 2:
            raise AssertionError(f"{name} must return a tuple (ids, z), got {type(out).__name__}")
        ids_ref, z_ref = _observations_reference(features, t)
        if np.ndim(out[0]) == 1 and len(out[0]) == features.shape[1] != len(ids_ref):
            raise AssertionError(f"{name} at frame {t}: returned all {len(out[0])} landmarks; keep only "
                                 "the observed ones (features[0, i, t] != -1)")
        ids = _array(out[0], name, ids_ref.shape, "ids")
        if not np.array_equal(ids, ids_ref):
            raise AssertionError(f"{name} at frame {t}: ids {ids.astype(int).tolist()}, expected "
                                 f"{ids_ref.tolist()} (landmark indices along axis 1, increasing)")
        z = _array(out[1], name, z_ref.shape, "pixels z")
        _compare(name, z, z_ref, f"at frame {t}", [
            ("the columns are in the wrong order: z rows are [uL, vL, uR, vR] = features[:, i, t]",
             lambda: z_ref[:, [0, 2, 1, 3]]),
        ])
    _ok(f"{name}: ids and pixels agree with the dataset on {features.shape[2]} frames, including an empty one")


def _spans_reference(features):
    seen = features[0] != -1  # (M, T)
    spans = np.full((features.shape[1], 2), -1, dtype=int)
    any_seen = seen.any(axis=1)
    spans[any_seen, 0] = np.argmax(seen[any_seen], axis=1)
    spans[any_seen, 1] = features.shape[2] - 1 - np.argmax(seen[any_seen, ::-1], axis=1)
    return spans


def check_track_spans(track_spans):
    """Exercise 00: ``track_spans(features) -> (M, 2)`` first and last frame, -1 if never seen."""
    name = "track_spans"
    rng = _rng()
    features = _random_dense(rng)
    ref = _spans_reference(features)
    got = _array(_call(track_spans, name, features), name, ref.shape)
    seen = ref[:, 0] >= 0
    never = ~seen
    wrong_never = seen.sum() and np.array_equal(got[seen], ref[seen]) and not np.array_equal(got[never], ref[never])
    if wrong_never:
        raise AssertionError(f"{name}: landmarks that are never observed must get [-1, -1] (e.g. landmark "
                             f"{int(np.nonzero(never)[0][0])}); np.argmax of an all-False row returns 0")
    last_plus_one = ref.copy()
    last_plus_one[seen, 1] += 1
    _compare(name, got, ref, "on a random dense array", [
        ("the last frame is off by one: return the index of the last observed frame (inclusive), "
         "not one past it", lambda: last_plus_one),
        ("the two columns are swapped: [first, last]", lambda: ref[:, ::-1]),
    ], atol=0)
    _ok(f"{name}: first/last frames agree for {int(seen.sum())} tracks and {int(never.sum())} unseen landmarks")


# ----------------------------------------------------------------------------- 01 kinematics


def check_hat(hat):
    """Exercise 01: ``hat(w) -> (3, 3)`` with ``hat(w) @ x == cross(w, x)``."""
    name = "hat"
    rng = _rng()
    for w in [np.array([1.0, 2.0, 3.0]), np.zeros(3)] + [rng.normal(size=3) for _ in range(5)]:
        got = _array(_call(hat, name, w), name, (3, 3))
        ref = lie.hat(w)
        _compare(name, got, ref, f"for w = {_fmt(w)}", [
            ("the signs are flipped (you built hat(w)^T = -hat(w)); hat(w) @ x must equal np.cross(w, x)",
             lambda: ref.T),
            ("the entries are the right numbers in the wrong places: row 0 is [0, -w3, w2], "
             "row 1 [w3, 0, -w1], row 2 [-w2, w1, 0]", lambda: lie.hat(w[[2, 0, 1]])),
        ], extra=lambda g: "" if np.allclose(g, -g.T) else "hat(w) must be skew-symmetric (hat(w)^T = -hat(w))")
    _ok(f"{name}: skew-symmetric and hat(w) @ x == cross(w, x)")


def _rodrigues_unnormalised(w):
    """A mistake: Rodrigues with the unit axis replaced by the rotation vector itself."""
    t = np.linalg.norm(w)
    W = lie.hat(w)
    return np.eye(3) + np.sin(t) * W + (1 - np.cos(t)) * W @ W


def _rodrigues_minus(w):
    """A mistake: the second-order term subtracted."""
    t = np.linalg.norm(w)
    W = lie.hat(w) / t
    return np.eye(3) + np.sin(t) * W - (1 - np.cos(t)) * W @ W


def check_so3_exp(so3_exp):
    """Exercise 01: Rodrigues' formula ``so3_exp(w) -> (3, 3)``, accurate near 0 and near pi."""
    name = "so3_exp"
    rng = _rng()
    for w in _rotation_vectors(rng):
        got = _array(_call(so3_exp, name, w), name, (3, 3))
        ref = lie.so3_exp(w)
        _compare(name, got, ref, f"for w = {_fmt(w)} (angle {np.linalg.norm(w):.3g} rad)", [
            ("you returned R^T (the rotation by -w): check the sign of the hat(w) term", lambda: ref.T),
            ("the axis is not normalised: Rodrigues uses hat(w / theta), i.e. "
             "I + sin(t)/t hat(w) + (1 - cos t)/t^2 hat(w)^2", lambda: _rodrigues_unnormalised(w)),
            ("the hat(w)^2 term has the wrong sign: + (1 - cos t)/t^2 hat(w)^2",
             lambda: _rodrigues_minus(w)),
        ], atol=1e-9, nan_hint=_NEAR_ZERO_HINT, extra=_not_rotation)
    _ok(f"{name}: Rodrigues agrees with the library from 0 to pi (incl. 1e-12 rad)")


def _swap_twist(u):
    u = np.asarray(u, dtype=float)
    return np.concatenate([u[3:], u[:3]])


def _se3_no_jacobian(u):
    T = lie.se3_exp(u)
    T[:3, 3] = u[:3]
    return T


def check_se3_exp(se3_exp):
    """Exercise 01: ``se3_exp(u) -> (4, 4)`` for a twist ``u = [v; w]``, closed form."""
    name = "se3_exp"
    rng = _rng()
    for u in _twists(rng):
        got = _array(_call(se3_exp, name, u), name, (4, 4))
        ref = lie.se3_exp(u)
        where = f"for u = {_fmt(u)} (angle {np.linalg.norm(u[3:]):.3g} rad)"
        _compare(name, got, ref, where, [
            ("wrong twist order: visla-edu's twist is u = [v; w] (linear velocity first, "
             "angular second); you used [w; v]", lambda: lie.se3_exp(_swap_twist(u))),
            ("you returned the inverse pose exp(-u^): check the signs", lambda: lie.se3_exp(-u)),
            ("the translation is v, but it must be V v with V = I + (1 - cos t)/t^2 hat(w) + "
             "(t - sin t)/t^3 hat(w)^2 (the left Jacobian of SO(3))", lambda: _se3_no_jacobian(u)),
            ("the rotation block is transposed (R^T instead of R)",
             lambda: np.block([[ref[:3, :3].T, ref[:3, 3:]], [ref[3:]]])),
        ], atol=1e-9, nan_hint=_NEAR_ZERO_HINT, extra=_not_se3)
    _ok(f"{name}: agrees with the library for twists [v; w] from rest to angles near pi")


def _dead_reckon_left(time_stamps, twists):
    poses = [np.eye(4)]
    for t, tau in enumerate(np.diff(time_stamps)):
        poses.append(lie.se3_exp(tau * twists[t]) @ poses[-1])
    return np.array(poses)


def _dead_reckon_no_tau(time_stamps, twists):
    poses = [np.eye(4)]
    for t in range(len(time_stamps) - 1):
        poses.append(poses[-1] @ lie.se3_exp(twists[t]))
    return np.array(poses)


def check_dead_reckon(dead_reckon):
    """Exercise 01: ``dead_reckon(time_stamps (T,), twists (T, 6)) -> (T, 4, 4)`` from the identity."""
    name = "dead_reckon"
    rng = _rng()
    T = 30
    time_stamps = 100.0 + np.cumsum(rng.uniform(0.08, 0.12, T))
    twists = np.concatenate([rng.normal([8, 0, 0], [1, 0.3, 0.1], (T, 3)),
                             rng.normal([0, 0, 0.1], [0.05, 0.05, 0.3], (T, 3))], axis=1)
    got = _array(_call(dead_reckon, name, time_stamps, twists), name, (T, 4, 4))
    ref = motion.dead_reckon(time_stamps, twists)
    lag = motion.dead_reckon(time_stamps, twists, lag=1)
    _compare(name, got, ref, "on a random 30-step drive", [
        ("you multiplied on the left, exp(tau u^) T_t: the IMU measures body-frame velocities, so "
         "T_{t+1} = T_t exp(tau_t u_t^) (multiply on the right)", lambda: _dead_reckon_left(time_stamps, twists)),
        ("wrong twist order: u = [v; w] (linear first)",
         lambda: motion.dead_reckon(time_stamps, twists[:, [3, 4, 5, 0, 1, 2]])),
        ("the step from t to t+1 must use u_t (the sample at the start of the interval), not u_{t+1}",
         lambda: lag),
        ("the twist must be scaled by the time step tau_t = t_{t+1} - t_t: exp(tau_t u_t^)",
         lambda: _dead_reckon_no_tau(time_stamps, twists)),
        ("the poses are inverted (imu_T_world): visla-edu stores world_T_imu",
         lambda: lie.se3_inv(ref)),
    ], atol=1e-8)
    _ok(f"{name}: the {T}-pose trajectory agrees with motion.dead_reckon")


# ----------------------------------------------------------------------------- 02 camera


def _calibrations(rng):
    out = [_rig()[:2], (np.array([[552.55, 0, 682.05], [0, 552.55, 238.77], [0, 0, 1]]), 0.5962)]
    for _ in range(2):
        f = rng.uniform(300, 900)
        K = np.array([[f, 0, rng.uniform(300, 700)], [0, f * rng.uniform(0.9, 1.1), rng.uniform(150, 300)],
                      [0, 0, 1]])
        out.append((K, rng.uniform(0.1, 1.0)))
    return out


def check_stereo_matrix(stereo_matrix):
    """Exercise 02: ``stereo_matrix(K, b) -> Ks (4, 4)``."""
    name = "stereo_matrix"
    for K, b in _calibrations(_rng()):
        got = _array(_call(stereo_matrix, name, K, b), name, (4, 4))
        ref = cam.stereo_matrix(K, b)
        plus = ref.copy()
        plus[2, 3] *= -1
        no_f = ref.copy()
        no_f[2, 3] = -b
        _compare(name, got, ref, f"for fsu = {K[0, 0]:.2f}, b = {b:.3f}", [
            ("the sign of the baseline term: the right camera sits at +b along x, so a point at depth z "
             "appears at uR = uL - fsu b / z; the entry is -fsu b", lambda: plus),
            ("the baseline term must be in pixels: -fsu * b, not -b", lambda: no_f),
            ("Ks is transposed", lambda: ref.T),
        ])
    _ok(f"{name}: Ks agrees with the library for 4 calibrations")


def check_project(project):
    """Exercise 02: ``project(Ks, cam_T_imu, world_T_imu, p_world (M, 3)) -> z (M, 4)``."""
    name = "project"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(4):
        world_T_imu = np.eye(4) if trial == 0 else _random_pose(rng)
        p_world = _points_in_view(rng, world_T_imu, imu_T_cam, 12, depth=(2.0, 300.0 if trial == 3 else 60.0))
        got = _array(_call(project, name, rig.Ks, rig.cam_T_imu, world_T_imu, p_world), name, (12, 4))
        ref = rig.predict(world_T_imu, p_world)
        _compare(name, got, ref, "for a random pose and 12 points in view", [
            ("you used world_T_imu where its inverse is needed: the point in the IMU frame is "
             "inv(world_T_imu) @ m", lambda: (cam.projection(
                 np.c_[p_world, np.ones(len(p_world))] @ (rig.cam_T_imu @ world_T_imu).T) @ rig.Ks.T)),
            ("you used imu_T_cam where cam_T_imu (= inv(imu_T_cam), written o_T_i) is needed",
             lambda: (cam.projection(np.c_[p_world, np.ones(len(p_world))]
                                     @ (imu_T_cam @ lie.se3_inv(world_T_imu)).T) @ rig.Ks.T)),
            ("the perspective division must divide by the depth q3 (the third coordinate), not q4",
             lambda: (np.c_[p_world, np.ones(len(p_world))] @ (rig.cam_T_imu @ lie.se3_inv(world_T_imu)).T)
             @ rig.Ks.T),
        ], rtol=1e-7, atol=1e-6)
    _ok(f"{name}: pixels agree with StereoCamera.predict at 4 poses, points from 2 m to 300 m")


def check_triangulate(triangulate):
    """Exercise 02: ``triangulate(z (M, 4), K, b) -> (M, 3)`` points in the left camera (disparity form)."""
    name = "triangulate"
    rng = _rng()
    for K, b in _calibrations(rng):
        d = rng.uniform(1.5, 120.0, 10)
        p = np.stack([rng.uniform(-0.8, 0.8, 10) * d, rng.uniform(-0.3, 0.3, 10) * d, d], axis=1)
        z = cam.projection(np.c_[p, np.ones(10)]) @ cam.stereo_matrix(K, b).T
        got = _array(_call(triangulate, name, z, K, b), name, (10, 3))
        _compare(name, got, p, f"for fsu = {K[0, 0]:.1f} px, b = {b:.3f} m", [
            ("disparity sign: the disparity is uL - uR (positive for points in front), depth = fsu b / (uL - uR)",
             lambda: -p),
            ("depth uses the wrong focal length or units: depth = fsu * b / disparity (fsu in px, b in m)",
             lambda: cam.triangulate_disparity(z, K, b) / K[0, 0]),
            ("x and y are not scaled by the depth: x = (uL - cu) * depth / fsu, y = (vL - cv) * depth / fsv",
             lambda: np.c_[(z[:, 0] - K[0, 2]) / K[0, 0], (z[:, 1] - K[1, 2]) / K[1, 1], p[:, 2]]),
            ("x and y used the same focal length: y = (vL - cv) * depth / fsv",
             lambda: np.c_[p[:, 0], (z[:, 1] - K[1, 2]) * p[:, 2] / K[0, 0], p[:, 2]]),
        ], rtol=1e-6, atol=1e-6)
    _ok(f"{name}: recovers points from 1.5 m to 120 m for 4 calibrations")


# ----------------------------------------------------------------------------- 03 Jacobians


def check_projection_jacobian(projection_jacobian):
    """Exercise 03: ``projection_jacobian(q (4,)) -> dpi/dq (4, 4)``."""
    name = "projection_jacobian"
    rng = _rng()
    for _ in range(6):
        q = np.r_[rng.normal(size=2) * 5, rng.uniform(1, 50), 1.0]
        got = _array(_call(projection_jacobian, name, q), name, (4, 4))
        ref = cam.projection_jacobian(q)
        _compare(name, got, ref, f"at q = {_fmt(q)}", [
            ("the Jacobian is transposed: row i holds the derivatives of pi_i", lambda: ref.T),
            ("the 1/q3 factor in front of the matrix is missing", lambda: ref * q[2]),
            ("the third column has the wrong sign: d(q1/q3)/dq3 = -q1/q3^2",
             lambda: ref * np.array([1.0, 1.0, -1.0, 1.0])),
            ("the last row is wrong: pi_4 = q4/q3 depends on q3 and q4 ([0, 0, -q4/q3^2, 1/q3])",
             lambda: np.r_[ref[:3], [np.zeros(4)]]),
        ], atol=1e-12)
    _ok(f"{name}: agrees with the library (and so with finite differences)")


def check_odot(odot):
    """Exercise 03: ``odot(s (4,)) -> (4, 6)`` with ``twist_hat(u) @ s == odot(s) @ u``."""
    name = "odot"
    rng = _rng()
    for _ in range(5):
        s = np.r_[rng.normal(scale=10, size=3), 1.0]
        got = _array(_call(odot, name, s), name, (4, 6))
        ref = lie.odot(s)
        _compare(name, got, ref, f"for s = {_fmt(s)}", [
            ("the sign of the hat block: s^odot = [[I, -hat(s)], [0, 0]] because hat(w) s = -hat(s) w",
             lambda: np.c_[ref[:, :3], -ref[:, 3:]]),
            ("the blocks are swapped: with u = [v; w] (linear first) the identity block multiplies v "
             "and comes first", lambda: np.c_[ref[:, 3:], ref[:, :3]]),
        ])
    _ok(f"{name}: twist_hat(u) @ s == odot(s) @ u for twists [v; w]")


def reference_numerical_jacobian(f, x, eps=1e-6):
    """Central-difference Jacobian of ``f: R^n -> R^m`` at ``x``, shape (m, n)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = eps
        cols.append((np.asarray(f(x + dx), dtype=float) - np.asarray(f(x - dx), dtype=float)) / (2 * eps))
    return np.stack(cols, axis=-1)


def _forward_jacobian(f, x, eps=1e-6):
    f0 = np.asarray(f(x), dtype=float)
    return np.stack([(np.asarray(f(x + eps * e), dtype=float) - f0) / eps for e in np.eye(x.size)], axis=-1)


def check_numerical_jacobian(numerical_jacobian):
    """Exercise 03: ``numerical_jacobian(f, x, eps=1e-6) -> (m, n)`` by central differences."""
    name = "numerical_jacobian"
    rng = _rng()
    A = rng.normal(size=(4, 3))

    def linear(x):
        return A @ x

    def curved(x):
        return np.array([np.exp(3 * x[0]) * x[1], np.sin(2 * x[1]) + x[0] ** 3])

    def analytic_curved(x):
        return np.array([[3 * np.exp(3 * x[0]) * x[1], np.exp(3 * x[0])], [3 * x[0] ** 2, 2 * np.cos(2 * x[1])]])

    cases = [(linear, rng.normal(size=3), A), (curved, np.array([0.7, 1.3]), analytic_curved(np.array([0.7, 1.3])))]
    for f, x, exact in cases:
        got = _array(_call(numerical_jacobian, name, f, x), name, exact.shape)
        _compare(name, got, exact, f"for f = {f.__name__} at x = {_fmt(x)}", [
            ("the Jacobian is transposed: it has one row per output and one column per input", lambda: exact.T),
            ("central differences divide by 2 eps: (f(x + eps e_i) - f(x - eps e_i)) / (2 eps)",
             lambda: 2 * exact),
            ("central differences divide by 2 eps, not eps / 2", lambda: 0.5 * exact),
            ("forward differences (f(x + eps) - f(x)) / eps are only accurate to O(eps); use central "
             "differences (f(x + eps) - f(x - eps)) / (2 eps), accurate to O(eps^2)",
             lambda: _forward_jacobian(f, x)),
        ], rtol=1e-7, atol=1e-7)
    _ok(f"{name}: central differences match the exact Jacobians")


def _pose_jacobian_left(rig, mu, m):
    """A mistake: the Jacobian for the left perturbation T = exp(delta^) mu."""
    q = rig.points_in_camera(mu, m[None])[0]
    return -rig.Ks @ cam.projection_jacobian(q) @ rig.cam_T_imu @ lie.se3_inv(mu) @ lie.odot(np.r_[m, 1.0])


def check_pose_jacobian(pose_jacobian):
    """Exercise 03: ``pose_jacobian(Ks, cam_T_imu, mu, m (3,)) -> (4, 6)`` for ``T = mu exp(delta^)``."""
    name = "pose_jacobian"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(4):
        mu = np.eye(4) if trial == 0 else _random_pose(rng)
        m = _points_in_view(rng, mu, imu_T_cam, 1)[0]
        got = _array(_call(pose_jacobian, name, rig.Ks, rig.cam_T_imu, mu, m), name, (4, 6))
        ref = rig.jacobian_pose(mu, m[None])[0]
        _compare(name, got, ref, f"for a random pose and m = {_fmt(m)}", [
            ("the minus sign is missing: z = Ks pi(o_T_i exp(-delta^) mu^-1 m), so the Jacobian is "
             "-Ks dpi/dq o_T_i (mu^-1 m)^odot", lambda: -ref),
            ("wrong twist order: the columns must be [d/dv, d/dw] for u = [v; w]",
             lambda: np.c_[ref[:, 3:], ref[:, :3]]),
            ("this is the Jacobian for the left perturbation exp(delta^) mu; visla-edu perturbs on the right, "
             "T = mu exp(delta^), so odot acts on the IMU-frame point mu^-1 m",
             lambda: _pose_jacobian_left(rig, mu, m)),
        ], rtol=1e-6, atol=1e-8)
    _ok(f"{name}: agrees with the library (and so with finite differences of mu exp(delta^))")


# ----------------------------------------------------------------------------- 04 mapping


def check_landmark_jacobian(landmark_jacobian):
    """Exercise 04: ``landmark_jacobian(Ks, cam_T_imu, world_T_imu, m (3,)) -> (4, 3)``."""
    name = "landmark_jacobian"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(4):
        T = np.eye(4) if trial == 0 else _random_pose(rng)
        m = _points_in_view(rng, T, imu_T_cam, 1)[0]
        out = _call(landmark_jacobian, name, rig.Ks, rig.cam_T_imu, T, m)
        if np.shape(out) == (4, 4):
            raise AssertionError(f"{name}: got a 4x4 matrix; multiply by P^T = [I; 0] (4x3) on the right, "
                                 "the landmark has 3 coordinates (its homogeneous 1 is not a variable)")
        got = _array(out, name, (4, 3))
        ref = rig.jacobian_landmark(T, m[None])[0]
        q = rig.points_in_camera(T, m[None])[0]
        _compare(name, got, ref, f"for m = {_fmt(m)}", [
            ("you used world_T_imu where inv(world_T_imu) is needed",
             lambda: rig.Ks @ cam.projection_jacobian(q) @ rig.cam_T_imu @ T[:, :3]),
            ("Ks is missing: z = Ks pi(q), so the Jacobian starts with Ks dpi/dq",
             lambda: cam.projection_jacobian(q) @ rig.cam_T_imu @ lie.se3_inv(T)[:, :3]),
            ("the sign is flipped: the landmark enters with a plus sign", lambda: -ref),
        ], rtol=1e-6, atol=1e-9)
    _ok(f"{name}: agrees with the library at 4 poses")


def check_init_landmark(init_landmark):
    """Exercise 04: ``init_landmark(z (4,), K, b, imu_T_cam, world_T_imu) -> (3,)`` world point."""
    name = "init_landmark"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(4):
        T = np.eye(4) if trial == 0 else _random_pose(rng)
        m = _points_in_view(rng, T, imu_T_cam, 1)[0]
        z = rig.predict(T, m[None])[0]
        got = _array(_call(init_landmark, name, z, K, b, imu_T_cam, T), name, (3,))
        p_cam = cam.triangulate_disparity(z, K, b)
        _compare(name, got, m, f"for z = {_fmt(z)}", [
            ("the point is still in the camera frame: map it with world_T_imu @ imu_T_cam",
             lambda: p_cam),
            ("the point is in the IMU frame: also apply world_T_imu",
             lambda: imu_T_cam[:3, :3] @ p_cam + imu_T_cam[:3, 3]),
            ("you used cam_T_imu (the inverse of imu_T_cam): world_T_cam = world_T_imu @ imu_T_cam",
             lambda: (T @ lie.se3_inv(imu_T_cam) @ np.r_[p_cam, 1])[:3]),
            ("you used inv(world_T_imu): world_T_cam = world_T_imu @ imu_T_cam",
             lambda: (lie.se3_inv(T) @ imu_T_cam @ np.r_[p_cam, 1])[:3]),
        ], rtol=1e-6, atol=1e-6)
    _ok(f"{name}: triangulated points land on the true landmarks in the world frame")


def check_landmark_update(landmark_update):
    """Exercise 04: ``landmark_update(m, Sigma, z, world_T_imu, Ks, cam_T_imu, noise_var) -> (m, Sigma)``."""
    name = "landmark_update"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(4):
        T = _random_pose(rng)
        m_true = _points_in_view(rng, T, imu_T_cam, 1, depth=(4.0, 40.0))[0]
        z = rig.predict(T, m_true[None])[0] + rng.normal(scale=2.0, size=4)
        m = m_true + rng.normal(scale=1.0, size=3)
        A = rng.normal(size=(3, 3))
        Sigma = A @ A.T + np.eye(3)
        out = _call(landmark_update, name, m, Sigma, z, T, rig.Ks, rig.cam_T_imu, 4.0)
        if not isinstance(out, tuple) or len(out) != 2:
            raise AssertionError(f"{name} must return a tuple (m_new, Sigma_new)")
        m_ref, S_ref = _landmark_update_reference(m, Sigma, z, T, rig, 4.0)
        got_m = _array(out[0], name, (3,), "mean")
        got_S = _array(out[1], name, (3, 3), "covariance")
        flipped = _landmark_update_reference(m, Sigma, 2 * rig.predict(T, m[None])[0] - z, T, rig, 4.0)[0]
        _compare(name, got_m, m_ref, "(mean)", [
            ("the innovation must be z - z_pred (observed minus predicted), not z_pred - z",
             lambda: flipped),
            ("the mean did not move: add K (z - z_pred)", lambda: m),
        ], rtol=1e-6, atol=1e-6)
        H = rig.jacobian_landmark(T, m[None])[0]
        Kg = Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T + 4.0 * np.eye(4))
        _compare(name, got_S, S_ref, "(covariance)", [
            ("Sigma_new = (I - K H) Sigma, with a minus sign", lambda: (np.eye(3) + Kg @ H) @ Sigma),
            ("the covariance did not change: Sigma_new = (I - K H) Sigma", lambda: Sigma),
            ("the observation noise is missing from S = H Sigma H^T + noise_var I",
             lambda: Sigma - Sigma @ H.T @ np.linalg.inv(H @ Sigma @ H.T) @ H @ Sigma),
        ], rtol=1e-6, atol=1e-8)
    _ok(f"{name}: mean and covariance agree with ekf.landmark_update")


def _landmark_update_reference(m, Sigma, z, T, rig, noise_var):
    """The library's single-landmark update (mean (3,), covariance (3, 3))."""
    from visla_edu import ekf

    m_new, S_new = ekf.landmark_update(m[None], Sigma[None], z[None], T, rig, noise_var)
    return m_new[0], S_new[0]


# ----------------------------------------------------------------------------- 05 pose


def check_curly_hat(curly_hat):
    """Exercise 05: ``curly_hat(u) -> (6, 6)`` for ``u = [v; w]``: ``[[hat(w), hat(v)], [0, hat(w)]]``."""
    name = "curly_hat"
    rng = _rng()
    for u in [np.array([1.0, 2, 3, 4, 5, 6])] + [rng.normal(size=6) for _ in range(4)]:
        got = _array(_call(curly_hat, name, u), name, (6, 6))
        ref = lie.curly_hat(u)
        v, w = lie.hat(u[:3]), lie.hat(u[3:])
        Z = np.zeros((3, 3))
        _compare(name, got, ref, f"for u = {_fmt(u)}", [
            ("wrong twist order: u = [v; w], so the diagonal blocks are hat(w) = hat(u[3:]) and the "
             "off-diagonal one hat(v) = hat(u[:3])", lambda: lie.curly_hat(_swap_twist(u))),
            ("hat(v) belongs in the upper-right block ([[hat(w), hat(v)], [0, hat(w)]] for [v; w])",
             lambda: np.block([[w, Z], [v, w]])),
            ("the signs are flipped (you built curly_hat(-u))", lambda: -ref),
            ("curly_hat is transposed", lambda: ref.T),
        ])
    _ok(f"{name}: expm(curly_hat(u)) == adjoint(se3_exp(u)) holds with your matrix")


def check_pose_transition(pose_transition):
    """Exercise 05: ``pose_transition(u, tau) -> F (6, 6) = exp(-tau curly_hat(u))`` in closed form."""
    name = "pose_transition"
    rng = _rng()
    for u in _twists(rng)[::2]:
        tau = float(rng.uniform(0.05, 0.2))
        out = _call(pose_transition, name, u, tau)
        if np.shape(out) == (4, 4):
            raise AssertionError(f"{name}: got a 4x4 matrix; F acts on 6-dim perturbations: use the adjoint "
                                 "of exp(-tau u^), a 6x6 matrix")
        got = _array(out, name, (6, 6))
        ref = motion.pose_transition(u, tau)
        _compare(name, got, ref, f"for u = {_fmt(u)}, tau = {tau:.3f}", [
            ("missing minus sign: F = exp(-tau curly_hat(u)) = Ad(exp(-tau u^)) (the perturbation is "
             "carried backwards through the motion step)", lambda: motion.pose_transition(u, -tau)),
            ("F is transposed", lambda: ref.T),
            ("wrong twist order: u = [v; w]", lambda: motion.pose_transition(_swap_twist(u), tau)),
            ("you used I - tau curly_hat(u), the first-order approximation; use the exact closed form "
             "Ad(exp(-tau u^))", lambda: np.eye(6) - tau * lie.curly_hat(u)),
        ], rtol=1e-7, atol=1e-9, nan_hint=_NEAR_ZERO_HINT)
    _ok(f"{name}: closed form agrees with expm(-tau curly_hat(u)), including at rest")


def _pose_update_reference(mu, Sigma, z, p_world, rig, noise_var, side="right", sign=1.0):
    z_pred, _, J = rig.predict_with_jacobians(mu, p_world)
    H = J.reshape(-1, 6)
    S = H @ Sigma @ H.T + noise_var * np.eye(len(H))
    K = Sigma @ H.T @ np.linalg.inv(S)
    delta = sign * K @ (z - z_pred).ravel()
    mu_new = mu @ lie.se3_exp(delta) if side == "right" else lie.se3_exp(delta) @ mu
    return mu_new, (np.eye(6) - K @ H) @ Sigma


def check_pose_update(pose_update):
    """Exercise 05: ``pose_update(mu, Sigma, z (k, 4), p_world (k, 3), Ks, cam_T_imu, noise_var) -> (mu, Sigma)``."""
    name = "pose_update"
    rng, (K, b, imu_T_cam), rig = _rng(), _rig(), _camera()
    for trial in range(3):
        T_true = _random_pose(rng)
        p_world = _points_in_view(rng, T_true, imu_T_cam, 8, depth=(4.0, 40.0))
        z = rig.predict(T_true, p_world) + rng.normal(scale=1.0, size=(8, 4))
        A = rng.normal(size=(6, 6)) * 0.05
        Sigma = A @ A.T + 1e-3 * np.eye(6)
        mu = T_true @ lie.se3_exp(rng.multivariate_normal(np.zeros(6), Sigma))
        out = _call(pose_update, name, mu, Sigma, z, p_world, rig.Ks, rig.cam_T_imu, 4.0)
        if not isinstance(out, tuple) or len(out) != 2:
            raise AssertionError(f"{name} must return a tuple (mu_new, Sigma_new)")
        mu_ref, S_ref = _pose_update_reference(mu, Sigma, z, p_world, rig, 4.0)
        got_mu = _array(out[0], name, (4, 4), "pose")
        got_S = _array(out[1], name, (6, 6), "covariance")
        _compare(name, got_mu, mu_ref, "(pose mean)", [
            ("the correction is applied on the left; with the right perturbation it goes on the right: "
             "mu_new = mu @ se3_exp(K (z - z_pred))",
             lambda: _pose_update_reference(mu, Sigma, z, p_world, rig, 4.0, side="left")[0]),
            ("the correction has the wrong sign: check the minus sign of the pose Jacobian "
             "(-Ks dpi/dq o_T_i (mu^-1 m)^odot) and the innovation z - z_pred",
             lambda: _pose_update_reference(mu, Sigma, z, p_world, rig, 4.0, sign=-1.0)[0]),
            ("the pose did not move", lambda: mu),
        ], rtol=1e-6, atol=1e-7, extra=_not_se3)
        _compare(name, got_S, S_ref, "(covariance)", [
            ("the covariance did not change: Sigma_new = (I - K H) Sigma", lambda: Sigma),
        ], rtol=1e-6, atol=1e-10)
    _ok(f"{name}: pose and covariance agree with ekf.pose_update")


# ----------------------------------------------------------------------------- 06 SLAM


def _slam_jacobian_reference(J_pose, J_landmark, slots, n_landmarks, pose_first=True, offset=6):
    k = len(slots)
    H = np.zeros((4 * k, 6 + 3 * n_landmarks))
    for i, s in enumerate(slots):
        rows = slice(4 * i, 4 * i + 4)
        if pose_first:
            H[rows, :6] = J_pose[i]
            H[rows, offset + 3 * s: offset + 3 * s + 3] = J_landmark[i]
        else:
            H[rows, 3 * n_landmarks:] = J_pose[i]
            H[rows, 3 * s: 3 * s + 3] = J_landmark[i]
    return H


def check_slam_jacobian(slam_jacobian):
    """Exercise 06: ``slam_jacobian(J_pose (k,4,6), J_landmark (k,4,3), slots (k,), n) -> H (4k, 6+3n)``."""
    name = "slam_jacobian"
    rng = _rng()
    for n, slots in [(5, np.array([3, 0])), (9, np.array([8, 2, 5, 6])), (1, np.array([0]))]:
        k = len(slots)
        J_pose = rng.normal(size=(k, 4, 6))
        J_landmark = rng.normal(size=(k, 4, 3))
        got = _array(_call(slam_jacobian, name, J_pose, J_landmark, slots, n), name, (4 * k, 6 + 3 * n))
        ref = _slam_jacobian_reference(J_pose, J_landmark, slots, n)
        _compare(name, got, ref, f"for slots {slots.tolist()} of {n} landmarks", [
            ("the pose columns come first in visla-edu's state [pose (6); landmarks (3n)] "
             "(the seed report orders it [landmarks; pose])",
             lambda: _slam_jacobian_reference(J_pose, J_landmark, slots, n, pose_first=False)),
            ("landmark slot s occupies columns 6 + 3 s ... 6 + 3 s + 2 (after the 6 pose columns)",
             lambda: _slam_jacobian_reference(J_pose, J_landmark, slots, n, offset=0)),
        ], atol=0)
    _ok(f"{name}: H has the pose block first and each landmark in its slot's columns")


def _dense_bytes(num_landmarks, stride=1):
    n = len(range(0, num_landmarks, stride))
    return (6 + 3 * n) ** 2 * 8


def check_dense_covariance_bytes(dense_covariance_bytes):
    """Exercise 06: ``dense_covariance_bytes(num_landmarks, stride=1) -> int`` for float64."""
    name = "dense_covariance_bytes"
    for M, stride in [(5105, 1), (13289, 1), (5105, 10), (13289, 20), (7, 3), (1, 1)]:
        got = _call(dense_covariance_bytes, name, M, stride)
        ref = _dense_bytes(M, stride)
        n = len(range(0, M, stride))
        where = f"for {M} landmarks with stride {stride}"
        _compare(name, got, ref, where, [
            ("the pose adds 6 dimensions: the state has 6 + 3 n entries", lambda: (3 * n) ** 2 * 8),
            ("a float64 has 8 bytes", lambda: (6 + 3 * n) ** 2 * 4),
            ("a covariance is D x D: square the dimension", lambda: (6 + 3 * n) * 8),
            ("every stride-th landmark from landmark 0 gives ceil(M / stride) landmarks, not M // stride",
             lambda: (6 + 3 * (M // stride)) ** 2 * 8),
            ("each landmark has 3 coordinates", lambda: (6 + n) ** 2 * 8),
        ], rtol=0, atol=0.5)
    _ok(f"{name}: 5105 landmarks -> {_dense_bytes(5105) / 1e9:.2f} GB, 13289 -> {_dense_bytes(13289) / 1e9:.1f} GB")


def _random_covariance(rng, D):
    A = rng.normal(size=(D, D))
    return A @ A.T + D * np.eye(D)


def check_marginalize(marginalize):
    """Exercise 06: ``marginalize(Sigma (D, D), keep (indices)) -> Sigma[keep][:, keep]``."""
    name = "marginalize"
    rng = _rng()
    for D, keep in [(12, np.array([0, 1, 2, 3, 4, 5, 9, 10, 11])), (15, np.array([0, 1, 2, 3, 4, 5, 6, 7, 8])),
                    (9, np.arange(9))]:
        Sigma = _random_covariance(rng, D)
        got = _array(_call(marginalize, name, Sigma, keep), name, (len(keep), len(keep)))
        ref = Sigma[np.ix_(keep, keep)]
        drop = np.setdiff1d(np.arange(D), keep)
        if len(drop):
            conditioned = ref - Sigma[np.ix_(keep, drop)] @ np.linalg.solve(Sigma[np.ix_(drop, drop)],
                                                                            Sigma[np.ix_(drop, keep)])
        else:
            conditioned = ref
        _compare(name, got, ref, f"keeping {len(keep)} of {D} dimensions", [
            ("this is the Schur complement, i.e. conditioning on the removed landmarks; marginalising a "
             "Gaussian in covariance form just deletes their rows and columns", lambda: conditioned),
            ("you inverted twice: marginalise in covariance form (no information matrix needed)",
             lambda: np.linalg.inv(np.linalg.inv(Sigma)[np.ix_(keep, keep)])),
        ])
    _ok(f"{name}: deleting rows and columns, the exact marginal")


# ----------------------------------------------------------------------------- 07 consistency


def check_motion_noise(motion_noise):
    """Exercise 07: ``motion_noise(tau, sigma_v, sigma_w) -> W (6, 6)`` for twists ``[v; w]``."""
    name = "motion_noise"
    for tau, sv, sw in [(0.1, 0.5, 0.02), (0.104, 1.0, 0.05), (0.5, 0.2, 0.3)]:
        got = _array(_call(motion_noise, name, tau, sv, sw), name, (6, 6))
        ref = motion.motion_noise(tau, sv, sw)
        _compare(name, got, ref, f"for tau = {tau}, sigma_v = {sv}, sigma_w = {sw}", [
            ("wrong twist order: u = [v; w], so the linear variances come first on the diagonal",
             lambda: motion.motion_noise(tau, sw, sv)),
            ("a velocity error of sigma over tau seconds moves the pose by tau sigma: scale the variances "
             "by tau^2", lambda: np.diag(np.repeat([sv**2, sw**2], 3))),
            ("variances scale with tau^2, not tau", lambda: np.diag(np.repeat([tau * sv**2, tau * sw**2], 3))),
            ("W holds variances: square the standard deviations (tau sigma)^2",
             lambda: np.diag(np.repeat([tau * sv, tau * sw], 3))),
        ], rtol=1e-9, atol=1e-15)
    _ok(f"{name}: W = tau^2 diag(sigma_v^2 I, sigma_w^2 I)")


def check_nees(nees):
    """Exercise 07: ``nees(error (n,), cov (n, n)) -> float`` = ``e^T cov^-1 e``."""
    name = "nees"
    rng = _rng()
    for n in (3, 6, 6):
        cov = _random_covariance(rng, n) * 1e-3
        e = rng.multivariate_normal(np.zeros(n), cov)
        got = _call(nees, name, e, cov)
        ref = float(metrics.nees(e[None], cov[None])[0])
        _compare(name, got, ref, f"for a random {n}-dim error", [
            ("you multiplied by the covariance; NEES uses its inverse: e^T Sigma^-1 e", lambda: e @ cov @ e),
            ("NEES is the squared distance, do not take the square root", lambda: np.sqrt(ref)),
            ("you divided by the dimension: NEES itself is not averaged", lambda: ref / n),
            ("you ignored the covariance (squared norm of e)", lambda: e @ e),
        ], rtol=1e-7)
    _ok(f"{name}: e^T Sigma^-1 e (chi-square with n dof when the filter is consistent)")


def check_average_nees_bounds(average_nees_bounds):
    """Exercise 07: ``average_nees_bounds(dof, n, probability=0.95) -> (lo, hi)`` for a mean of n NEES."""
    name = "average_nees_bounds"
    for dof, n, p in [(6, 1, 0.95), (6, 50, 0.95), (4, 200, 0.99), (3, 10, 0.9)]:
        out = _call(average_nees_bounds, name, dof, n, p)
        got = _array(out, name, (2,), "bounds")
        ref = np.array(metrics.average_nees_bounds(dof, n, p))
        tail = (1 - p) / 2
        _compare(name, got, ref, f"for dof {dof}, {n} values, probability {p}", [
            ("the sum of n values is chi-square with n * dof degrees of freedom; divide its quantiles by n",
             lambda: np.array(stats.chi2.ppf([tail, 1 - tail], dof))),
            ("you forgot to divide the quantiles of the sum by n",
             lambda: np.array(stats.chi2.ppf([tail, 1 - tail], dof * n))),
            ("two-sided: put (1 - p) / 2 in each tail", lambda: np.array(stats.chi2.ppf([1 - p, p], dof * n)) / n),
        ], rtol=1e-6)
    _ok(f"{name}: chi-square bounds of the average NEES")
