#!/usr/bin/env python3
"""Laps and track excursions of a recorded race, computed from the bag alone.

    launch_scripts/race_check.py BAG_EXPORT.jsonl TRACK.json [--racer-log LOG] [--json]

BAG_EXPORT.jsonl is `dynlab bag export BAG` of a bag recorded by launch_scripts/race.sh
(topics /car/odom, /car/cmd, /car/pose). The driven line is the simulator's ground truth
(/car/odom); progress and the lateral offset come from the nearest centre-line segment, as
`dynlab_sim::Track::locate` does (half width interpolated along the segment, from the inner and
outer border points). Reports completed laps and their times, excursions (times the car's
centre left the track), the smallest border distance, top speed, the command rate and the
command delay (log time at the recorder minus the command's stamp, both simulation time).
With --racer-log (the racer's log, as race.sh writes it to OUT_BAG.racer.log) also the racer's
own counts: from its summary at shutdown ("racing summary: N solves, solve p50 X ms, p99 Y ms,
worst Z ms, B stopped at the solve budget, L late commands, M poses missed") when the log has
one — every solve counted —, otherwise from its progress lines ("N solves, last X ms (status),
worst Y ms, [B stopped at the solve budget, ]Z late commands, M poses missed", logged every 100
solves): the counts at the last such line, the worst solve, and the median and 99th percentile
of the sampled solve times (every 100th solve, so p99 of a short run is the largest sample).
Exit status 0 always; the caller judges the numbers. Standard library only.
"""

import json
import math
import re
import sys

PROGRESS = re.compile(
    r"(\d+) solves, last ([\d.]+) ms \([^)]*\), worst ([\d.]+) ms, "
    r"(?:(\d+) stopped at the solve budget, )?(\d+) late commands, (\d+) poses missed"
)
SUMMARY = re.compile(
    r"racing summary: (\d+) solves, solve p50 ([\d.]+) ms, p99 ([\d.]+) ms, worst ([\d.]+) ms, "
    r"(\d+) stopped at the solve budget, (\d+) late commands, (\d+) poses missed"
)


def load_track(path):
    with open(path) as f:
        t = json.load(f)
    n = len(t["X"])
    centre = [(t["X"][i], t["Y"][i]) for i in range(n)]
    hw = [0.5 * math.hypot(t["X_o"][i] - t["X_i"][i], t["Y_o"][i] - t["Y_i"][i]) for i in range(n)]
    arc = [0.0]
    for i in range(n):
        a, b = centre[i], centre[(i + 1) % n]
        arc.append(arc[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
    return centre, hw, arc


def locate(track, p):
    """(arc, lateral, half_width) of p on the nearest centre-line segment."""
    centre, hw, arc = track
    n = len(centre)
    best = None
    for i in range(n):
        a, b = centre[i], centre[(i + 1) % n]
        d = (b[0] - a[0], b[1] - a[1])
        l2 = d[0] * d[0] + d[1] * d[1]
        t = 0.0 if l2 <= 0 else max(0.0, min(1.0, ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / l2))
        q = (a[0] + t * d[0], a[1] + t * d[1])
        dist2 = (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2
        if best is None or dist2 < best[0]:
            best = (dist2, i, t)
    _, i, t = best
    a, b = centre[i], centre[(i + 1) % n]
    seg = max(math.hypot(b[0] - a[0], b[1] - a[1]), 1e-12)
    tan = ((b[0] - a[0]) / seg, (b[1] - a[1]) / seg)
    lateral = (p[0] - a[0]) * -tan[1] + (p[1] - a[1]) * tan[0]
    half = hw[i] + t * (hw[(i + 1) % n] - hw[i])
    return arc[i] + t * seg, lateral, half


def stamp(msg):
    s = msg["value"]["header"]["stamp"]
    return s["sec"] + 1e-9 * s["nanosec"]


def check(export_path, track_path):
    track = load_track(track_path)
    length = track[2][-1]
    odom, cmds, poses = [], [], []
    with open(export_path) as f:
        for line in f:
            m = json.loads(line)
            if m["topic"] == "/car/odom":
                odom.append(m)
            elif m["topic"] == "/car/cmd":
                cmds.append(m)
            elif m["topic"] == "/car/pose":
                poses.append(m)
    odom.sort(key=stamp)
    rep = {
        "odom_samples": len(odom),
        "pose_samples": len(poses),
        "commands": len(cmds),
        "track_length_m": length,
    }
    travelled, last_arc, laps, last_lap_t = 0.0, None, [], None
    excursions, off, time_off, min_border, top_speed = 0, False, 0.0, math.inf, 0.0
    t_prev = None
    for m in odom:
        t = stamp(m)
        v = m["value"]
        p = v["pose"]["pose"]["position"]
        tw = v["twist"]["twist"]["linear"]
        top_speed = max(top_speed, math.hypot(tw["x"], tw["y"]))
        a, lat, half = locate(track, (p["x"], p["y"]))
        if last_arc is None:
            last_lap_t = t
        else:
            d = a - last_arc
            if d > 0.5 * length:
                d -= length
            elif d < -0.5 * length:
                d += length
            travelled += d
        last_arc = a
        border = half - abs(lat)
        min_border = min(min_border, border)
        if border < 0:
            if not off:
                excursions += 1
            if t_prev is not None:
                time_off += t - t_prev
        off = border < 0
        if travelled >= length * (len(laps) + 1):
            laps.append(t - last_lap_t)
            last_lap_t = t
        t_prev = t
    sim_time = stamp(odom[-1]) - stamp(odom[0]) if odom else 0.0
    rep.update(
        {
            "sim_time_s": sim_time,
            "laps": len(laps),
            "lap_times_s": laps,
            "distance_m": travelled,
            "excursions": excursions,
            "time_off_track_s": time_off,
            "min_border_distance_m": min_border,
            "top_speed_mps": top_speed,
        }
    )
    if cmds:
        ts = sorted(stamp(c) for c in cmds)
        delays = sorted(c["log_time_ns"] * 1e-9 - stamp(c) for c in cmds)
        span = ts[-1] - ts[0]
        rep["command_rate_hz"] = (len(ts) - 1) / span if span > 0 else 0.0
        rep["command_delay_p50_s"] = delays[len(delays) // 2]
        rep["command_delay_max_s"] = delays[-1]
        rep["first_command_s"] = ts[0]
    return rep


def racer_log(path):
    """Solve and late-command counts from the racer's summary or progress lines (empty when none)."""
    rows, summary = [], None
    with open(path, errors="replace") as f:
        for line in f:
            m = SUMMARY.search(line)
            if m:
                summary = m
                continue
            m = PROGRESS.search(line)
            if m:
                rows.append((int(m[1]), float(m[2]), float(m[3]), int(m[4] or 0), int(m[5]), int(m[6])))
    if summary is not None:
        n = int(summary[1])
        return {
            "solves_logged": n,
            "late_commands": int(summary[6]),
            "late_fraction": int(summary[6]) / n if n else 0.0,
            "poses_missed": int(summary[7]),
            "solve_worst_ms": float(summary[4]),
            "solve_p50_ms": float(summary[2]),
            "solve_p99_ms": float(summary[3]),
            "budget_stops": int(summary[5]),
            "solve_samples": n,
        }
    if not rows:
        return {"solves_logged": 0}
    last = sorted(r[1] for r in rows)
    return {
        "solves_logged": rows[-1][0],
        "late_commands": rows[-1][4],
        "late_fraction": rows[-1][4] / rows[-1][0],
        "poses_missed": rows[-1][5],
        "solve_worst_ms": rows[-1][2],
        "solve_sampled_p50_ms": last[len(last) // 2],
        "solve_sampled_p99_ms": last[min(len(last) - 1, int(0.99 * len(last)))],
        "budget_stops": rows[-1][3],
        "solve_samples": len(last),
    }


def main():
    argv = sys.argv[1:]
    log = None
    if "--racer-log" in argv:
        i = argv.index("--racer-log")
        if i + 1 >= len(argv):
            print("race_check.py: --racer-log needs a file", file=sys.stderr)
            sys.exit(2)
        log = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    args = [a for a in argv if not a.startswith("--")]
    if len(args) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    rep = check(args[0], args[1])
    if log is not None:
        try:
            rep.update(racer_log(log))
        except OSError as e:
            print(f"race_check.py: cannot read the racer log {log}: {e.strerror}; race.sh writes it "
                  "beside the bag as OUT_BAG.racer.log", file=sys.stderr)
            sys.exit(2)
    if "--json" in sys.argv:
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
