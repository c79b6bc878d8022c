"""The controllers hold a safe command when their poses stop, and resume when they return: the
simulator (`sim_node`) is killed under a running controller and started again, and an
independent peer (Eclipse Cyclone DDS, Python) watches what the controller publishes.

- racer: zero throttle (steering held) while `/car/pose` is silent, one WARN saying so, one INFO
  when poses return, then racing again (throttle > 0) on the new simulator's clock, which starts
  again from 0;
- mppi_pusher: no push while `/push/block_pose` is silent, one WARN, one INFO, then pushing again
  from the new simulator's block although its stamps went back to 0.

The models are physics models fitted by `dynlab train` on small data (as in test_racer_dds.py and
test_mppi_dds.py). Staleness is decided on the controllers' steady clock, so the test passes
`stale_timeout` large enough (1 s) for a loaded machine; the default is 0.2 s.
"""
from __future__ import annotations

import math
import signal
import time

from conftest import REPO, run, start, stop
from peers.ros_types import (AckermannDriveStamped, Header, Peer, Point, Pose, PoseStamped,
                             PushAction, Quaternion, Time, wait_matched)

RACER_DOMAIN = 91
PUSHER_DOMAIN = 92


def collect(reader, seconds: float, until=None) -> list:
    """Samples taken from `reader` for `seconds` of wall time, or until `until(samples)`."""
    got = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        got += [s for s in reader.take(N=1000) if type(s).__name__ != "InvalidSample"]
        if until is not None and until(got):
            break
        time.sleep(0.02)
    return got


def test_racer_holds_zero_throttle_while_poses_stop_and_races_again_when_they_return(tmp_path):
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", REPO / "bags" / "car_nominal", "--kind", "physics",
        "--steps", 1, "--physics-windows", 300, "--out", model, "--quiet", timeout=180)
    track_file = REPO / "launch_scripts" / "tracks" / "default.json"
    scenario = REPO / "launch_scripts" / "scenarios" / "car_track.toml"
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration
    peer = Peer(RACER_DOMAIN)
    cmds = peer.reader("/car/cmd", AckermannDriveStamped,
                       Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000)))
    sim_args = ("sim_node", "--ros-args", "-p", "world:=car", "-p", f"scenario:={scenario}",
                "-p", "rate:=0.2")
    racer = start("racer", "--ros-args", "-p", f"model:={model}", "-p", f"track:={track_file}",
                  "-p", "use_sim_time:=true", "-p", "stale_timeout:=1.0", domain=RACER_DOMAIN)
    sim = start(*sim_args, domain=RACER_DOMAIN)
    sim2 = None
    try:
        assert wait_matched(cmds, timeout=30), "racer did not publish /car/cmd"
        racing = collect(cmds, 15, until=lambda g: sum(c.drive.acceleration > 0 for c in g) >= 10)
        assert sum(c.drive.acceleration > 0 for c in racing) >= 10, f"{len(racing)} commands before the kill"
        # the simulator dies
        sim.send_signal(signal.SIGKILL)
        sim.communicate(timeout=10)
        held = collect(cmds, 4)
        # the commands in flight at the kill may still accelerate; then only zero throttle
        assert len(held) >= 10, f"{len(held)} commands in 4 s without poses: the hold is repeated"
        tail = held[-10:]
        assert all(c.drive.acceleration == 0.0 for c in tail), [c.drive.acceleration for c in held]
        # steering held as it was, not snapped
        assert len({c.drive.steering_angle for c in tail}) == 1, [c.drive.steering_angle for c in tail]
        # a new simulator: the car at its start again, the clock from 0
        sim2 = start(*sim_args, domain=RACER_DOMAIN)
        resumed = collect(cmds, 15, until=lambda g: sum(c.drive.acceleration > 0 for c in g) >= 10)
    finally:
        if sim2 is not None:
            stop(sim2, check=False)
        err = stop(racer, check=False)
        if sim.poll() is None:
            sim.kill()
    assert sum(c.drive.acceleration > 0 for c in resumed) >= 10, \
        f"racer did not race again after the restart\n{err[-3000:]}"
    # racing again on the new clock: stamps restarted near 0 (the old run's were past 1 s)
    stamps = [c.header.stamp.sec + 1e-9 * c.header.stamp.nanosec for c in resumed if c.drive.acceleration > 0]
    assert min(stamps) < max(c.header.stamp.sec + 1e-9 * c.header.stamp.nanosec for c in racing), stamps[:5]
    assert err.count("no pose for") == 1, err[-3000:]
    assert err.count("poses back after") == 1, err[-3000:]
    assert "with their clock restarted" in err, err[-3000:]
    warn = next(line for line in err.splitlines() if "no pose for" in line)
    assert "WARN" in warn, warn
    info = next(line for line in err.splitlines() if "poses back after" in line)
    assert "INFO" in info, info


def test_pusher_sends_no_push_while_poses_stop_and_pushes_again_on_a_restarted_simulator(tmp_path):
    explore = tmp_path / "explore.toml"
    explore.write_text("pose_rate = 0.5\n")
    bag = tmp_path / "bag"
    run("dynlab", "collect", "push", "--explore", explore, "--episodes", 60, "--seed", 3,
        "--episode-gap", 30, "--out", bag, timeout=120)
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", bag, "--kind", "physics", "--steps", 1, "--out", model,
        "--quiet", timeout=120)
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration
    peer = Peer(PUSHER_DOMAIN)
    actions = peer.reader("/push/action", PushAction,
                          Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100)))
    pusher = start("mppi_pusher", "--ros-args", "-p", f"model:={model}", "-p", "samples:=300",
                   "-p", "horizon:=8", "-p", "goal:=0.6,0.05,0.0", "-p", "stale_timeout:=1.0",
                   domain=PUSHER_DOMAIN)
    # the first simulator runs fast, so its clock is far ahead when it dies ...
    sim = start("sim_node", "--ros-args", "-p", "rate:=10.0", "-p", "pose_rate:=10.0",
                "-p", "pose_qos:=reliable", domain=PUSHER_DOMAIN)
    sim2 = None
    try:
        assert wait_matched(actions, timeout=30), "mppi_pusher did not publish /push/action"
        before = collect(actions, 20, until=lambda g: len(g) >= 2)
        assert len(before) >= 2, f"{len(before)} pushes before the kill"
        time.sleep(2.0)  # a few more pushes: the old clock well ahead of the new one
        before += collect(actions, 0.1)
        sim.send_signal(signal.SIGKILL)
        sim.communicate(timeout=10)
        collect(actions, 1.5)  # a push planned from the last pose may still be on its way
        silent = collect(actions, 2.0)
        assert silent == [], f"{len(silent)} pushes without poses"
        # ... the second runs at real time from 0: a pusher waiting for a pose stamped after
        # the old run's last push would push late, from a pose stamped after it (checked below)
        sim2 = start("sim_node", "--ros-args", "-p", "rate:=1.0", "-p", "pose_rate:=10.0",
                     "-p", "pose_qos:=reliable", domain=PUSHER_DOMAIN)
        after = collect(actions, 15, until=lambda g: len(g) >= 1)
    finally:
        if sim2 is not None:
            stop(sim2, check=False)
        err = stop(pusher, check=False)
        if sim.poll() is None:
            sim.kill()
    assert len(after) >= 1, f"no push after the simulator restarted\n{err[-3000:]}"
    # planned from the new run's poses (an action is stamped with its pose), not held back until
    # the new clock passes the old run's last push
    def t(a):
        return a.header.stamp.sec + 1e-9 * a.header.stamp.nanosec
    assert t(after[0]) < max(t(a) for a in before), (t(after[0]), [t(a) for a in before])
    assert err.count("no block pose for") == 1, err[-3000:]
    assert err.count("block pose back after") == 1, err[-3000:]
    assert "with its clock restarted" in err, err[-3000:]
