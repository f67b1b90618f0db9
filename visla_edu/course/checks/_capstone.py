"""Checks of notebook 12 (the capstone): the three assembly functions and the loops they drive.

Each check tests the student's function on random states through spy parts that record which
of the notebooks' functions it calls (the assembly must go through ``parts``). ``predict`` and
``slam_update`` then drive :func:`visla_edu.course.capstone.run_capstone` on ``sim-tiny`` (hidden:
a ``"tiny"`` drive of another seed), every position within :data:`LOOP_TOLERANCE` of the reference
(for SLAM the library's ``slam_error="right"`` joint filter, reproduced to rounding error).
"""

from dataclasses import fields, replace

import numpy as np

from visla_edu import camera as cam
from visla_edu import ekf, lie, metrics, motion, run
from visla_edu.course import capstone
from visla_edu.course.checks._core import _hidden_seed, as_array, compare, exercise_check, fail, ok, rng, student
from visla_edu.course.checks._inputs import points_in_view, random_covariance, random_pose, stereo_camera
from visla_edu.filters import FilterConfig

__all__ = ["check_capstone_predict", "check_capstone_landmarks", "check_capstone_slam", "capstone_steps",
           "reference_capstone_steps"]

#: Largest position difference (m) between the student's loop and the reference over a drive.
LOOP_TOLERANCE = 1e-6


# ---------------------------------------------------------------- the reference assembly
def _propagated(Sigma, F, W):
    """``Sigma`` with its pose rows and columns moved by ``F`` and ``W`` added to the pose block."""
    Sigma = np.array(Sigma, dtype=float)
    Sigma[:6, :] = F @ Sigma[:6, :]
    Sigma[:, :6] = Sigma[:, :6] @ F.T
    Sigma[:6, :6] += W
    return Sigma


def _reference_predict(parts, world_T_imu, Sigma, u, tau, W):
    Sigma = _propagated(Sigma, parts.pose_transition(u, tau), W)
    return world_T_imu @ parts.se3_exp(tau * np.asarray(u, dtype=float)), Sigma


def _sensitivities(parts, world_T_imu, z, K, b, imu_T_cam):
    """New landmark means (k, 3) and their pose sensitivities G (k, 3, 6)."""
    p_new = np.array([parts.init_landmark(z_i, K, b, imu_T_cam, world_T_imu) for z_i in z]).reshape(-1, 3)
    s = np.c_[p_new, np.ones(len(p_new))] @ lie.se3_inv(world_T_imu).T  # in the IMU frame
    return p_new, np.array([(world_T_imu @ parts.odot(s_i))[:3] for s_i in s]).reshape(-1, 3, 6)


def _augmented(Sigma, G, C_pixels, cross=True, pose_weight=1.0):
    """``Sigma`` with the new landmarks of sensitivities ``G`` (k, 3, 6); a mistake drops the cross-covariance
    (``cross``) or weights the pose part ``G Sigma_pp G^T`` of the new block (``pose_weight``)."""
    k, D = len(G), len(Sigma)
    G = G.reshape(3 * k, 6)
    out = np.zeros((D + 3 * k, D + 3 * k))
    out[:D, :D] = Sigma
    if cross:
        out[D:, :D] = G @ Sigma[:6]
        out[:D, D:] = out[D:, :D].T
    block = G @ Sigma[:6, :6] @ G.T * pose_weight
    for i in range(k):
        block[3 * i:3 * i + 3, 3 * i:3 * i + 3] += C_pixels[i]
    out[D:, D:] = block
    return out


def _reference_add_landmarks(parts, world_T_imu, Sigma, z, K, b, imu_T_cam, C_pixels):
    p_new, G = _sensitivities(parts, world_T_imu, z, K, b, imu_T_cam)
    return p_new, _augmented(np.asarray(Sigma, dtype=float), G, C_pixels)


def _slam_update_with(parts, world_T_imu, Sigma, p_active, slots, z, Ks, cam_T_imu, noise_var,
                      side="right", sign=1.0, move_landmarks=True):
    m = p_active[slots]
    z_pred = parts.project(Ks, cam_T_imu, world_T_imu, m)
    J_pose = np.array([parts.pose_jacobian(Ks, cam_T_imu, world_T_imu, m_i) for m_i in m])
    J_lm = np.array([parts.landmark_jacobian(Ks, cam_T_imu, world_T_imu, m_i) for m_i in m])
    H = parts.slam_jacobian(J_pose, J_lm, slots, len(p_active))
    S = H @ Sigma @ H.T + noise_var * np.eye(len(H))
    gain = np.linalg.solve(S, H @ Sigma).T
    delta = sign * gain @ (np.asarray(z) - z_pred).ravel()
    step = parts.se3_exp(delta[:6])
    Sigma = (np.eye(len(Sigma)) - gain @ H) @ Sigma
    p_new = p_active + delta[6:].reshape(-1, 3) if move_landmarks else p_active
    return (world_T_imu @ step if side == "right" else step @ world_T_imu), 0.5 * (Sigma + Sigma.T), p_new


def _reference_slam_update(parts, world_T_imu, Sigma, p_active, slots, z, Ks, cam_T_imu, noise_var):
    return _slam_update_with(parts, world_T_imu, Sigma, p_active, slots, z, Ks, cam_T_imu, noise_var)


REFERENCE = capstone.Steps(_reference_predict, _reference_add_landmarks, _reference_slam_update)


def reference_capstone_steps():
    """The checks' reference assembly as :class:`visla_edu.course.capstone.Steps` (nothing printed).

    Notebook 07 runs the capstone's VIO loop with it and the student's ``pose_update``.
    """
    return REFERENCE


# ---------------------------------------------------------------- spies and drives
class _Spy:
    """Library parts that count their calls (the assembly must call ``parts``)."""

    def __init__(self):
        self.calls = {f.name: 0 for f in fields(capstone.Parts)}
        library = capstone.library_parts()
        self.parts = capstone.Parts(**{name: self._counting(name, getattr(library, name)) for name in self.calls})

    def _counting(self, name, fn):
        def call(*args, **kwargs):
            self.calls[name] += 1
            return fn(*args, **kwargs)
        return call

    def require(self, name, used):
        missing = [part for part in used if self.calls[part] == 0]
        if missing:
            raise fail(name, f"use parts.{missing[0]} (your own function) inside {name}",
                       f"{name} never called parts.{', parts.'.join(missing)}: the capstone assembles the filter "
                       "from the functions passed in, so that yours are the ones at work")


def _drive(hidden):
    """The drive of the loop checks (hidden: another seed) and its config, resolved on the visible one (same noise)."""
    from visla_edu import data, simulate

    visible = data.load("sim-tiny")
    config = run.resolve_config(visible, FilterConfig(slam_error="right", msckf_window=0))
    return (simulate.simulate_drive("tiny", seed=_hidden_seed() % 1000 + 1) if hidden else visible), config


def _run_loop(ds, config, steps, joint):
    return capstone.run_capstone(ds, config, capstone.library_parts(), steps, joint=joint)[:2]


def _compare_loops(name, got, reference, what):
    gap = np.linalg.norm(got[:, :3, 3] - reference[:, :3, 3], axis=1)
    if not np.all(np.isfinite(gap)) or gap.max() > LOOP_TOLERANCE:
        frame = int(np.argmax(np.where(np.isfinite(gap), gap, np.inf)))
        raise fail(name, f"the {what} loop leaves the reference at frame {frame}",
                   f"position {gap[frame]:.3g} m from the reference ({what} with the library's parts and the "
                   f"reference assembly; tolerance {LOOP_TOLERANCE:g} m)")


def _loop_summary(ds, poses, covs):
    gt = ds.ground_truth.world_T_imu
    nees = np.nanmean(metrics.nees(metrics.pose_errors(poses, gt), covs))
    return f"ATE {metrics.ate(poses, gt):.3f} m, mean pose NEES {nees:.1f} on {ds.name} ({ds.num_frames} frames)"


# ---------------------------------------------------------------- exercise 1: predict
def _predict_variants(parts, T, Sigma, u, tau, W):
    F = parts.pose_transition(u, tau)
    pose_only = np.array(Sigma)
    pose_only[:6, :6] = F @ Sigma[:6, :6] @ F.T + W
    step = parts.se3_exp(tau * u)
    return [
        ("the mean moves on the right: world_T_imu @ se3_exp(tau u)", lambda: step @ T),
        ("the step is se3_exp(tau u): multiply the twist by tau", lambda: T @ parts.se3_exp(u)),
    ], [
        ("the motion noise W is missing from the pose block", lambda: _propagated(Sigma, F, 0 * W)),
        ("the cross-covariance must move too: Sigma_pl <- F Sigma_pl\n(the landmark columns of the pose "
         "rows, and their transpose)", lambda: pose_only),
        ("F is on the wrong side: Sigma_pp <- F Sigma_pp F^T + W", lambda: _propagated(Sigma, F.T, W)),
    ]


_PREDICT_HIDDEN = (motion.predict_pose, motion.predict_pose_covariance, motion.predict_joint_covariance,
                   motion.imu_step, _reference_predict, _propagated)


@exercise_check
def check_capstone_predict(predict, hidden=False):
    """Exercise 12.1: ``predict(parts, world_T_imu, Sigma (D, D), u (6,), tau, W) -> (world_T_imu, Sigma)``.

    A tuple equal to ``(world_T_imu @ parts.se3_exp(tau u), Sigma')``, ``Sigma'`` with the pose rows
    and columns moved by ``F = parts.pose_transition(u, tau)`` and ``W`` added to the pose block
    (``rtol=1e-9``; ``atol=1e-9`` for the pose, 1e-12 for the covariance), through those two
    parts (``u = [v; w]``, ``tau`` in s); then the VIO loop (``parts.pose_update``). Hides
    ``motion.predict_pose``, ``predict_pose_covariance``, ``predict_joint_covariance``, ``imu_step``
    and the reference's.
    """
    name = "predict"
    generator, spy = rng(hidden), _Spy()
    call = student(predict, name, hide=_PREDICT_HIDDEN)
    for n in ([0, 3, 1] if hidden else [0, 2]):
        T, D = random_pose(generator), 6 + 3 * n
        Sigma, W = random_covariance(generator, D), np.diag(generator.uniform(1e-4, 1e-2, 6))
        u, tau = np.r_[generator.normal(scale=3.0, size=3), generator.normal(scale=0.3, size=3)], 0.1
        out = call(spy.parts, T, Sigma, u, tau, W)
        if not isinstance(out, tuple) or len(out) != 2:
            raise fail(name, "must return a tuple (world_T_imu, Sigma)")
        ref_T, ref_S = _reference_predict(capstone.library_parts(), T, Sigma, u, tau, W)
        mean_variants, cov_variants = _predict_variants(capstone.library_parts(), T, Sigma, u, tau, W)
        where = f"(a state with {n} landmarks)"
        compare(name, as_array(out[0], name, (4, 4), "pose"), ref_T, f"(pose mean) {where}", mean_variants,
                rtol=1e-9, atol=1e-9)
        compare(name, as_array(out[1], name, (D, D), "covariance"), ref_S, f"(covariance) {where}",
                cov_variants, rtol=1e-9, atol=1e-12)
    spy.require(name, ["pose_transition", "se3_exp"])
    ds, config = _drive(hidden)
    got, covs = _run_loop(ds, config, replace(REFERENCE, predict=call), joint=False)
    _compare_loops(name, got, _run_loop(ds, config, REFERENCE, joint=False)[0], "VIO")
    ok(f"{name}: agrees; VIO with it: {_loop_summary(ds, got, covs)}", hidden)


# ---------------------------------------------------------------- exercise 2: add_landmarks
def _landmark_case(generator, n, k, hidden=False):
    c = stereo_camera(hidden)
    T = random_pose(generator)
    m = points_in_view(generator, T, c.imu_T_cam, k, depth=(4.0, 30.0))
    z = c.predict(T, m) + generator.normal(scale=0.5, size=(k, 4))
    Sigma = random_covariance(generator, 6 + 3 * n) * 0.01
    A = generator.normal(size=(k, 3, 3)) * 0.3
    C_pixels = A @ np.swapaxes(A, 1, 2) + 0.01 * np.eye(3)
    return c, T, Sigma, z, C_pixels


def _landmark_variants(parts, T, Sigma, z, c, C_pixels):
    p_new, G = _sensitivities(parts, T, z, c.K, c.b, c.imu_T_cam)
    G_left = np.array([np.c_[np.eye(3), -lie.hat(p)] for p in p_new])  # exp(d^) T: world-frame perturbation
    G_body_frame = T[:3, :3].T @ G  # forgot the rotation to the world frame
    return [
        ("the new landmark's cross-covariance G Sigma_px is missing\n(the textbook shortcut: notebook 08, "
         "section 5, shows it makes the filter overconfident)", lambda: _augmented(Sigma, G, C_pixels, cross=False)),
        ("the new landmarks are correlated with each other too: G Sigma_pp G^T is one (3k, 3k) block",
         lambda: _augmented(Sigma, G, C_pixels, pose_weight=np.kron(np.eye(len(G)), np.ones((3, 3))))),
        ("G is the right perturbation's: (world_T_imu @ odot(s))[:3], s in the IMU frame",
         lambda: _augmented(Sigma, G_left, C_pixels)),
        ("G needs the rotation to the world frame: (world_T_imu @ odot(s))[:3]",
         lambda: _augmented(Sigma, G_body_frame, C_pixels)),
        ("the pixel part C_pixels is missing from the new block", lambda: _augmented(Sigma, G, 0 * C_pixels)),
        ("the pose part G Sigma_pp G^T is missing from the new block",
         lambda: _augmented(Sigma, G, C_pixels, pose_weight=0.0)),
    ]


@exercise_check
def check_capstone_landmarks(add_landmarks, hidden=False):
    """Exercise 12.2: ``add_landmarks(parts, world_T_imu, Sigma, z (k, 4), K, b, imu_T_cam, C_pixels (k, 3, 3))
    -> (p_new (k, 3), Sigma (D + 3k, D + 3k))``.

    A tuple: the means ``parts.init_landmark`` of each observation and ``Sigma`` augmented with the
    new block ``G Sigma_pp G^T + C_pixels`` (one (3k, 3k) block) and the cross-covariance
    ``G Sigma_px``, ``G = (world_T_imu @ parts.odot(s))[:3]`` for the new point ``s`` in the IMU
    frame (``rtol=1e-8``; ``atol=1e-8`` for the means, 1e-12 for the covariance), through those
    two parts (``b`` in m). No loop is run. Hides ``ekf.initialize_landmarks`` and the reference's helpers.
    """
    name = "add_landmarks"
    generator, spy = rng(hidden), _Spy()
    call = student(add_landmarks, name, hide=[ekf.initialize_landmarks, _reference_add_landmarks,
                                               _sensitivities, _augmented])
    for n, k in ([(0, 1), (4, 3), (1, 2)] if hidden else [(0, 2), (3, 1), (2, 3)]):
        c, T, Sigma, z, C_pixels = _landmark_case(generator, n, k, hidden)
        out = call(spy.parts, T, Sigma, z, c.K, c.b, c.imu_T_cam, C_pixels)
        if not isinstance(out, tuple) or len(out) != 2:
            raise fail(name, "must return a tuple (p_new, Sigma)")
        library = capstone.library_parts()
        p_ref, S_ref = _reference_add_landmarks(library, T, Sigma, z, c.K, c.b, c.imu_T_cam, C_pixels)
        where = f"({k} new landmarks, {n} in the state)"
        compare(name, as_array(out[0], name, (k, 3), "landmark means"), p_ref, f"(means) {where}", [
            ("triangulate with parts.init_landmark at world_T_imu", lambda: c.triangulate(z)),
        ], rtol=1e-8, atol=1e-8)
        D = 6 + 3 * (n + k)
        compare(name, as_array(out[1], name, (D, D), "covariance"), S_ref, f"(covariance) {where}",
                _landmark_variants(library, T, Sigma, z, c, C_pixels), rtol=1e-8, atol=1e-12)
    spy.require(name, ["init_landmark", "odot"])
    ok(f"{name}: means, the new block G Sigma_pp G^T + C and the cross-covariance G Sigma_px agree", hidden)


# ---------------------------------------------------------------- exercise 3: slam_update
def _slam_case(generator, n, observed, hidden=False):
    c = stereo_camera(hidden)
    T_true = random_pose(generator)
    m_true = points_in_view(generator, T_true, c.imu_T_cam, n, depth=(4.0, 30.0))
    Sigma = random_covariance(generator, 6 + 3 * n) * 0.01
    T = T_true @ lie.se3_exp(generator.normal(scale=0.02, size=6))
    p_active = m_true + generator.normal(scale=0.1, size=(n, 3))
    slots = generator.choice(n, size=observed, replace=False)
    z = c.predict(T_true, m_true[slots]) + generator.normal(scale=1.0, size=(observed, 4))
    return c, T, Sigma, p_active, slots, z


_SLAM_HIDDEN = (ekf.joint_update, ekf.joint_correction, ekf.pose_update, ekf.cholesky_update,
                cam.StereoCamera.predict_with_jacobians, cam.StereoCamera.jacobian_pose,
                cam.StereoCamera.jacobian_landmark, _reference_slam_update, _slam_update_with)


@exercise_check
def check_capstone_slam(slam_update, hidden=False):
    """Exercise 12.3: ``slam_update(parts, world_T_imu, Sigma, p_active (n, 3), slots (k,), z (k, 4), Ks,
    cam_T_imu, noise_var) -> (world_T_imu, Sigma, p_active)``.

    A tuple of three equal to the joint EKF update through ``parts`` (``H`` from
    ``parts.slam_jacobian``, ``L = Sigma H^T S^-1``, the pose corrected on the right by
    ``parts.se3_exp(dx[:6])``, every landmark moved by ``dx[6:]``, ``(I - L H) Sigma``
    symmetrised; pose and landmarks ``rtol=1e-7``, ``atol=1e-8``, covariance ``rtol=1e-6``,
    ``atol=1e-10``), using ``parts.project``, ``pose_jacobian`` and ``landmark_jacobian`` too;
    then the SLAM loop against ``run.run_filter(ds, "slam", config)``. ``p_active`` is in slot order,
    ``noise_var`` in px^2. Hides the library's joint and pose updates, the camera's Jacobians and the
    reference's update.
    """
    name = "slam_update"
    generator, spy = rng(hidden), _Spy()
    call = student(slam_update, name, hide=_SLAM_HIDDEN)
    library = capstone.library_parts()
    for n, k in ([(5, 2), (1, 1), (8, 5)] if hidden else [(4, 2), (6, 6)]):
        c, T, Sigma, p_active, slots, z = _slam_case(generator, n, k, hidden)
        args = (T, Sigma, p_active, slots, z, c.Ks, c.cam_T_imu, 4.0)
        out = call(spy.parts, *args)
        if not isinstance(out, tuple) or len(out) != 3:
            raise fail(name, "must return a tuple (world_T_imu, Sigma, p_active)")
        ref = _slam_update_with(library, *args)
        where = f"({k} of {n} landmarks observed)"
        compare(name, as_array(out[0], name, (4, 4), "pose"), ref[0], f"(pose mean) {where}", [
            ("the correction is applied on the left; use world_T_imu @ se3_exp(dx[:6])",
             lambda: _slam_update_with(library, *args, side="left")[0]),
            ("the correction has the wrong sign: the innovation is z - z_pred",
             lambda: _slam_update_with(library, *args, sign=-1.0)[0]),
        ], rtol=1e-7, atol=1e-8)
        D = 6 + 3 * n
        compare(name, as_array(out[1], name, (D, D), "covariance"), ref[1], f"(covariance) {where}", [
            ("the covariance did not change: Sigma <- (I - L H) Sigma", lambda: Sigma),
        ], rtol=1e-6, atol=1e-10)
        compare(name, as_array(out[2], name, (n, 3), "landmark means"), ref[2], f"(landmark means) {where}", [
            ("every landmark in the state moves: p_active + dx[6:].reshape(-1, 3)\n(the unobserved ones too, "
             "through their correlation)", lambda: p_active),
            ("the correction has the wrong sign: the innovation is z - z_pred",
             lambda: _slam_update_with(library, *args, sign=-1.0)[2]),
        ], rtol=1e-7, atol=1e-8)
    spy.require(name, ["project", "pose_jacobian", "landmark_jacobian", "slam_jacobian", "se3_exp"])
    _check_slam_loop(name, call, hidden)


def _check_slam_loop(name, call, hidden):
    """The joint loop with the student's update against the library's right-perturbation filter."""
    ds, config = _drive(hidden)
    got, covs = _run_loop(ds, config, replace(REFERENCE, slam_update=call), joint=True)
    _compare_loops(name, got, run.run_filter(ds, "slam", config, progress=False).world_T_imu, "SLAM")
    ok(f"{name}: agrees; SLAM with it matches the library's (slam_error='right'): {_loop_summary(ds, got, covs)}",
       hidden)


# ---------------------------------------------------------------- for the notebook's later cells
def capstone_steps(predict, add_landmarks, slam_update):
    """:class:`visla_edu.course.capstone.Steps` of the student's functions, the reference for any unfinished one.

    So that the notebook's later cells run before every exercise is done (one line printed per
    function). Each is called once, with the library's parts and nothing hidden, on a fixed probe
    (seed 9: 3 landmarks, 2 observed, and 2 new observations) and used if it runs (no exception)
    and each output is ``numpy.allclose`` to the reference's (``rtol=1e-6``, ``atol=1e-8``).
    """
    generator, library = np.random.default_rng(9), capstone.library_parts()
    c, T, Sigma, p_active, slots, z = _slam_case(generator, 3, 2)
    _, _, _, z_new, C_pixels = _landmark_case(generator, 1, 2)
    probes = {
        "predict": (library, T, Sigma, np.r_[1.0, 0.1, 0.0, 0.0, 0.02, 0.1], 0.1, 1e-4 * np.eye(6)),
        "add_landmarks": (library, T, Sigma, z_new, c.K, c.b, c.imu_T_cam, C_pixels),
        "slam_update": (library, T, Sigma, p_active, slots, z, c.Ks, c.cam_T_imu, 4.0),
    }
    chosen = {}
    for fn_name, fn in (("predict", predict), ("add_landmarks", add_landmarks), ("slam_update", slam_update)):
        reference = getattr(REFERENCE, fn_name)
        try:
            out = fn(*probes[fn_name])
            agrees = all(np.allclose(np.asarray(a, dtype=float), b, rtol=1e-6, atol=1e-8)
                         for a, b in zip(out, reference(*probes[fn_name]), strict=True))
        except Exception:  # noqa: BLE001 - a stub raises NotImplementedError, broken code anything
            agrees = False
        print(f"using your {fn_name}" if agrees
              else f"using the reference {fn_name} (yours is not finished or disagrees)")
        chosen[fn_name] = fn if agrees else reference
    return capstone.Steps(**chosen)
