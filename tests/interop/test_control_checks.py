"""The judges of the control demo (launch_scripts/control.sh): push_check.py on a recorded pushing
run and race_check.py's reading of the racer's log, on hand-made bag exports and logs."""
from __future__ import annotations

import json
import math
import sys

from conftest import REPO

sys.path.insert(0, str(REPO / "launch_scripts"))
from push_check import check as push_check  # noqa: E402
from race_check import racer_log  # noqa: E402


def pose_line(t: float, x: float, y: float, th: float) -> str:
    return json.dumps({"topic": "/push/block_pose", "value": {
        "header": {"stamp": {"sec": int(t), "nanosec": int(round((t % 1) * 1e9))}},
        "pose": {"position": {"x": x, "y": y, "z": 0.0},
                 "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(th / 2), "w": math.cos(th / 2)}}}})


def action_line(t: float) -> str:
    return json.dumps({"topic": "/push/action", "value": {
        "header": {"stamp": {"sec": int(t), "nanosec": int(round((t % 1) * 1e9))}},
        "location": 0.0, "angle": 0.0, "length": 0.5}})


def write(path, lines):
    path.write_text("\n".join(lines) + "\n")
    return path


GOAL = (0.8, -0.1, 0.0)
OBSTACLE = (0.6, 0.2, 0.1, 0.5)


def test_a_run_ending_at_the_goal_succeeds_strictly(tmp_path):
    # three pushes from the obstacle scene's start to the goal, under the box (x 0.55…0.65 from
    # y = −0.05 up)
    path = [(0.4, 0.0, -0.6), (0.48, -0.14, -0.3), (0.68, -0.17, -0.05), (0.79, -0.1, 0.02)]
    lines = []
    for i, (x, y, th) in enumerate(path):
        lines.append(pose_line(2.0 * i, x, y, th))
        if i < 3:
            lines.append(action_line(2.0 * i))
    rep = push_check(write(tmp_path / "run.jsonl", lines), GOAL, OBSTACLE)
    assert rep["pushes"] == 3
    assert not rep["collision"]
    assert rep["success"] and rep["strict"]
    assert abs(rep["final_distance_m"] - 0.01) < 1e-9


def test_touching_the_obstacle_is_a_collision_and_no_success(tmp_path):
    # the block's corner reaches into the box (its left face at x = 0.55, bottom at y = −0.05)
    lines = [pose_line(0.0, 0.4, 0.0, 0.0), action_line(0.0), pose_line(2.0, 0.52, -0.07, 0.3),
             action_line(2.0), pose_line(4.0, 0.79, -0.1, 0.0)]
    rep = push_check(write(tmp_path / "run.jsonl", lines), GOAL, OBSTACLE)
    assert rep["collision"]
    assert not rep["success"] and not rep["strict"]
    # the same run in free space: no obstacle, no collision
    rep = push_check(tmp_path / "run.jsonl", GOAL, None)
    assert not rep["collision"] and rep["success"]


def test_max_pushes_judges_the_pose_before_the_next_push_and_the_log_counts_missed_actions(tmp_path):
    lines = []
    xs = [0.4, 0.5, 0.6, 0.7, 0.8]
    for i, x in enumerate(xs):
        lines.append(pose_line(2.0 * i, x, -0.1, 0.0))
        if i < 4:
            lines.append(action_line(2.0 * i + 0.1))
    export = write(tmp_path / "run.jsonl", lines)
    rep = push_check(export, GOAL, None, max_pushes=2)
    assert rep["pushes"] == 2
    assert abs(rep["final_pose"][0] - 0.6) < 1e-9
    assert not rep["strict"]
    # the recorder missed the first action; the pusher's log has all four
    log = write(tmp_path / "pusher.log",
                [f"\x1b[32m INFO\x1b[0m mppi_pusher: push {i} from (0.4, 0.0, 0.0): p = 0.1" for i in range(1, 5)])
    export2 = write(tmp_path / "run2.jsonl", [ln for ln in lines if ln != action_line(0.1)])
    rep = push_check(export2, GOAL, None, log=str(log))
    assert rep["pushes"] == 4 and rep["actions_recorded"] == 3
    rep = push_check(export2, GOAL, None, max_pushes=2, log=str(log))
    assert rep["pushes"] == 2
    # the 3rd push (the 2nd recorded action, at 4.1 s) cuts: the last pose kept is at 4 s
    assert abs(rep["final_pose"][0] - 0.6) < 1e-9


def test_the_racer_log_gives_late_commands_and_solve_times(tmp_path):
    lines = ["\x1b[2m2026-11-25T12:45:33Z\x1b[0m \x1b[32m INFO\x1b[0m racer: racing default.json"]
    for n, last, worst, late in [(100, 7.5, 59.0, 1), (200, 8.0, 59.0, 1), (300, 21.0, 61.0, 4)]:
        lines.append(f"\x1b[32m INFO\x1b[0m \x1b[2mracer\x1b[0m: {n} solves, last {last} ms (max-iterations), "
                     f"worst {worst} ms, {late} late commands, 0 poses missed")
    rep = racer_log(write(tmp_path / "racer.log", lines))
    assert rep["solves_logged"] == 300
    assert rep["late_commands"] == 4
    assert rep["solve_worst_ms"] == 61.0
    assert rep["solve_sampled_p50_ms"] == 8.0
    assert rep["solve_samples"] == 3
    assert racer_log(write(tmp_path / "empty.log", ["nothing"])) == {"solves_logged": 0}
    # the progress lines of a racer with a solve budget
    lines.append("\x1b[32m INFO\x1b[0m racer: 400 solves, last 9.0 ms (deadline), worst 62.0 ms, "
                 "3 stopped at the solve budget, 5 late commands, 2 poses missed")
    rep = racer_log(write(tmp_path / "budget.log", lines))
    assert (rep["solves_logged"], rep["late_commands"], rep["budget_stops"]) == (400, 5, 3)
    assert rep["poses_missed"] == 2
    # the summary at shutdown wins over the sampled progress lines
    lines.append("\x1b[32m INFO\x1b[0m racer: racing summary: 457 solves, solve p50 4.2 ms, p99 11.5 ms, "
                 "worst 62.0 ms, 3 stopped at the solve budget, 6 late commands, 2 poses missed")
    rep = racer_log(write(tmp_path / "summary.log", lines))
    assert rep["solves_logged"] == 457 and rep["late_commands"] == 6
    assert (rep["solve_p50_ms"], rep["solve_p99_ms"], rep["solve_worst_ms"]) == (4.2, 11.5, 62.0)
    assert "solve_sampled_p50_ms" not in rep


def test_push_mppi_sh_runs_one_judged_episode_over_dds(tmp_path):
    """push_mppi.sh with MAX_PUSHES: sim_node, mppi_pusher and recorder over DDS, stopped after
    the pushes, the bag judged (one JSON line)."""
    import os
    import subprocess

    from conftest import bin_dir, run

    explore = tmp_path / "explore.toml"
    explore.write_text("pose_rate = 0.5\n")
    bag = tmp_path / "bag"
    run("dynlab", "collect", "push", "--explore", explore, "--episodes", 60, "--seed", 3,
        "--episode-gap", 30, "--out", bag, timeout=120)
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", bag, "--kind", "physics", "--out", model, "--quiet", timeout=120)
    out = tmp_path / "run"
    env = dict(os.environ, DYNLAB_BIN_DIR=str(bin_dir()), ROS_DOMAIN_ID="61", MAX_PUSHES="3",
               RATE="10", TIMEOUT="90", CHECK_ARGS="--json")
    proc = subprocess.run(["bash", str(REPO / "launch_scripts" / "push_mppi.sh"), str(model), "free", str(out)],
                          env=env, capture_output=True, text=True, timeout=150)
    assert proc.returncode == 0, proc.stderr
    rep = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rep["pushes"] == 3, rep
    assert rep["pose_samples"] > 0
    # the free scene starts 0.4 m from the goal: three pushes bring the block closer
    assert rep["final_distance_m"] < 0.38, rep
    assert (tmp_path / "run.pusher.log").read_text().count("push 3 from") == 1
