#!/usr/bin/env python3
"""A car data generator that is not dynlab's simulator: the textbook dynamic bicycle of a 1:43 RC
car (Pacejka lateral tyres, a DC drivetrain; by default no friction ellipse, so the drive force
never takes the rear tyres' lateral grip — `--friction-ellipse` caps the rear tyre's combined
force at its peak instead), integrated with RK4 at 1 kHz in
numpy, driven by a waypoint-chasing driver with sweeps and throttle steps, seen by a motion
capture (120 Hz unless `--rate`; jittered stamps, 1 mm / 0.004 rad noise, dropouts) and written by
`rosbags` as a rosbag2 MCAP bag under other topic names than dynlab's (`/mocap/orca/pose`, PoseStamped; `/orca/cmd`,
AckermannDriveStamped at 50 Hz: steering angle, duty as `acceleration`).

Hidden effects (comma-separated `--effects`): `aero_drag` (−c·vₓ|vₓ| on the drive force, c 0.01),
`steering_offset` (+0.03 rad), `motor_lag` (first-order duty, τ 0.2 s), `grip_patch` (a disc at
(0.5, 0) of radius 0.6 m where both tyres keep 45 % of their force), `cmd_delay` (both
commands reach the car 60 ms after they are sent: radio and servo electronics, a transport delay;
dynlab's `command_delay` approximates it by a Padé filter), `servo_rate` (a steering servo that follows
the command with a 25 ms proportional loop and turns the wheels at most 2.5 rad/s; dynlab's
`steering_lag` has a smooth rate limit), and outside dynlab's library `steering_gain_speed` (the
steering angle divided by 1 + vₓ²/4), `grip_band` (a 0.8 m wide band through (0, 0.3) at 0.5
rad where the tyres keep half their force), `yaw_damping` (a yaw moment −c·ω, c = 4 s⁻¹
times I_z: the tyres' relaxation and the chassis' scrub), `floor_tilt` (the floor slopes
1.5° down towards the heading 2 rad: gravity pulls the car along it with g·sin 1.5° =
0.257 m/s², in the body frame `v̇ₓ += a·cos(ψ − 2)`, `v̇_y −= a·sin(ψ − 2)`), `steer_stop` (the
wheels meet a mechanical end stop at ±0.25 rad, the commands reach ±0.35 rad), `traction_limit`
(the rear tyres pass at most 0.06 N of drive force before they spin) and `battery_sag` (the
drive force falls with the battery's charge, by 30 % from the first drive of the bag to its
last).

The car's parameters are the datasheet's scaled by seeded factors in [1 − f, 1 + f]
(`--perturb f`, default 0.1), the same for every bag of one `--car-seed`: a nominal bag and an
effect bag of the same car differ only in the effect and the driving seed.

    foreign_car.py OUT_DIR --car-seed 3 --seed 7 [--effects aero_drag,steering_offset]
                   [--episodes 4] [--duration 15] [--perturb 0.1] [--rate 120] [--friction-ellipse]
"""
import argparse
import math
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

# the ORCA 1:43 car's datasheet (Liniger et al.)
DATASHEET = dict(m=0.041, Iz=27.8e-6, lf=0.029, lr=0.033, Bf=2.579, Cf=1.2, Df=0.192,
                 Br=3.3852, Cr=1.2691, Dr=0.1737, Cm1=0.287, Cm2=0.0545, Cr0=0.0518, Cr2=0.00035)
STEER_MAX = 0.35
FLOOR = 1.3  # the driver keeps the car within ±FLOOR m
EFFECTS = ("aero_drag", "steering_offset", "motor_lag", "grip_patch", "steering_gain_speed", "grip_band",
           "cmd_delay", "yaw_damping", "servo_rate", "floor_tilt", "steer_stop", "traction_limit",
           "battery_sag")
DELAY = 0.06  # s, cmd_delay
SERVO_TAU, SERVO_RATE = 0.025, 2.5  # s, rad/s: servo_rate
TILT_ACC, TILT_DIR = 9.81 * math.sin(math.radians(1.5)), 2.0  # m/s², rad: floor_tilt
STOP = 0.25  # rad, steer_stop: the wheels' mechanical end stop
TRACTION = 0.06  # N, traction_limit: the most drive force the rear tyres pass before they spin
SAG = 0.3  # battery_sag: the drive force's loss over the bag


def option_error(rate, perturb):
    """What is wrong with a motion capture `rate` (Hz) or a parameter spread `perturb`, or None."""
    if not 1.0 <= rate <= 1000.0:
        return f"--rate {rate:g}: the motion capture runs at 1 to 1000 Hz (the car is integrated at 1 kHz)"
    if not 0.0 <= perturb < 1.0:
        return f"--perturb {perturb:g}: each parameter is scaled within 1 ± F, so F is in [0, 1)"
    return None


def car_params(car_seed, perturb):
    rng = np.random.default_rng(1000 + car_seed)
    return {k: v * (1.0 + rng.uniform(-perturb, perturb)) for k, v in DATASHEET.items()}


def grip(effects, x, y):
    g = 1.0
    if "grip_patch" in effects and (x - 0.5) ** 2 + y ** 2 < 0.6 ** 2:
        g *= 0.45
    if "grip_band" in effects:
        a = 0.5  # its centre line through (0, 0.3)
        if abs(-x * math.sin(a) + (y - 0.3) * math.cos(a)) < 0.4:
            g *= 0.5
    return g


def deriv(p, effects, s, steer, duty):
    """State (x, y, ψ, vₓ, v_y, ω, duty_state, wheel angle) → its derivative."""
    x, y, psi, vx, vy, om, dstate, wheels = s
    d = dstate if "motor_lag" in effects else duty
    delta = wheels if "servo_rate" in effects else steer
    if "steer_stop" in effects:
        delta = min(max(delta, -STOP), STOP)
    if "steering_offset" in effects:
        delta += 0.03
    if "steering_gain_speed" in effects:
        delta /= 1.0 + vx * vx / 4.0
    vxs = max(abs(vx), 0.05)
    af = delta - math.atan2(om * p["lf"] + vy, vxs)
    ar = math.atan2(om * p["lr"] - vy, vxs)
    g = grip(effects, x, y)
    ffy = g * p["Df"] * math.sin(p["Cf"] * math.atan(p["Bf"] * af))
    fry = g * p["Dr"] * math.sin(p["Cr"] * math.atan(p["Br"] * ar))
    drive = (p["Cm1"] - p["Cm2"] * vx) * d * p.get("charge", 1.0)
    if "traction_limit" in effects:
        drive = min(max(drive, -TRACTION), TRACTION)
    if p["friction_ellipse"]:
        total = math.hypot(drive, fry)
        if total > g * p["Dr"]:
            drive, fry = drive * g * p["Dr"] / total, fry * g * p["Dr"] / total
    frx = drive - p["Cr0"] * math.tanh(vx / 0.02) - p["Cr2"] * vx * vx
    if "aero_drag" in effects:
        frx -= 0.01 * vx * abs(vx)
    m, iz = p["m"], p["Iz"]
    c, sn = math.cos(psi), math.sin(psi)
    # the slope's pull in the body frame
    ax, ay = ((TILT_ACC * math.cos(psi - TILT_DIR), -TILT_ACC * math.sin(psi - TILT_DIR))
              if "floor_tilt" in effects else (0.0, 0.0))
    return np.array([
        vx * c - vy * sn,
        vx * sn + vy * c,
        om,
        (frx - ffy * math.sin(delta) + m * vy * om) / m + ax,
        (fry + ffy * math.cos(delta) - m * vx * om) / m + ay,
        (ffy * p["lf"] * math.cos(delta) - fry * p["lr"]) / iz - (4.0 * om if "yaw_damping" in effects else 0.0),
        (duty - dstate) / 0.2,
        min(max((steer - wheels) / SERVO_TAU, -SERVO_RATE), SERVO_RATE),
    ])


def rk4(p, effects, s, steer, duty, h):
    k1 = deriv(p, effects, s, steer, duty)
    k2 = deriv(p, effects, s + 0.5 * h * k1, steer, duty)
    k3 = deriv(p, effects, s + 0.5 * h * k2, steer, duty)
    k4 = deriv(p, effects, s + h * k3, steer, duty)
    return s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def episode(p, effects, rng, duration):
    """One drive: returns (t, state) at 1 kHz and the 50 Hz commands (t, steer, duty)."""
    h, cmd_every = 0.001, 20
    s = np.array([rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(-math.pi, math.pi),
                  0.3, 0.0, 0.0, 0.0, 0.0])
    goal = rng.uniform(-FLOOR + 0.2, FLOOR - 0.2, 2)
    duty_level, next_duty, sweep_until = 0.3, 0.0, -1.0
    states, cmds = [], []
    steer, duty = 0.0, 0.0
    sent = []  # commands on their way to the car (cmd_delay)
    applied = (0.0, 0.0)
    n = int(duration / h)
    for i in range(n):
        t = i * h
        if i % cmd_every == 0:
            x, y, psi = s[0], s[1], s[2]
            if np.hypot(goal[0] - x, goal[1] - y) < 0.4:
                goal = rng.uniform(-FLOOR + 0.2, FLOOR - 0.2, 2)
            # head home when near the edge of the floor
            if max(abs(x), abs(y)) > FLOOR:
                goal = rng.uniform(-0.5, 0.5, 2)
            if t >= next_duty:
                duty_level = rng.uniform(0.12, 0.45)
                next_duty = t + rng.uniform(0.5, 2.0)
                if rng.random() < 0.25:
                    sweep_until = t + rng.uniform(0.3, 0.8)
            err = math.atan2(goal[1] - y, goal[0] - x) - psi
            err = (err + math.pi) % (2 * math.pi) - math.pi
            steer = float(np.clip(1.5 * err, -STEER_MAX, STEER_MAX))
            if t < sweep_until:
                steer = STEER_MAX * math.copysign(1.0, math.sin(9.0 * t))
            duty = float(np.clip(duty_level + rng.normal(0, 0.02), -0.1, 1.0))
            cmds.append((t, steer, duty))
            sent.append((t + (DELAY if "cmd_delay" in effects else 0.0), steer, duty))
        while sent and sent[0][0] <= t + 1e-9:
            applied = sent.pop(0)[1:]
        states.append((t, s.copy()))
        s = rk4(p, effects, s, *applied, h)
        if not np.all(np.isfinite(s)):
            break
    return states, cmds


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("--car-seed", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--effects", default="")
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--perturb", type=float, default=0.1)
    ap.add_argument("--rate", type=float, default=120.0, help="the motion capture's frequency, Hz")
    ap.add_argument("--friction-ellipse", action="store_true",
                    help="the drive force takes the rear tire's lateral grip (default: independent)")
    a = ap.parse_args()
    if (err := option_error(a.rate, a.perturb)) is not None:
        ap.error(err)
    effects = {e for e in a.effects.split(",") if e}
    unknown = effects - set(EFFECTS)
    if unknown:
        ap.error(f"unknown effects {sorted(unknown)}; known: {', '.join(EFFECTS)}")
    p = car_params(a.car_seed, a.perturb)
    p["friction_ellipse"] = a.friction_ellipse
    rng = np.random.default_rng(a.seed)

    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(
        "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\nfloat32 acceleration\nfloat32 jerk\n",
        "ackermann_msgs/msg/AckermannDrive"))
    ts.register(get_types_from_msg("std_msgs/Header header\nackermann_msgs/AckermannDrive drive\n",
                                   "ackermann_msgs/msg/AckermannDriveStamped"))
    T = ts.types

    def stamp(t_ns):
        return T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)

    out = Path(a.out)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        pose_c = w.add_connection("/mocap/orca/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
        cmd_c = w.add_connection("/orca/cmd", "ackermann_msgs/msg/AckermannDriveStamped", typestore=ts)
        msgs = []
        t_start = 1_750_000_000 * 10**9
        for ep in range(a.episodes):
            # battery_sag: the battery's charge falls from one drive to the next
            p["charge"] = 1.0 - (SAG * ep / max(a.episodes - 1, 1) if "battery_sag" in effects else 0.0)
            states, cmds = episode(p, effects, rng, a.duration)
            t0 = t_start + ep * int((a.duration + 5.0) * 1e9)
            # poses at --rate with jitter, noise and dropouts
            dropouts = [(rng.uniform(0, a.duration), rng.uniform(0.05, 0.25)) for _ in range(2)]
            for j in range(int(a.duration * a.rate)):
                tm = j / a.rate + rng.uniform(-0.1, 0.1) / a.rate
                if tm < 0 or any(s0 <= tm < s0 + dl for s0, dl in dropouts):
                    continue
                i = min(int(round(tm * 1000)), len(states) - 1)
                s = states[i][1]
                x = s[0] + rng.normal(0, 1e-3)
                y = s[1] + rng.normal(0, 1e-3)
                yaw = s[2] + rng.normal(0, 0.004)
                t_ns = t0 + int(tm * 1e9)
                m = T["geometry_msgs/msg/PoseStamped"](
                    header=T["std_msgs/msg/Header"](stamp=stamp(t_ns), frame_id="mocap"),
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.01),
                        orientation=T["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))
                msgs.append((t_ns, pose_c, m, "geometry_msgs/msg/PoseStamped"))
            for tc, steer, duty in cmds:
                t_ns = t0 + int(tc * 1e9)
                d = T["ackermann_msgs/msg/AckermannDrive"](
                    steering_angle=np.float32(steer), steering_angle_velocity=np.float32(0),
                    speed=np.float32(0), acceleration=np.float32(duty), jerk=np.float32(0))
                m = T["ackermann_msgs/msg/AckermannDriveStamped"](
                    header=T["std_msgs/msg/Header"](stamp=stamp(t_ns), frame_id="base_link"), drive=d)
                msgs.append((t_ns, cmd_c, m, "ackermann_msgs/msg/AckermannDriveStamped"))
        msgs.sort(key=lambda e: e[0])
        for t_ns, c, m, typ in msgs:
            w.write(c, t_ns, ts.serialize_cdr(m, typ))
    print(f"{out}: {a.episodes} × {a.duration:g} s, effects {sorted(effects) or 'none'}, car seed {a.car_seed}")


if __name__ == "__main__":
    main()
