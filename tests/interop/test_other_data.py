"""Other people's data: a bag written by `rosbags` (not by `dynlab collect`) the way a real robot's
`ros2 bag record` might look — a 240 Hz motion capture with jittered stamps under another topic
name, commands at 37 Hz not aligned with the poses, extra topics, and a 1 s hole in the poses —
goes through `dynlab compare` and `dynlab eval-model` with a model trained on the bundled 100 Hz
bag. Missing topics get a message naming the topic and the topics that are there.
"""
import json
import math

import numpy as np
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from conftest import run

# the ROS 2 definitions of ackermann_msgs (not in rosbags' Jazzy store), from the ROS package
ACKERMANN_DRIVE = """float32 steering_angle
float32 steering_angle_velocity
float32 speed
float32 acceleration
float32 jerk
"""
ACKERMANN_DRIVE_STAMPED = """std_msgs/Header header
ackermann_msgs/AckermannDrive drive
"""


def store():
    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(ACKERMANN_DRIVE, "ackermann_msgs/msg/AckermannDrive"))
    ts.register(get_types_from_msg(ACKERMANN_DRIVE_STAMPED, "ackermann_msgs/msg/AckermannDriveStamped"))
    return ts


def stamp(ts, t_ns):
    return ts.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def write_mocap_bag(path, with_cmd=True):
    """A car on a circle of radius 1.5 m at ≈ 1.2 m/s, seen at 240 Hz, for 12 s, no poses in
    [5 s, 6 s)."""
    ts = store()
    T = ts.types
    rng = np.random.default_rng(3)
    with Rosbag2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        pose_c = w.add_connection("/mocap/rc_car/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
        cmd_c = w.add_connection("/rc_car/ackermann_cmd", "ackermann_msgs/msg/AckermannDriveStamped",
                                 typestore=ts) if with_cmd else None
        extra_c = w.add_connection("/rosout_text", "std_msgs/msg/String", typestore=ts)
        twist_c = w.add_connection("/imu/twist", "geometry_msgs/msg/Twist", typestore=ts)
        msgs = []
        t0 = 1_700_000_000 * 10**9
        n = int(12 * 240)
        for i in range(n):
            t = t0 + int(i * 1e9 / 240 + rng.uniform(-0.15, 0.15) * 1e9 / 240)
            if 5e9 <= t - t0 < 6e9:
                continue
            a = (t - t0) * 1e-9 * 0.8
            x, y, yaw = 1.5 * math.cos(a), 1.5 * math.sin(a), a + math.pi / 2
            x += rng.normal(0, 5e-4)
            y += rng.normal(0, 5e-4)
            q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
            m = T["geometry_msgs/msg/PoseStamped"](
                header=T["std_msgs/msg/Header"](stamp=stamp(ts, t), frame_id="mocap"),
                pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.02),
                                                  orientation=q))
            msgs.append((t, pose_c, m, "geometry_msgs/msg/PoseStamped"))
        if with_cmd:
            for j in range(int(12 * 37)):
                t = t0 + int(j * 1e9 / 37) + 1_234_567
                d = T["ackermann_msgs/msg/AckermannDrive"](
                    steering_angle=np.float32(0.2 + 0.05 * math.sin(j / 10)), steering_angle_velocity=np.float32(0),
                    speed=np.float32(0), acceleration=np.float32(0.4 + 0.1 * math.cos(j / 7)), jerk=np.float32(0))
                m = T["ackermann_msgs/msg/AckermannDriveStamped"](
                    header=T["std_msgs/msg/Header"](stamp=stamp(ts, t), frame_id="base_link"), drive=d)
                msgs.append((t, cmd_c, m, "ackermann_msgs/msg/AckermannDriveStamped"))
        for j in range(24):
            t = t0 + j * 500_000_000
            msgs.append((t, extra_c, T["std_msgs/msg/String"](data=f"hello {j}"), "std_msgs/msg/String"))
            z = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
            msgs.append((t, twist_c, T["geometry_msgs/msg/Twist"](linear=z, angular=z), "geometry_msgs/msg/Twist"))
        msgs.sort(key=lambda e: e[0])
        for t, c, m, typ in msgs:
            w.write(c, t + 2_000_000, ts.serialize_cdr(m, typ))
    return path


def test_compare_and_eval_on_a_foreign_mocap_bag(car_nominal_model, tmp_path):
    bag = write_mocap_bag(tmp_path / "robot")
    topics = ["--pose-topic", "/mocap/rc_car/pose", "--cmd-topic", "/rc_car/ackermann_cmd"]
    out = tmp_path / "report"
    proc = run("dynlab", "compare", "--model", car_nominal_model, "--bag", bag, "--out", out, *topics, timeout=120)
    text = proc.stdout
    assert "resampled to the model's step" in text, text
    assert "1 gap(s)" in text, text
    report = json.loads((out / "report.json").read_text())
    assert report["schema"] == "dynlab.compare/1"
    assert report["data"]["trajectories"] == 2  # split at the hole
    assert abs(report["data"]["dt_s"] - 0.01) < 1e-6  # resampled to the model's 100 Hz
    notes = " ".join(report["data"]["notes"][0])
    assert "zero-order hold" in notes and "gap" in notes
    ev = report["model"]["eval"]
    assert ev["windows"] > 900
    assert all(math.isfinite(d["rmse"]) for d in ev["k_step"])
    # a circle at constant speed: the physics model's one-step position error is small
    assert ev["one_step"][0]["rmse"] < 0.01
    worst = report["model"]["worst"]
    assert worst and all(0 <= w["start_s"] <= 12.5 for w in worst)
    assert (out / "index.html").read_text().count("<svg") >= 5
    # eval-model reads it as well (at the bag's own rate: it says nothing about resampling)
    ev2 = json.loads(run("dynlab", "eval-model", "--model", car_nominal_model, "--bag", bag, *topics, "--json").stdout)
    assert ev2["windows"] > 0


def test_missing_topics_are_named(car_nominal_model, tmp_path):
    bag = write_mocap_bag(tmp_path / "no_cmd", with_cmd=False)
    proc = run("dynlab", "compare", "--model", car_nominal_model, "--bag", bag, "--out", tmp_path / "r",
               "--pose-topic", "/mocap/rc_car/pose", check=False)
    assert proc.returncode != 0
    assert "/car/cmd" in proc.stderr and "/mocap/rc_car/pose" in proc.stderr, proc.stderr
    # the default pose topic is not there either: the message names it and lists what is
    proc = run("dynlab", "compare", "--model", car_nominal_model, "--bag", bag, "--out", tmp_path / "r", check=False)
    assert proc.returncode != 0
    assert "/car/pose" in proc.stderr and "/mocap/rc_car/pose" in proc.stderr, proc.stderr
