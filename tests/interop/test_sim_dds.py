"""The simulator over DDS and headless: sim_node, explorer, dynlab collect, launch scripts.

- A run over DDS gives the same poses as a headless run with the same actions: an independent
  peer (Eclipse Cyclone DDS, Python) drives `sim_node` in lock-step mode with a fixed action
  sequence, and every pose it receives must equal, bit for bit, the pose with the same stamp in a
  bag from `dynlab collect --actions` (the headless replay), read with `rosbags`.
- `dynlab collect`: byte-identical bags for the same seed on 1 and 2 threads, topics and counts
  as documented read back with `rosbags` and `mcap-ros2-support`, errors naming the bad key of a
  scenario file.
- `launch_scripts/record_sim.sh` leaves a bag with the simulator's topics.

Each DDS test uses its own domain and topic names, waits on matched endpoints with bounded
timeouts, and stops our processes with SIGINT.
"""
from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess
import time
import uuid

import pytest
from mcap_ros2.reader import read_ros2_messages
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.typesys import Stores, get_typestore

from conftest import REPO, binary, run, start, stop
from peers.ros_types import (RELIABLE, RELIABLE_KEEP_ALL, AckermannDrive, AckermannDriveStamped, Peer, PoseStamped,
                             PushAction, take_until, wait_matched)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def unique(prefix: str) -> str:
    return f"{prefix}_{uuid.uuid4().hex[:8]}"






def bag_poses(bag: pathlib.Path, topic: str) -> dict[int, tuple]:
    """Stamp (ns) → (x, y, z, qx, qy, qz, qw, frame) of every PoseStamped, read with rosbags."""
    out = {}
    with Rosbag2Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        assert conns, f"{topic} not in {[c.topic for c in reader.connections]}"
        for conn, _, raw in reader.messages(connections=conns):
            m = TYPESTORE.deserialize_cdr(raw, conn.msgtype)
            out[m.header.stamp.sec * 10**9 + m.header.stamp.nanosec] = pose_fields(m)
    return out


def pose_fields(m) -> tuple:
    p, q = m.pose.position, m.pose.orientation
    return (p.x, p.y, p.z, q.x, q.y, q.z, q.w, m.header.frame_id)


def compare_with_replay(received: list, replay: dict[int, tuple]):
    got = {}
    for m in received:
        t = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        assert t not in got, f"stamp {t} received twice"
        got[t] = pose_fields(m)
    assert set(got) <= set(replay), f"stamps not in the headless run: {sorted(set(got) - set(replay))[:5]}"
    # the pose at t = 0 is published at start-up, possibly before the peer matched
    missing = sorted(set(replay) - set(got) - {0})
    assert not missing, f"{len(missing)} poses of the headless run never arrived, first {missing[:5]}"
    for t, fields in got.items():
        assert fields == replay[t], f"pose at {t} ns differs: DDS {fields} vs headless {replay[t]}"


def write_params(path: pathlib.Path, params: dict):
    lines = ["/**:", "  ros__parameters:"]
    for k, v in params.items():
        lines.append(f"    {k}: {json.dumps(v)}")
    path.write_text("\n".join(lines) + "\n")


NOISY_PUSH = """
name = "dds_test"
start = [0.4, 0.0, 0.6283185307179586]
[effects.com_offset]
offset = [0.01, 0.005]
[noise]
position_std = 0.0005
yaw_std = 0.002
"""

PUSH_ACTIONS = [(0.0, 0.0, 0.5), (0.7, -0.4, 1.0), (-0.9, 0.8, 0.3), (1.4, 0.2, 0.6), (0.2, -1.2, 0.0),
                (-0.3, 0.1, 0.9)]


def test_sim_node_lockstep_pushes_over_dds_equal_the_headless_replay(tmp_path):
    """Cyclone sends six pushes (one out of range: clamped) and a NaN one (ignored) to sim_node
    in lock-step mode, with topics remapped and parameters from a YAML file; every block pose
    received equals the headless replay's pose with the same stamp."""
    domain = 41
    scenario = tmp_path / "push.toml"
    scenario.write_text(NOISY_PUSH)
    pose_topic, action_topic = unique("/dds_push/pose"), unique("/dds_push/action")
    params = tmp_path / "params.yaml"
    write_params(params, {"world": "push", "mode": "lockstep", "scenario": str(scenario),
                          "pose_qos": "reliable", "seed": 7, "pose_rate": 50.0})
    node = start("sim_node", "--ros-args", "--params-file", params, "-r", f"/push/block_pose:={pose_topic}",
                 "-r", f"/push/action:={action_topic}", domain=domain)
    try:
        peer = Peer(domain)
        poses = peer.reader(pose_topic, PoseStamped, qos=RELIABLE_KEEP_ALL)
        actions = peer.writer(action_topic, PushAction, qos=RELIABLE)
        assert wait_matched(actions) and wait_matched(poses), "sim_node never matched the peer"
        time.sleep(2.0)  # let sim_node's writer see our reader too (see the car test)
        for i, (p, phi, length) in enumerate(PUSH_ACTIONS):
            actions.write(PushAction(location=p, angle=phi, length=length))
            if i == 2:
                actions.write(PushAction(location=0.1, angle=math.nan, length=0.5))
        # headless: the same actions replayed by dynlab collect (lock-step semantics, same seed)
        lines = tmp_path / "actions.jsonl"
        lines.write_text("".join(json.dumps({"location": p, "angle": a, "length": l}) + "\n"
                                 for p, a, l in PUSH_ACTIONS))
        bag = tmp_path / "replay"
        out = run("dynlab", "collect", "push", "--scenario", scenario, "--actions", lines, "--seed", 7,
                  "--pose-rate", 50, "--out", bag)
        assert "location = 1.4: outside [-1, 1], clamped" in out.stderr
        replay = bag_poses(bag, "/push/block_pose")
        received = take_until(poses, len(replay), timeout=30, idle=3.0)
    finally:
        err = stop(node)
    assert "location = 1.4: outside [-1, 1], clamped" in err, err
    assert "angle = NaN" in err and "ignored" in err, err
    assert all(f[7] == "table" for f in replay.values())
    assert len(replay) > 6 * 20, len(replay)  # 6 pushes of ≥ 0.4 s at 50 Hz
    compare_with_replay(received, replay)
    # the clamped push moved the block: its poses are not all equal
    assert len({f[:2] for f in replay.values()}) > 50


CAR_COMMANDS = [(0.25 * math.sin(0.1 * i), 0.15 + 0.5 * (i % 40 > 25)) for i in range(120)]


def test_sim_node_lockstep_car_over_dds_equals_the_headless_replay(tmp_path):
    """120 commands of 20 ms each from Cyclone; every /car/pose equals the headless replay's."""
    domain = 42
    scenario = tmp_path / "car.toml"
    scenario.write_text("[effects.aero_drag]\nc = 0.01\n[noise]\nposition_std = 0.001\n")
    pose_topic, cmd_topic = unique("/dds_car/pose"), unique("/dds_car/cmd")
    node = start("sim_node", "--ros-args", "-p", "world:=car", "-p", "mode:=lockstep", "-p",
                 f"scenario:={scenario}", "-p", "pose_qos:=reliable", "-p", "seed:=3", "-r",
                 f"/car/pose:={pose_topic}", "-r", f"/car/cmd:={cmd_topic}", domain=domain)
    try:
        peer = Peer(domain)
        poses = peer.reader(pose_topic, PoseStamped, qos=RELIABLE_KEEP_ALL)
        cmds = peer.writer(cmd_topic, AckermannDriveStamped, qos=RELIABLE_KEEP_ALL)
        assert wait_matched(cmds) and wait_matched(poses), "sim_node never matched the peer"
        # Our reader seeing sim_node's writer does not mean that writer has seen our reader yet
        # (discovery is not symmetric); a volatile writer drops what it publishes before that.
        time.sleep(2.0)
        for steer, throttle in CAR_COMMANDS:
            cmds.write(AckermannDriveStamped(drive=AckermannDrive(steering_angle=steer, acceleration=throttle)))
        lines = tmp_path / "commands.jsonl"
        lines.write_text("".join(json.dumps({"steering": s, "throttle": t}) + "\n" for s, t in CAR_COMMANDS))
        bag = tmp_path / "replay"
        run("dynlab", "collect", "car", "--scenario", scenario, "--actions", lines, "--seed", 3, "--out", bag)
        replay = bag_poses(bag, "/car/pose")
        received = take_until(poses, len(replay), timeout=30, idle=3.0)
    finally:
        stop(node)
    assert len(replay) == 1 + 2 * len(CAR_COMMANDS)  # 100 Hz poses, 20 ms per command
    assert all(f[7] == "world" for f in replay.values())
    compare_with_replay(received, replay)
    # the car drove: more than 0.3 m in 2.4 s
    first, last = replay[min(replay)], replay[max(replay)]
    assert math.hypot(last[0] - first[0], last[1] - first[1]) > 0.3


def collect(tmp_path: pathlib.Path, name: str, *args) -> tuple[pathlib.Path, str]:
    bag = tmp_path / name
    proc = run("dynlab", "collect", *args, "--out", bag)
    return bag, proc.stderr


def test_collect_is_byte_identical_for_a_seed_on_any_thread_count(tmp_path):
    scen = REPO / "launch_scripts" / "scenarios"
    for world, scenario, n in [("push", "push_friction_patch.toml", 6), ("car", "car_aero_drag.toml", 3)]:
        a, _ = collect(tmp_path / "t1", world, world, "--scenario", scen / scenario, "--episodes", n,
                       "--seed", 11, "--threads", 1)
        b, _ = collect(tmp_path / "t2", world, world, "--scenario", scen / scenario, "--episodes", n,
                       "--seed", 11, "--threads", 2)
        c, _ = collect(tmp_path / "s12", world, world, "--scenario", scen / scenario, "--episodes", n,
                       "--seed", 12, "--threads", 2)
        files = sorted(p.name for p in a.iterdir())
        assert files == sorted([f"{world}_0.mcap", "metadata.yaml"]), files
        for f in files:
            assert (a / f).read_bytes() == (b / f).read_bytes(), f"{world}: {f} differs between 1 and 2 threads"
        assert (a / f"{world}_0.mcap").read_bytes() != (c / f"{world}_0.mcap").read_bytes()


def test_collected_bags_read_back_with_independent_readers(tmp_path):
    push, out = collect(tmp_path, "push", "push", "--episodes", 3, "--seed", 5, "--clock")
    assert "collected 3 episodes" in out and "MB" in out and "/push/action" in out, out
    with Rosbag2Reader(push) as r:
        counts = {c.topic: (c.msgtype, c.msgcount) for c in r.connections}
        qos = {c.topic: c.ext.offered_qos_profiles for c in r.connections}
    # 10 pushes, 2 s apart, poses at 10 Hz: 201 poses and 10 actions per episode (unless the block
    # left the table); /clock at every pose
    n_poses = counts["/push/block_pose"][1]
    assert counts["/push/block_pose"][0] == "geometry_msgs/msg/PoseStamped"
    assert counts["/push/action"] == ("dynlab_msgs/msg/PushAction", 30)
    assert n_poses == 3 * 201
    assert counts["/clock"] == ("rosgraph_msgs/msg/Clock", n_poses)
    assert qos["/push/block_pose"][0].reliability.name.lower().endswith("best_effort")
    assert qos["/push/action"][0].reliability.name.lower().endswith("reliable")
    # the PushAction definition in the bag is enough for mcap-ros2-support to decode it
    mcap = next(push.glob("*.mcap"))
    acts = [m.ros_msg for m in read_ros2_messages(str(mcap), topics=["/push/action"])]
    assert len(acts) == 30
    assert all(-1 <= a.location <= 1 and -math.pi / 2 <= a.angle <= math.pi / 2 and 0 <= a.length <= 1
               for a in acts)
    assert all(a.header.frame_id == "table" for a in acts)
    # episodes are separated by a one-second gap on one time line starting at 0
    stamps = sorted(bag_poses(push, "/push/block_pose"))
    gaps = [b - a for a, b in zip(stamps, stamps[1:]) if b - a > 200_000_000]
    assert stamps[0] == 0 and len(gaps) == 2 and all(g == 1_000_000_000 for g in gaps)

    car, _ = collect(tmp_path, "car", "car", "--episodes", 2, "--seed", 5)
    with Rosbag2Reader(car) as r:
        counts = {c.topic: (c.msgtype, c.msgcount) for c in r.connections}
    assert counts == {"/car/pose": ("geometry_msgs/msg/PoseStamped", 2 * 3001),
                      "/car/cmd": ("ackermann_msgs/msg/AckermannDriveStamped", 2 * 1500),
                      "/car/odom": ("nav_msgs/msg/Odometry", 2 * 3001)}
    odom = [m.ros_msg for m in read_ros2_messages(str(next(car.glob("*.mcap"))), topics=["/car/odom"])]
    assert odom[0].child_frame_id == "car" and odom[0].header.frame_id == "world"
    # the explorer drives: the fastest ground-truth speed is well above walking pace
    assert max(math.hypot(o.twist.twist.linear.x, o.twist.twist.linear.y) for o in odom) > 1.0


@pytest.mark.parametrize("text,key", [
    ("[effects.friction_patch]\nmuu = 0.3\n", "effects.friction_patch.muu"),
    ("[effects.friction_patch]\nmu = -0.2\n", "effects.friction_patch.mu"),
    ("[block]\nsize = [0.1]\n", "block.size"),
])
def test_collect_names_the_bad_key_of_a_scenario_file(tmp_path, text, key):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(text)
    proc = run("dynlab", "collect", "push", "--scenario", scenario, "--episodes", 1, "--out",
               tmp_path / "bag", check=False)
    assert proc.returncode != 0
    assert key in proc.stderr, proc.stderr
    assert not (tmp_path / "bag").exists()


def test_record_sim_script_leaves_a_bag_recorded_over_dds(tmp_path):
    """sim_node (5× real time), explorer and recorder as separate processes over DDS."""
    bag = tmp_path / "car_dds"
    env = dict(os.environ, DYNLAB_BIN_DIR=str(binary("sim_node").parent), ROS_DOMAIN_ID="43")
    proc = subprocess.run(["bash", str(REPO / "launch_scripts" / "record_sim.sh"), "car", str(bag), "4",
                           "-p", "rate:=5.0"], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    with Rosbag2Reader(bag) as r:
        counts = {c.topic: (c.msgtype, c.msgcount) for c in r.connections}
    assert counts["/car/pose"][0] == "geometry_msgs/msg/PoseStamped"
    assert counts["/car/cmd"][0] == "ackermann_msgs/msg/AckermannDriveStamped"
    assert counts["/car/odom"][0] == "nav_msgs/msg/Odometry"
    # 4 s of wall time at 5× and 100 Hz is ≈ 2000 poses; discovery takes some of it (the bounds
    # are loose so that a loaded machine does not fail the test)
    assert counts["/car/pose"][1] > 100, counts
    assert counts["/car/cmd"][1] > 20, counts
    # header stamps are simulation time, one pose per 10 ms of it
    poses = sorted(bag_poses(bag, "/car/pose"))
    assert all(t % 10_000_000 == 0 for t in poses)
    assert (poses[-1] - poses[0]) > 1e9


@pytest.mark.parametrize("params,needle", [
    (["-p", "world:=boat"], "parameter world: `boat` is not a world"),
    (["-p", "pose_rate:=300.0"], "parameter pose_rate"),
    (["-p", "mode:=fast"], "parameter mode"),
    (["-p", "world:=car", "-p", "scenario:=/nonexistent/car.toml"], "/nonexistent/car.toml"),
])
def test_sim_node_refuses_bad_parameters_naming_them(params, needle):
    proc = subprocess.run([str(binary("sim_node")), "--ros-args", *params], capture_output=True, text=True,
                          timeout=60, env=dict(os.environ, ROS_DOMAIN_ID="44"))
    assert proc.returncode != 0
    assert needle in proc.stderr, proc.stderr
