#!/usr/bin/env python3
"""Outcome of a recorded pushing run, computed from the bag alone.

    launch_scripts/push_check.py BAG_EXPORT.jsonl --goal X,Y,THETA [--obstacle CX,CY,SX,SY]
                                 [--max-pushes N] [--log PUSHER_LOG] [--json]

BAG_EXPORT.jsonl is `dynlab bag export BAG` of a bag recorded by launch_scripts/push_mppi.sh
(topics /push/block_pose, /push/action). Judged as `dynlab eval push` judges an episode (Tu & Lin's
Table I): success = the last recorded pose within 0.1 m of the goal and no collision; strict =
within 0.02 m and 0.1 rad (where mppi_pusher stops). With --max-pushes only the poses up to the
N-th push's settled pose count (the run may have gone on). A collision is the 0.1 × 0.1 m block
overlapping the obstacle box at any recorded pose (separating-axis test on the measured poses).
With --log (mppi_pusher's log, as push_mppi.sh writes it) the pushes are counted from the log
("push N from" lines): a recorder that subscribed late misses the first actions, not the log.
Exit status 0 always; the caller judges the numbers. Standard library only.
"""

import json
import math
import re
import sys

BLOCK = (0.1, 0.1)
SUCCESS_DISTANCE = 0.1
STRICT_DISTANCE = 0.02
STRICT_ANGLE = 0.1


def stamp(msg):
    s = msg["value"]["header"]["stamp"]
    return s["sec"] + 1e-9 * s["nanosec"]


def yaw(q):
    return math.atan2(2.0 * (q["w"] * q["z"] + q["x"] * q["y"]), 1.0 - 2.0 * (q["y"] ** 2 + q["z"] ** 2))


def wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def corners(cx, cy, sx, sy, th):
    c, s = math.cos(th), math.sin(th)
    return [(cx + c * dx - s * dy, cy + s * dx + c * dy)
            for dx, dy in ((sx / 2, sy / 2), (-sx / 2, sy / 2), (-sx / 2, -sy / 2), (sx / 2, -sy / 2))]


def overlap(a, b):
    """Separating-axis test of two convex quadrilaterals (corner lists)."""
    for poly in (a, b):
        for i in range(4):
            p, q = poly[i], poly[(i + 1) % 4]
            ax = (q[1] - p[1], p[0] - q[0])
            pa = [ax[0] * x + ax[1] * y for x, y in a]
            pb = [ax[0] * x + ax[1] * y for x, y in b]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


def floats(text, n, name):
    v = [float(x) for x in text.split(",")]
    if len(v) != n:
        raise SystemExit(f"push_check.py: {name} needs {n} comma-separated numbers, got {text!r}")
    return v


def logged_pushes(path):
    """The number of "push N from" lines of an mppi_pusher log."""
    n = 0
    with open(path, errors="replace") as f:
        for line in f:
            if re.search(r"push \d+ from", line):
                n += 1
    return n


def check(export_path, goal, obstacle=None, max_pushes=None, log=None):
    poses, actions = [], []
    with open(export_path) as f:
        for line in f:
            m = json.loads(line)
            if m["topic"] == "/push/block_pose":
                p = m["value"]["pose"]
                poses.append((stamp(m), p["position"]["x"], p["position"]["y"], yaw(p["orientation"])))
            elif m["topic"] == "/push/action":
                actions.append(stamp(m))
    poses.sort()
    actions.sort()
    pushes = len(actions)
    missed = 0
    if log is not None:
        pushes = max(pushes, logged_pushes(log))
        missed = pushes - len(actions)
    if max_pushes is not None and pushes > max_pushes:
        # keep the poses before the (N+1)-th push began (the first `missed` are not in the bag)
        cut = actions[max(max_pushes - missed, 0)]
        poses = [p for p in poses if p[0] < cut]
        pushes = max_pushes
    rep = {"pose_samples": len(poses), "pushes": pushes, "actions_recorded": len(actions)}
    if not poses:
        rep.update({"success": False, "strict": False, "collision": False})
        return rep
    obst = corners(*obstacle, 0.0) if obstacle else None
    collision = bool(obst) and any(overlap(corners(x, y, *BLOCK, th), obst) for _, x, y, th in poses)
    _, x, y, th = poses[-1]
    d = math.hypot(x - goal[0], y - goal[1])
    e = wrap(th - goal[2])
    rep.update({
        "sim_time_s": poses[-1][0] - poses[0][0],
        "final_pose": [x, y, th],
        "final_distance_m": d,
        "final_angle_error_rad": e,
        "collision": collision,
        "success": d < SUCCESS_DISTANCE and not collision,
        "strict": d < STRICT_DISTANCE and abs(e) < STRICT_ANGLE and not collision,
    })
    return rep


def main():
    args, opts, i = [], {}, 1
    argv = sys.argv
    while i < len(argv):
        a = argv[i]
        if a in ("--goal", "--obstacle", "--max-pushes", "--log"):
            if i + 1 >= len(argv):
                raise SystemExit(f"push_check.py: {a} needs a value")
            opts[a] = argv[i + 1]
            i += 2
            continue
        if not a.startswith("--"):
            args.append(a)
        i += 1
    if len(args) != 1 or "--goal" not in opts:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    goal = floats(opts["--goal"], 3, "--goal")
    obstacle = floats(opts["--obstacle"], 4, "--obstacle") if opts.get("--obstacle") else None
    max_pushes = int(opts["--max-pushes"]) if "--max-pushes" in opts else None
    rep = check(args[0], goal, obstacle, max_pushes, opts.get("--log"))
    if "--json" in argv:
        print(json.dumps(rep))
        return
    for k, v in rep.items():
        if isinstance(v, float):
            v = f"{v:.4f}"
        elif isinstance(v, list):
            v = ", ".join(f"{x:.3f}" for x in v)
        print(f"{k:>24}: {v}")


if __name__ == "__main__":
    main()
