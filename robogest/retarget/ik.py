"""Direction-matching inverse kinematics on the robot's MuJoCo model.

Humans and robots differ in proportions, so positions cannot be copied; directions can. Each YAML
``retarget`` vector asks the robot link between two sites to point where the human bone between two
joints points. Damped least squares solves all vectors at once per frame, warm-started from the
previous frame, with a weak pull towards the rest pose for joints the vectors leave free, and the
joint limits enforced after every step. Held joints (a humanoid's legs, ``held: true`` in the YAML) are not
variables: they stay at their rest angle while the others solve (a vector may still span bodies below them).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from robogest.errors import ConfigError
from robogest.motion.human_motion import HumanMotion
from robogest.retarget.base import HUMAN_TO_ROBOT, Retargeter, RetargetResult
from robogest.robot.config import RobotConfig
from robogest.robot.mjcf import load_mjcf
from robogest.robot.problems import not_in_model


class DirectionIK(Retargeter):
    """Damped-least-squares IK on link directions.

    Parameters
    ----------
    robot : RobotConfig
    iterations : int
        Gauss-Newton steps per frame (warm start makes 2–3 enough at 20–50 fps).
    damping : float
        Levenberg–Marquardt damping λ (unitless, directions are unit vectors).
    rest_weight : float
        Weight of the pull towards the rest pose, relative to a direction error of 1.
    tolerance_rad : float
        Stop iterating once no joint moves more than this in a step.
    avoid_collisions : bool
        Never command a pose in which the robot's geoms penetrate each other or the world (a desk arm's
        hand pushed into its desk): such a frame moves only as far towards its IK solution as stays
        collision-free (bisection from the previous frame).
    """

    def __init__(
        self,
        robot: RobotConfig,
        iterations: int = 4,
        damping: float = 0.05,
        rest_weight: float = 0.002,
        tolerance_rad: float = 1e-3,
        avoid_collisions: bool = True,
    ):
        super().__init__(robot)
        self.avoid_collisions = avoid_collisions
        self.iterations = iterations
        self.tolerance_rad = tolerance_rad
        self.damping = damping
        self.rest_weight = rest_weight
        self.model = load_mjcf(robot)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.qadr = np.empty(len(robot.joints), dtype=int)
        self.dadr = np.empty(len(robot.joints), dtype=int)
        for k, j in enumerate(robot.joints):
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
            if jid < 0:
                names = [m.joint(i).name for i in range(m.njnt)]
                problem = not_in_model(
                    robot.path or robot.name, f"joints[{k}].name", j.name, "joint", names, robot.model_path
                )
                raise ConfigError(str(problem))
            self.qadr[k] = m.jnt_qposadr[jid]
            self.dadr[k] = m.jnt_dofadr[jid]
        self.site_ids: list[tuple[int, int]] = []
        for k, v in enumerate(robot.retarget):
            ids = []
            for s in v.robot:
                sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, s)
                if sid < 0:
                    names = [m.site(i).name for i in range(m.nsite)]
                    where = robot.path or robot.name
                    problem = not_in_model(where, f"retarget[{k}].robot", s, "site", names, robot.model_path)
                    raise ConfigError(str(problem))
                ids.append(sid)
            self.site_ids.append((ids[0], ids[1]))
        self.human_pairs = [v.human for v in robot.retarget]
        self.frame = Rotation.from_euler("xyz", robot.retarget_frame_rpy_rad).as_matrix()  # (3, 3)
        self.weights = np.sqrt(np.array([v.weight for v in robot.retarget]))  # (K,)
        self.rest = robot.rest_q_rad
        held = robot.held_mask
        # a held joint's limits are its angle: the clip after every step keeps it there
        self.lo = np.where(held, self.rest, robot.q_min_rad)
        self.hi = np.where(held, self.rest, robot.q_max_rad)
        self.free = np.flatnonzero(~held)  # (F,) the joints IK solves for
        # Hinge Jacobians are built from joint axes and anchors (a x (p - anchor)) instead of
        # mj_jacSite: one vectorised cross product per step instead of two MuJoCo calls per site.
        self.jids = np.array([m.dof_jntid[a] for a in self.dadr])  # (J,)
        bad = [
            j.name
            for j, jid in zip(robot.joints, self.jids, strict=True)
            if m.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE
        ]
        if bad:
            raise ConfigError(f"{robot.path}: joints {bad} are not hinge joints in {robot.model_path}; IK needs hinges")
        self._eye3 = np.eye(3)[None]
        self._eye_j = np.eye(len(self.free))
        self.sites = np.array(sorted({s for pair in self.site_ids for s in pair}))  # (S,) unique sites
        self._sa = np.searchsorted(self.sites, [a for a, _ in self.site_ids])  # (K,) index into sites
        self._sb = np.searchsorted(self.sites, [b for _, b in self.site_ids])
        jbody = m.jnt_bodyid[self.jids]
        self._moves = np.zeros((len(self.sites), len(self.jids)))  # (S, J) 1 where joint j moves site s
        for si, sid in enumerate(self.sites):
            b = m.site_bodyid[sid]
            while b > 0:
                self._moves[si, jbody == b] = 1.0
                b = m.body_parentid[b]

    def human_directions(self, motion: HumanMotion) -> np.ndarray:
        """Unit bone directions in the robot frame, ``(T, K, 3)``."""
        pos = motion.positions() @ (self.frame @ HUMAN_TO_ROBOT).T  # (T, J, 3) robot frame
        idx = motion.skeleton.index
        a = np.stack([pos[:, idx(h0)] for h0, _ in self.human_pairs], axis=1)  # (T, K, 3)
        b = np.stack([pos[:, idx(h1)] for _, h1 in self.human_pairs], axis=1)
        d = b - a
        unit: np.ndarray = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
        return unit

    def _links(self, q: np.ndarray, with_jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Robot link directions ``(K, 3)`` and their Jacobians ``(K, 3, F)`` (free joints) at angles ``q (J,)``."""
        m, d = self.model, self.data
        d.qpos[self.qadr] = q
        mujoco.mj_kinematics(m, d)
        p = d.site_xpos[self.sites]  # (S, 3)
        v = p[self._sb] - p[self._sa]  # (K, 3)
        length = np.maximum(np.sqrt((v * v).sum(axis=1, keepdims=True)), 1e-9)  # (K, 1)
        n = v / length
        if not with_jac:
            return n, None
        jids = self.jids[self.free]
        axis = d.xaxis[jids]  # (F, 3) world joint axes
        anchor = d.xanchor[jids]  # (F, 3)
        r = p[:, None] - anchor[None]  # (S, F, 3) lever arms
        a = axis[None]
        jp = np.stack(  # (S, F, 3) = axis x lever, zero where the joint does not move the site
            [a[..., 1] * r[..., 2] - a[..., 2] * r[..., 1],
             a[..., 2] * r[..., 0] - a[..., 0] * r[..., 2],
             a[..., 0] * r[..., 1] - a[..., 1] * r[..., 0]],
            axis=-1,
        ) * self._moves[:, self.free, None]  # fmt: skip
        dv = (jp[self._sb] - jp[self._sa]).transpose(0, 2, 1)  # (K, 3, F)
        proj = self._eye3 - n[:, :, None] * n[:, None, :]  # (K, 3, 3) removes the length change
        return n, proj @ dv / length[:, :, None]

    def followable(self) -> np.ndarray:
        """``(K,)`` bool: retarget vectors that can follow their bone: among the joints that turn the link (at rest),
        those on the body deepest in the tree are not all held. A finger's or a torso's vector with the waist held
        is not; an arm's is, whether the waist is held or not (the elbow, not the waist, points the forearm)."""
        m = self.model
        depth = np.zeros(m.nbody, dtype=int)
        for b in range(1, m.nbody):
            depth[b] = depth[m.body_parentid[b]] + 1
        n0, _ = self._links(self.rest, with_jac=False)
        turns = np.zeros((len(n0), len(self.rest)), dtype=bool)  # (K, J)
        for j in range(len(self.rest)):
            q = self.rest.copy()
            q[j] += 1e-4
            n1, _ = self._links(q, with_jac=False)
            turns[:, j] = np.abs(n1 - n0).max(axis=1) > 1e-8
        self._links(self.rest, with_jac=False)
        jdepth = depth[m.jnt_bodyid[self.jids]]  # (J,)
        held = self.robot.held_mask
        out = np.zeros(len(n0), dtype=bool)
        for k in range(len(n0)):
            if turns[k].any():
                deepest = turns[k] & (jdepth == jdepth[turns[k]].max())
                out[k] = bool((deepest & ~held).any())
        return out

    def solve_frame(self, target: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame: joint angles ``(J,)`` pointing the links along ``target (K, 3)``, from ``q``.

        Returns the angles and the link directions ``(K, 3)`` they give.
        """
        free = self.free
        nf = len(free)
        reg = (self.damping**2 + self.rest_weight) * self._eye_j
        q = np.clip(q, self.lo, self.hi)  # held joints at their angle
        n, jac = self._links(q, with_jac=True)
        for it in range(self.iterations):
            e = ((target - n) * self.weights[:, None]).reshape(-1)  # (3K,)
            jw = (jac * self.weights[:, None, None]).reshape(-1, nf)  # (3K, F)
            g = jw.T @ e + self.rest_weight * (self.rest[free] - q[free])
            step = np.linalg.solve(jw.T @ jw + reg, g)
            q = q.copy()
            q[free] += step
            q = np.clip(q, self.lo, self.hi)
            last = it == self.iterations - 1 or nf == 0 or float(np.abs(step).max()) < self.tolerance_rad
            n, jac = self._links(q, with_jac=not last)
            if last:
                break
        return q, n

    def in_collision(self, q: np.ndarray, tol_m: float = 1e-3) -> bool:
        """Whether joint angles ``q (J,)`` make any two geoms penetrate by more than ``tol_m``."""
        m, d = self.model, self.data
        d.qpos[self.qadr] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return bool(d.ncon) and bool((d.contact.dist < -tol_m).any())

    def _back_off(self, q_free: np.ndarray, q_new: np.ndarray, steps: int = 6) -> np.ndarray:
        """The furthest point from collision-free ``q_free`` towards ``q_new`` that is collision-free."""
        lo, hi = 0.0, 1.0
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            if self.in_collision(q_free + mid * (q_new - q_free)):
                hi = mid
            else:
                lo = mid
        q_rad: np.ndarray = q_free + lo * (q_new - q_free)
        return q_rad

    def retarget(self, motion: HumanMotion, q0: np.ndarray | None = None) -> RetargetResult:
        targets = self.human_directions(motion)  # (T, K, 3)
        t_n = motion.n_frames
        q = np.clip(self.rest if q0 is None else np.asarray(q0, dtype=np.float64), self.lo, self.hi)
        check = self.avoid_collisions and not self.in_collision(q)  # nothing to keep if we start in contact
        out = np.empty((t_n, len(self.robot.joints)))
        err = np.empty((t_n, len(self.site_ids)))
        blocked = np.zeros(t_n, dtype=bool)
        for t in range(t_n):
            q_new, n = self.solve_frame(targets[t], q)
            if check and self.in_collision(q_new):
                q_new = self._back_off(q, q_new)
                n, _ = self._links(q_new, with_jac=False)
                blocked[t] = True
            q = q_new
            out[t] = q
            err[t] = np.arccos(np.clip(np.sum(n * targets[t], axis=-1), -1.0, 1.0))
        return RetargetResult(q_rad=out, fps=motion.fps, direction_error_rad=err, collision_frames=blocked)
