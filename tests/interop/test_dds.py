"""DDS interop of our recorder, player and node runtime with independent peers.

Peers: Eclipse Cyclone DDS (Python `cyclonedds`) publishes and subscribes ROS 2 topics; bags are
read back with `rosbags` and `mcap-ros2-support` and written for playback with them. Every test
uses its own topic names and its own DDS domain, so lingering processes cannot cross-talk, and
waits on matched publications/subscriptions or on our processes' exit, with bounded timeouts.
"""
from __future__ import annotations

import pathlib
import signal
import time
import uuid

import pytest
from cyclonedds.core import Policy, Qos
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.reader import read_ros2_messages
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_typestore

from conftest import start, stop
from peers.ros_types import (RELIABLE_KEEP_ALL, SENSOR_DATA, Clock, Peer, Time, pose,
                             pose_tuple, take_until, wait_matched)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POSE_TYPE = "geometry_msgs/msg/PoseStamped"


def unique(name: str) -> str:
    return f"{name}_{uuid.uuid4().hex[:8]}"






def wait_for_recorder_subscription(writer, proc, timeout=15.0):
    if not wait_matched(writer, timeout):
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"the recorder never subscribed:\n{err}")


def rosbags_messages(bag: pathlib.Path, topic: str) -> list:
    with Rosbag2Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        assert conns, f"{topic} not in {[c.topic for c in reader.connections]}"
        assert all(c.msgtype == POSE_TYPE for c in conns)
        return [(TYPESTORE.deserialize_cdr(raw, conn.msgtype), t)
                for conn, t, raw in reader.messages(connections=conns)]


def mcap_files(bag: pathlib.Path) -> list:
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1, files
    return files


def mcap_ros2_messages(bag: pathlib.Path, topic: str) -> list:
    return [m.ros_msg for m in read_ros2_messages(str(mcap_files(bag)[0]), topics=[topic])]


def write_pose_bag(path: pathlib.Path, topic: str, n: int, period_ns: int, start_ns=1_700_000_000_000_000_000):
    """A rosbag2 bag (MCAP storage, metadata version 9) written by rosbags."""
    with Rosbag2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(topic, POSE_TYPE, typestore=TYPESTORE)
        for i in range(n):
            writer.write(conn, start_ns + i * period_ns, TYPESTORE.serialize_cdr(to_rosbags(pose(i)), POSE_TYPE))


def to_rosbags(p):
    T = TYPESTORE.types
    h, q, o = p.header, p.pose.position, p.pose.orientation
    return T["geometry_msgs/msg/PoseStamped"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=h.stamp.sec, nanosec=h.stamp.nanosec),
                                        frame_id=h.frame_id),
        pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=q.x, y=q.y, z=q.z),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=o.x, y=o.y, z=o.z, w=o.w)))


def test_cyclone_publisher_to_recorder_reads_identically_in_rosbags_and_mcap_ros2(tmp_path):
    domain, topic = 11, unique("/car/pose")
    bag = tmp_path / "run"
    rec = start("recorder", "-o", bag, topic, domain=domain)
    peer = Peer(domain)
    writer = peer.writer(topic, qos=RELIABLE_KEEP_ALL)
    wait_for_recorder_subscription(writer, rec)
    sent = [pose(i) for i in range(300)]
    for p in sent:
        writer.write(p)
        time.sleep(0.002)
    assert writer.wait_for_acks(int(5e9))
    err = stop(rec, signal.SIGINT)
    assert "300 messages" in err, err

    expected = [pose_tuple(p) for p in sent]
    got_rosbags = rosbags_messages(bag, topic)
    assert [pose_tuple(m) for m, _ in got_rosbags] == expected
    times = [t for _, t in got_rosbags]
    assert times == sorted(times) and times[-1] - times[0] > 0.3e9  # receive times, ≥ 300 × 2 ms
    assert [pose_tuple(m) for m in mcap_ros2_messages(bag, topic)] == expected

    # QoS recorded as offered (reliable, volatile) and the ros2 profile, as rosbag2 writes them
    with open(mcap_files(bag)[0], "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        (channel,) = [c for c in summary.channels.values() if c.topic == topic]
        assert channel.message_encoding == "cdr"
        assert "reliability: reliable" in channel.metadata["offered_qos_profiles"]
        assert summary.schemas[channel.schema_id].encoding == "ros2msg"


def test_player_to_cyclone_subscriber_every_message_identical_and_in_order(tmp_path):
    domain, topic = 12, unique("/car/pose")
    bag = tmp_path / "recorded"
    n = 120
    write_pose_bag(bag, topic, n, period_ns=5_000_000)  # 200 Hz, 0.6 s
    peer = Peer(domain)
    reader = peer.reader(topic, qos=RELIABLE_KEEP_ALL)
    # best effort like ROS 2's clock QoS, keeping every sample until the test takes them
    clock_reader = peer.reader("/clock", Clock, qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepAll))
    play = start("player", bag, "--wait-for-subscribers", 15, domain=domain)
    got = take_until(reader, n, timeout=30)
    stop(play, timeout=30)
    assert [pose_tuple(p) for p in got] == [pose_tuple(pose(i)) for i in range(n)]
    # /clock carried bag time, never going backwards (100 Hz over 0.6 s of playback)
    clocks = [c.clock.sec * 10**9 + c.clock.nanosec for c in clock_reader.take(N=10000) if isinstance(c, Clock)]
    assert len(clocks) > 10, clocks
    assert clocks == sorted(clocks)
    assert all(1_700_000_000_000_000_000 <= c <= 1_700_000_000_000_000_000 + (n - 1) * 5_000_000 for c in clocks)


def test_player_plays_a_bare_mcap_at_double_rate_with_topic_filter(tmp_path):
    domain, topic, other = 13, unique("/push/block_pose"), unique("/other")
    path = tmp_path / "bare.mcap"
    from mcap_ros2.writer import Writer as McapRos2Writer
    msgdef = TYPESTORE.generate_msgdef(POSE_TYPE, ros_version=2)[0]
    with open(path, "wb") as f:
        w = McapRos2Writer(f)
        schema = w.register_msgdef(POSE_TYPE, msgdef)
        for i in range(50):
            for t in (topic, other):
                p = pose(i, frame="table")
                w.write_message(t, schema, {
                    "header": {"stamp": {"sec": p.header.stamp.sec, "nanosec": p.header.stamp.nanosec},
                               "frame_id": p.header.frame_id},
                    "pose": {"position": vars(p.pose.position), "orientation": vars(p.pose.orientation)}},
                    log_time=1_000_000_000 + i * 20_000_000)
        w.finish()
    peer = Peer(domain)
    reader = peer.reader(topic, qos=RELIABLE_KEEP_ALL)
    other_reader = peer.reader(other, qos=RELIABLE_KEEP_ALL)
    t0 = time.monotonic()
    play = start("player", path, "--rate", 2.0, "--topics", topic, "--clock-rate", 0,
                 "--wait-for-subscribers", 15, domain=domain)
    got = take_until(reader, 50, timeout=30)
    stop(play, timeout=30)
    assert [pose_tuple(p) for p in got] == [pose_tuple(pose(i, frame="table")) for i in range(50)]
    assert other_reader.take(N=100) == []
    assert time.monotonic() - t0 > 0.49  # 0.98 s of bag at 2× is ≥ 0.49 s of wall time


def test_both_ways_with_remaps_on_domain_7_and_nothing_on_domain_0(tmp_path):
    suffix = uuid.uuid4().hex[:8]
    # Cyclone → our recorder, recorded topic remapped
    bag = tmp_path / "remapped"
    wire = f"/mocap/pose_{suffix}"
    rec = start("recorder", "-o", bag, f"/car/pose_{suffix}", "--ros-args", "-r",
                f"/car/pose_{suffix}:=/mocap/pose_{suffix}", "-r", "__node:=rec7", domain=7)
    peer7, peer0 = Peer(7), Peer(0)
    writer = peer7.writer(wire, qos=RELIABLE_KEEP_ALL)
    wait_for_recorder_subscription(writer, rec)
    for i in range(40):
        writer.write(pose(i))
    assert writer.wait_for_acks(int(5e9))
    stop(rec, signal.SIGTERM)
    assert [pose_tuple(m) for m, _ in rosbags_messages(bag, wire)] == [pose_tuple(pose(i)) for i in range(40)]

    # our player → Cyclone on domain 7 under the remapped name; nothing on domain 0 or the old name
    src = tmp_path / "src"
    write_pose_bag(src, f"/car/pose_{suffix}", 30, period_ns=10_000_000)
    target = f"/sim/pose_{suffix}"
    reader7 = peer7.reader(target, qos=RELIABLE_KEEP_ALL)
    old_name7 = peer7.reader(f"/car/pose_{suffix}", qos=RELIABLE_KEEP_ALL)
    reader0 = peer0.reader(target, qos=RELIABLE_KEEP_ALL)
    play = start("player", src, "--wait-for-subscribers", 15, "--ros-args", "-r",
                 f"/car/pose_{suffix}:={target}", domain=7)
    got = take_until(reader7, 30, timeout=30)
    stop(play, timeout=30)
    assert [pose_tuple(p) for p in got] == [pose_tuple(pose(i)) for i in range(30)]
    assert reader0.take(N=100) == [] and reader0.get_subscription_matched_status().current_count == 0
    assert old_name7.take(N=100) == []


def test_typed_publisher_and_subscription_interoperate_both_ways():
    domain = 14
    peer = Peer(domain)
    # our typed publisher → Cyclone
    to_cyclone = unique("/probe/out")
    reader = peer.reader(to_cyclone, qos=RELIABLE_KEEP_ALL)
    pub = start("dds_probe", "pub", "--topic", to_cyclone, "--rate", 200, "--count", 50, domain=domain)
    got = take_until(reader, 50, timeout=30)
    stop(pub, timeout=30)
    assert [p.header.frame_id for p in got] == [str(i) for i in range(50)]
    assert [p.pose.position.x for p in got] == [float(i) for i in range(50)]
    # Cyclone → our typed subscription (best effort, sensor data)
    to_us = unique("/probe/in")
    sub = start("dds_probe", "sub", "--topic", to_us, "--count", 40, "--best-effort", domain=domain)
    writer = peer.writer(to_us, qos=SENSOR_DATA)
    assert wait_matched(writer, 15), "dds_probe sub never matched"
    time.sleep(0.3)
    for i in range(40):
        p = pose(i)
        p.header.stamp.sec, p.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
        writer.write(p)
        time.sleep(0.005)
    out, err = sub.communicate(timeout=30)
    assert sub.returncode == 0, err
    assert '"received": 40' in out, out + err


def test_recorder_killed_with_sigkill_leaves_a_bag_holding_all_but_the_last_second(tmp_path):
    domain, topic = 15, unique("/car/pose")
    bag = tmp_path / "killed"
    rec = start("recorder", "-o", bag, topic, domain=domain)
    peer = Peer(domain)
    writer = peer.writer(topic, qos=RELIABLE_KEEP_ALL)
    wait_for_recorder_subscription(writer, rec)
    sent_at = []
    t_end = time.monotonic() + 3.5
    i = 0
    while time.monotonic() < t_end:
        writer.write(pose(i))
        sent_at.append(time.monotonic())
        i += 1
        time.sleep(0.01)
    killed_at = time.monotonic()
    rec.kill()
    rec.wait(timeout=10)
    assert rec.returncode == -signal.SIGKILL

    # The bag reads: metadata.yaml is there, and the MCAP file streams record by record up to
    # the cut (no footer or summary after a kill).
    assert (bag / "metadata.yaml").exists()
    decoder = DecoderFactory()
    schemas, channels, frames = {}, {}, []
    with open(mcap_files(bag)[0], "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False, emit_chunks=False).records:
                kind = type(record).__name__
                if kind == "Schema":
                    schemas[record.id] = record
                elif kind == "Channel":
                    channels[record.id] = record
                elif kind == "Message":
                    ch = channels[record.channel_id]
                    decode = decoder.decoder_for(ch.message_encoding, schemas[ch.schema_id])
                    frames.append(decode(record.data).header.frame_id)
        except Exception:  # the damaged tail after the last complete chunk
            pass
    indices = [int(f.rsplit("_", 1)[1]) for f in frames]
    assert indices == list(range(len(indices))), "the bag holds a prefix of what was sent, in order"
    must_have = sum(1 for t in sent_at if t <= killed_at - 1.25)  # flushed every second
    assert must_have > 100
    assert len(indices) >= must_have, f"{len(indices)} messages in the bag, {must_have} sent > 1 s before the kill"


def test_recorder_with_use_sim_time_logs_messages_at_clock_time(tmp_path):
    domain, topic = 16, unique("/push/block_pose")
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    use_sim_time: true\n")
    bag = tmp_path / "simtime"
    rec = start("recorder", "-o", bag, topic, "--ros-args", "--params-file", params, domain=domain)
    peer = Peer(domain)
    clock = peer.writer("/clock", Clock, qos=SENSOR_DATA)
    writer = peer.writer(topic, qos=RELIABLE_KEEP_ALL)
    wait_for_recorder_subscription(writer, rec)
    assert wait_matched(clock, 15), "the recorder never subscribed to /clock"
    sim_ns = 42_000_000_000
    for i in range(50):
        sim_ns += 10_000_000
        clock.write(Clock(clock=Time(sec=sim_ns // 10**9, nanosec=sim_ns % 10**9)))
        time.sleep(0.005)
        writer.write(pose(i))
        time.sleep(0.005)
    assert writer.wait_for_acks(int(5e9))
    stop(rec)
    got = rosbags_messages(bag, topic)
    assert [pose_tuple(m) for m, _ in got] == [pose_tuple(pose(i)) for i in range(50)]
    log_times = [t for _, t in got]
    assert all(42_000_000_000 <= t <= sim_ns for t in log_times), log_times[:5]
    assert log_times == sorted(log_times) and log_times[-1] > log_times[0]


def test_player_loops_until_interrupted(tmp_path):
    domain, topic = 17, unique("/car/pose")
    bag = tmp_path / "short"
    write_pose_bag(bag, topic, 10, period_ns=20_000_000)  # 0.18 s of bag
    peer = Peer(domain)
    reader = peer.reader(topic, qos=RELIABLE_KEEP_ALL)
    play = start("player", bag, "--loop", "--rate", 2.0, "--wait-for-subscribers", 15, domain=domain)
    got = take_until(reader, 25, timeout=30)
    stop(play, signal.SIGINT)
    frames = [p.header.frame_id for p in got]
    assert len(frames) >= 25
    assert frames == [f"world_{i % 10}" for i in range(len(frames))], "passes repeat the bag in order"
