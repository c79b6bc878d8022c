"""MPPI closes the loop over DDS: `sim_node` and `mppi_pusher` as separate processes, and an
independent peer (Eclipse Cyclone DDS, Python) that publishes the goal on /push/goal and watches
/push/block_pose reach it.

The model is the nominal pushing physics fitted by `dynlab train --kind physics` on a small bag
from `dynlab collect` with one pose per push (a few seconds), so the test needs no data outside
the repository.
"""
from __future__ import annotations

import math
import time


from conftest import run, start, stop
from peers.ros_types import Header, Peer, Point, Pose, PoseStamped, Quaternion, Time, wait_matched

DOMAIN = 57






def yaw_of(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), q.w * q.w + q.x * q.x - q.y * q.y - q.z * q.z)


def test_mppi_pusher_drives_the_simulated_block_to_a_goal_over_dds(tmp_path):
    explore = tmp_path / "explore.toml"
    explore.write_text("pose_rate = 0.5\n")
    bag = tmp_path / "bag"
    run("dynlab", "collect", "push", "--explore", explore, "--episodes", 60, "--seed", 3,
        "--episode-gap", 30, "--out", bag, timeout=120)
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", bag, "--kind", "physics", "--steps", 1, "--out", model,
        "--quiet", timeout=120)

    goal = (0.6, 0.05, 0.0)
    sim = start("sim_node", "--ros-args", "-p", "rate:=10.0", "-p", "pose_rate:=10.0",
                "-p", "pose_qos:=reliable", domain=DOMAIN)
    pusher = start("mppi_pusher", "--ros-args", "-p", f"model:={model}", "-p", "samples:=300",
                   "-p", "horizon:=8", "-p", "push_wait:=1.8", "-p", "stale_timeout:=2.0", domain=DOMAIN)
    peer = Peer(DOMAIN)
    try:
        from cyclonedds.core import Qos, Policy
        from cyclonedds.util import duration
        qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
        writer = peer.writer("/push/goal", PoseStamped, qos)
        reader = peer.reader("/push/block_pose", PoseStamped, qos)
        assert wait_matched(writer, timeout=30), "mppi_pusher did not subscribe to /push/goal"
        assert wait_matched(reader, timeout=30), "sim_node did not publish /push/block_pose"
        time.sleep(2.0)
        half = 0.5 * goal[2]
        writer.write(PoseStamped(
            header=Header(stamp=Time(sec=0, nanosec=0), frame_id="table"),
            pose=Pose(position=Point(x=goal[0], y=goal[1], z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)))))
        deadline = time.monotonic() + 120
        best = math.inf
        reached = False
        while time.monotonic() < deadline and not reached:
            for s in reader.take(N=1000):
                if type(s).__name__ == "InvalidSample":
                    continue
                p = s.pose.position
                d = math.hypot(p.x - goal[0], p.y - goal[1])
                dth = abs(math.remainder(yaw_of(s.pose.orientation) - goal[2], math.tau))
                best = min(best, d)
                if d < 0.03 and dth < 0.15:
                    reached = True
            time.sleep(0.02)
            assert sim.poll() is None, "sim_node exited"
            assert pusher.poll() is None, "mppi_pusher exited"
        assert reached, f"block never reached the goal (closest {best:.3f} m)"
    finally:
        err_p = stop(pusher, check=False)
        stop(sim, check=False)
    assert "push 1 from" in err_p, err_p[-2000:]
