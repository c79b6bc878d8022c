#!/usr/bin/env python3
"""A pushing data generator that is not dynlab's simulator: quasi-static pushing of a rectangular
block by a disc pusher, solved exactly (no limit-surface approximation) as the principle of
maximal dissipation over a dense support grid (15 × 15 points, each with its own Coulomb
friction and share of the block's weight), stepped every 0.5 mm of pusher travel in numpy, seen
by a motion capture (10 Hz block poses, 0.5 mm / 2 mrad noise) and written by `rosbags` as a
rosbag2 MCAP bag under other topic names than dynlab's (`/mocap/box/pose`, PoseStamped;
`/pusher/push`, dynlab_msgs/PushAction, one per push, published just after the pose it starts
from).

The pusher touches the block's face `x = −a/2` (block frame) at `κ·p·b/2` (κ = 0.95) and moves on
a straight line at the angle φ to the face's inward normal, by ℓ·0.1 m at 5 cm/s; the contact is
lost where it leaves the face. Each step solves, for the block's twist `V`,

    min  Σᵢ wᵢ·‖Aᵢ vᵢ(V)‖ − G·V   subject to the contact's velocity constraint(s),

(`vᵢ`: support point i's velocity, `Aᵢ`: its friction, `G`: a table slope's pull at the centre
of mass) by Newton's method on its optimality conditions: a frictionless pusher only presses
along the face normal; with pusher friction the contact sticks while the force stays in its
friction cone, and slides on the cone's edge otherwise.

Hidden effects (comma-separated `--effects`): in dynlab's library `com_offset` (the weight rests
on the table by a linear pressure whose centroid is (10, −6) mm off the block's centre),
`table_tilt` (the table slopes 1.7° down towards the world direction 2 rad, μ 0.3),
`friction_patch` (a disc at (0.1, 0.05) m of radius 0.2 m where the table's friction is 0.4 of
its own), `pusher_friction` (μ_p = 0.3 at the pusher's contact); outside the library
`anisotropic` (a table with a grain at 30°: friction across it 1.6 times that along it),
`friction_band` (a 0.2 m wide band through (0, 0.1) at 0.4 rad where the table's friction is 2.5
times its own) and `slippery_band` (a 0.24 m wide band through (0.05, −0.1) at −0.7 rad where it is
0.4 of its own: a low-friction region that is not a disc).

The block's size and the pusher's radius are the datasheet's (0.1 × 0.1 m, r 1 cm) scaled by
seeded factors in [1 − f, 1 + f] (`--perturb f`, default 0.1), the same for every bag of one
`--block-seed`; `--print-size` prints the block's measured depth and width (to the millimetre)
for `dynlab train --set a=… --set b=…`.

    foreign_push.py OUT_DIR --block-seed 3 --seed 7 [--effects com_offset,table_tilt]
                    [--episodes 40] [--pushes 10] [--perturb 0.1]
    foreign_push.py --block-seed 3 --print-size
"""
import argparse
import math
import sys
from pathlib import Path

import numpy as np

DATASHEET = dict(a=0.1, b=0.1, rp=0.01)
EFFECTS = ("com_offset", "table_tilt", "friction_patch", "pusher_friction", "anisotropic", "friction_band",
           "slippery_band")
GRID = 15  # support points per side
KAPPA = 0.95  # usable share of the half face
PUSH_M = 0.1  # metres of push at ℓ = 1
SPEED = 0.05  # pusher speed, m/s
STEP_M = 0.0005  # pusher travel per solver step, m
OFFSET = (0.01, -0.006)  # com_offset, m (block frame)
MU = 0.3  # table friction (the slope's pull is tan α / μ of the friction)
TILT = (math.tan(math.radians(1.7)) / MU, 2.0)  # normalised pull, world direction (rad)
PATCH = ((0.1, 0.05), 0.2, 0.4)  # centre, radius, friction factor
MU_P = 0.3  # pusher_friction
GRAIN = (math.radians(30.0), 1.6)  # grain angle, across/along friction ratio
BAND = ((0.0, 0.1), 0.4, 0.1, 2.5)  # a point on its centre line, angle, half width, factor
SLIPPERY_BAND = ((0.05, -0.1), -0.7, 0.12, 0.4)  # likewise
POSE_RATE = 10.0  # Hz
PERIOD = 3.0  # s between push starts


def option_error(perturb, episodes, pushes):
    """What is wrong with the options, or None."""
    if not 0.0 <= perturb < 0.5:
        return f"--perturb {perturb:g}: each size is scaled within 1 ± F, so F is in [0, 0.5)"
    if episodes < 1 or pushes < 1:
        return f"--episodes {episodes} --pushes {pushes}: both must be at least 1"
    return None


def block_params(block_seed, perturb):
    rng = np.random.default_rng(2000 + block_seed)
    return {k: v * (1.0 + rng.uniform(-perturb, perturb)) for k, v in DATASHEET.items()}


class Block:
    """The block's support grid (block frame), weights and friction, for a set of effects."""

    def __init__(self, p, effects):
        self.a, self.b, self.rp = p["a"], p["b"], p["rp"]
        self.effects = effects
        u = (np.arange(GRID) + 0.5) / GRID - 0.5
        sx, sy = np.meshgrid(u * self.a, u * self.b, indexing="ij")
        self.s = np.stack([sx.ravel(), sy.ravel()], axis=1)
        w = np.ones(len(self.s))
        if "com_offset" in effects:
            # a linear pressure whose centroid is OFFSET
            var = self.s.var(axis=0)
            w = 1.0 + self.s[:, 0] * OFFSET[0] / var[0] + self.s[:, 1] * OFFSET[1] / var[1]
            if np.any(w <= 0.0):
                raise ValueError("the centre-of-mass offset is too large for this block")
        self.w = w / w.sum()
        self.com = (self.w[:, None] * self.s).sum(axis=0)

    def friction(self, pts):
        """Per world point: (scale, across/along ratio, grain angle)."""
        k = np.ones(len(pts))
        if "friction_patch" in self.effects:
            (cx, cy), r, f = PATCH
            k = np.where((pts[:, 0] - cx) ** 2 + (pts[:, 1] - cy) ** 2 < r * r, k * f, k)
        for name, band in (("friction_band", BAND), ("slippery_band", SLIPPERY_BAND)):
            if name in self.effects:
                (px, py), ang, half, f = band
                d = -(pts[:, 0] - px) * math.sin(ang) + (pts[:, 1] - py) * math.cos(ang)
                k = np.where(np.abs(d) < half, k * f, k)
        return k


def rot(th):
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def minimize(phi, C, d, V0):
    """Newton's method from a feasible start with backtracking: the minimum of the convex `phi`
    (value, gradient, Hessian) on `C·V = d`, and its multipliers."""
    V = V0 + C.T @ np.linalg.solve(C @ C.T, d - C @ V0)
    m = len(d)
    lam = np.zeros(m)
    f, g, H = phi(V)
    for _ in range(100):
        K = np.zeros((3 + m, 3 + m))
        K[:3, :3] = H
        K[:3, 3:] = C.T
        K[3:, :3] = C
        sol = np.linalg.solve(K + 1e-13 * np.eye(3 + m), np.concatenate([-g, np.zeros(m)]))
        dv, lam = sol[:3], -sol[3:]
        dec = -g @ dv  # the Newton decrement²
        if dec < 1e-16:
            break
        s = 1.0
        while True:
            f1, g1, H1 = phi(V + s * dv)
            if f1 <= f - 0.25 * s * dec or s < 1e-10:
                break
            s *= 0.5
        V, f, g, H = V + s * dv, f1, g1, H1
    return V, lam


def solve_twist(block, pose, c_arm, n, t, u, d_n, stick, slide_sign, V0):
    """The twist (vx, vy, ω) of the block's centre and the contact force (f_n, f_t) of one step.

    `c_arm`: the contact point relative to the centre (world axes); `n`, `t`: the face's normal
    and tangent; `u`: the pusher's velocity; `d_n`: the normal velocity the contact must have;
    `stick`: also match the tangential velocity; `slide_sign` (not sticking, with pusher
    friction): the force is `f_n·(n + slide_sign·μ_p·t)`."""
    R = rot(pose[2])
    r = block.s @ R.T  # support arms, world axes
    pts = pose[:2] + r
    w = block.w * block.friction(pts)
    if "anisotropic" in block.effects:
        g, ratio = GRAIN
        G = rot(g)
        A = G @ np.diag([1.0, ratio]) @ G.T
    else:
        A = np.eye(2)
    # point velocities v_i = J_i V, J_i = [[1, 0, −r_y], [0, 1, r_x]]
    J = np.zeros((len(r), 2, 3))
    J[:, 0, 0] = 1.0
    J[:, 1, 1] = 1.0
    J[:, 0, 2] = -r[:, 1]
    J[:, 1, 2] = r[:, 0]
    AJ = np.einsum("ab,ibc->iac", A, J)
    g_lin = np.zeros(3)
    if "table_tilt" in block.effects:
        mag, ang = TILT
        gv = mag * np.array([math.cos(ang), math.sin(ang)])
        arm = R @ block.com
        g_lin = np.array([gv[0], gv[1], arm[0] * gv[1] - arm[1] * gv[0]])
    eps2 = 1e-14

    def phi(V):
        av = np.einsum("iac,c->ia", AJ, V)
        nrm = np.sqrt((av * av).sum(axis=1) + eps2)
        f = w @ nrm - g_lin @ V
        grad = np.einsum("i,iac,ia->c", w / nrm, AJ, av) - g_lin
        P = np.eye(2)[None] * (nrm**2)[:, None, None] - np.einsum("ia,ib->iab", av, av)
        H = np.einsum("i,iac,iab,ibd->cd", w / nrm**3, AJ, P, AJ)
        return f, grad, H

    Jc = np.array([[1.0, 0.0, -c_arm[1]], [0.0, 1.0, c_arm[0]]])
    if slide_sign == 0:
        rows, rhs = [n @ Jc], [d_n]
        if stick:
            rows.append(t @ Jc)
            rhs.append(t @ u)
        V, lam = minimize(phi, np.array(rows), np.array(rhs), V0)
        return V, (lam[0], lam[1] if stick else 0.0)
    # sliding: the twist whose friction balances a force along the cone's edge (and the
    # slope), on any scale; then the scale at which the contact keeps up with the pusher
    col = Jc.T @ (n + slide_sign * MU_P * t)
    V, lam = minimize(phi, col[None], np.array([1.0]), V0 / max(col @ V0, 1e-9))
    k = d_n / (n @ Jc @ V)
    return k * V, (lam[0], slide_sign * MU_P * lam[0])


def push(block, pose, p, phi, ell, t0, rng, record):
    """One push from `pose`; appends (time, pose) samples at POSE_RATE to `record`; returns the
    pose after it (and settling until the next push)."""
    pose = np.array(pose, dtype=float)
    R = rot(pose[2])
    a, b = block.a, block.b
    # the pusher's centre starts touching the face at κ·p·b/2, and moves along θ₀ + φ
    q = pose[:2] + R @ np.array([-a / 2 - block.rp, KAPPA * p * b / 2])
    direction = np.array([math.cos(pose[2] + phi), math.sin(pose[2] + phi)])
    length = ell * PUSH_M
    steps = max(int(math.ceil(length / STEP_M)), 1)
    h = length / steps / SPEED  # s per step
    u = SPEED * direction
    V = np.array([u[0], u[1], 0.0])
    next_sample = t0
    contact = True
    slide_sign = 0
    for j in range(steps + 1):
        tj = t0 + j * h
        while next_sample <= tj + 1e-12:
            record.append((next_sample, pose.copy()))
            next_sample += 1.0 / POSE_RATE
        if j == steps or not contact:
            break
        R = rot(pose[2])
        n, t = R[:, 0], R[:, 1]
        qb = R.T @ (q - pose[:2])
        cy = qb[1]
        pen = qb[0] - (-a / 2 - block.rp)  # > 0: the disc is inside the face's offset
        if abs(cy) > b / 2 or n @ u <= 0.0:
            contact = False
            break
        c_arm = R @ np.array([-a / 2, cy])
        d_n = n @ u + pen / h
        if "pusher_friction" in block.effects:
            V1, f = solve_twist(block, pose, c_arm, n, t, u, d_n, True, 0, V)
            if f[0] > 0 and abs(f[1]) <= MU_P * f[0]:
                V = V1
            else:
                # sliding: the friction opposes the contact's slip along the face
                s = 1.0 if f[1] > 0 else -1.0
                V, f = solve_twist(block, pose, c_arm, n, t, u, d_n, False, s, V)
        else:
            V, f = solve_twist(block, pose, c_arm, n, t, u, d_n, False, 0, V)
        if not np.all(np.isfinite(V)) or f[0] < 0.0:
            raise RuntimeError("the quasi-static step has no solution (the pusher would pull)")
        pose = pose + h * V
        q = q + h * u
    # the rest of the period: the block at rest, sampled on
    while next_sample < t0 + PERIOD - 1e-9:
        record.append((next_sample, pose.copy()))
        next_sample += 1.0 / POSE_RATE
    return pose


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", nargs="?")
    ap.add_argument("--block-seed", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--effects", default="")
    ap.add_argument("--episodes", type=int, default=40)
    ap.add_argument("--pushes", type=int, default=10)
    ap.add_argument("--perturb", type=float, default=0.1)
    ap.add_argument("--print-size", action="store_true",
                    help="print the block's measured depth and width (m) and exit")
    a = ap.parse_args()
    if (err := option_error(a.perturb, a.episodes, a.pushes)) is not None:
        ap.error(err)
    effects = {e for e in a.effects.split(",") if e}
    unknown = effects - set(EFFECTS)
    if unknown:
        ap.error(f"unknown effects {sorted(unknown)}; known: {', '.join(EFFECTS)}")
    p = block_params(a.block_seed, a.perturb)
    if a.print_size:
        print(f"a={p['a']:.3f} b={p['b']:.3f}")
        return
    if a.out is None:
        ap.error("give OUT_DIR (or --print-size)")
    block = Block(p, effects)
    rng = np.random.default_rng(a.seed)

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(
        "std_msgs/Header header\nfloat64 location\nfloat64 angle\nfloat64 length\n",
        "dynlab_msgs/msg/PushAction"))
    T = ts.types

    def stamp(t_ns):
        return T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)

    msgs = []
    t_start = 1_760_000_000.0
    t = 0.0
    for _ in range(a.episodes):
        pose = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-math.pi, math.pi)])
        record = []
        for _ in range(a.pushes):
            loc = rng.uniform(-1.0, 1.0)
            phi = rng.uniform(-math.pi / 2, math.pi / 2)
            ell = rng.uniform(0.0, 1.0)
            msgs.append((t + 0.001, "push", (loc, phi, ell)))
            try:
                pose = push(block, pose, loc, phi, ell, t, rng, record)
            except RuntimeError as e:
                sys.exit(f"foreign_push.py: push (p {loc:.3f}, φ {phi:.3f}, ℓ {ell:.3f}) from pose {pose}: {e}; "
                         "try another --seed or weaker effects")
            t += PERIOD
        record.append((t, pose.copy()))  # the settled pose after the last push
        for tm, s in record:
            msgs.append((tm, "pose", s + np.array([rng.normal(0, 5e-4), rng.normal(0, 5e-4),
                                                   rng.normal(0, 2e-3)])))
        t += 5.0  # the block is put back between episodes
    out = Path(a.out)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        pose_c = w.add_connection("/mocap/box/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
        push_c = w.add_connection("/pusher/push", "dynlab_msgs/msg/PushAction", typestore=ts)
        for tm, kind, v in sorted(msgs, key=lambda e: e[0]):
            t_ns = int(round((t_start + tm) * 1e9))
            header = T["std_msgs/msg/Header"](stamp=stamp(t_ns), frame_id="table")
            if kind == "pose":
                m = T["geometry_msgs/msg/PoseStamped"](
                    header=header,
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=float(v[0]), y=float(v[1]), z=0.05),
                        orientation=T["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(v[2] / 2), w=math.cos(v[2] / 2))))
                w.write(pose_c, t_ns, ts.serialize_cdr(m, "geometry_msgs/msg/PoseStamped"))
            else:
                m = T["dynlab_msgs/msg/PushAction"](header=header, location=float(v[0]),
                                                    angle=float(v[1]), length=float(v[2]))
                w.write(push_c, t_ns, ts.serialize_cdr(m, "dynlab_msgs/msg/PushAction"))
    print(f"{out}: {a.episodes} × {a.pushes} pushes, effects {sorted(effects) or 'none'}, block seed {a.block_seed}")


if __name__ == "__main__":
    main()
