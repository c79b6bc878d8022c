"""Bags against independent peers: mcap-ros2-support and rosbags write bags we read; they read the
bags we write, value for value; a cut bag never makes `dynlab bag info` panic; `sim_node`'s /tf
and latched /tf_static, recorded over DDS, read with rosbags, also after `dynlab bag repair`.

Message values are random (seeded) and generated from the message definitions by a small .msg
parser here, so every field of every type the registry knows is exercised.
"""
import json
import math
import random
import re
import shutil
import time
import uuid

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages
from mcap_ros2.writer import Writer as McapRos2Writer
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from conftest import run, start, stop

SEPARATOR = "=" * 80
INT_RANGES = {
    "int8": (-(2**7), 2**7 - 1), "uint8": (0, 2**8 - 1), "byte": (0, 255), "char": (0, 255),
    "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1),
}
INFINITE = QosTime(9223372036, 854775807)


# --- a minimal .msg parser (independent of our Rust code and of the peers) -------------------

def full_name(name, package):
    parts = name.split("/")
    if len(parts) == 3:
        return name
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if name == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{name}"


def parse_definition(type_name, text):
    """{full type name: [(field name, base type, array kind, size)]} for a ros2msg schema."""
    blocks, current, lines = {}, type_name, []
    for line in text.splitlines():
        if line.startswith("=" * 10):
            blocks[current], current, lines = lines, None, []
        elif current is None:
            current = full_name(line.removeprefix("MSG:").strip(), "")
        else:
            lines.append(line)
    blocks[current] = lines
    types = {}
    for name, body in blocks.items():
        package = name.split("/")[0]
        fields = []
        for line in body:
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            typ, fname = line.split()[:2]
            if "=" in fname or (len(line.split()) > 2 and line.split()[2].startswith("=")):
                continue  # constant
            m = re.fullmatch(r"([\w/]+(?:<=\d+)?)(?:\[(<=)?(\d*)\])?", typ)
            base, bounded, size = m.group(1), m.group(2), m.group(3)
            kind = None if m.group(0) == base else ("bounded" if bounded else ("array" if size else "seq"))
            if base.split("<=")[0] not in INT_RANGES and base.split("<=")[0] not in (
                    "bool", "float32", "float64", "string", "wstring"):
                base = full_name(base, package)
            fields.append((fname, base, kind, int(size) if size else None))
        types[name] = fields
    return types


def random_scalar(rng, base, types):
    if base in types:
        return random_value(rng, base, types)
    plain = base.split("<=")[0]
    if plain == "bool":
        return rng.random() < 0.5
    if plain in INT_RANGES:
        lo, hi = INT_RANGES[plain]
        return rng.choice([lo, hi, 0, rng.randint(lo, hi)])
    if plain == "float64":
        return rng.choice([rng.uniform(-1e3, 1e3), rng.uniform(-1, 1) * 10 ** rng.randint(-300, 300), -0.0, 0.1])
    if plain == "float32":
        return float(np.float32(rng.uniform(-1e3, 1e3)))
    if plain in ("string", "wstring"):
        limit = int(base.split("<=")[1]) if "<=" in base else 12
        return "".join(rng.choice("abcXYZ_/019 é") for _ in range(rng.randint(0, limit)))
    raise ValueError(base)


def random_value(rng, type_name, types):
    value = {}
    for fname, base, kind, size in types[type_name]:
        if kind is None:
            value[fname] = random_scalar(rng, base, types)
        else:
            n = size if kind == "array" else rng.randint(0, size if kind == "bounded" else 3)
            value[fname] = [random_scalar(rng, base, types) for _ in range(n)]
    return value


def plain(obj):
    """Decoded messages of either peer as nested dicts and lists."""
    if isinstance(obj, np.ndarray):
        return [plain(x) for x in obj.tolist()]
    if isinstance(obj, (list, tuple)):
        return [plain(x) for x in obj]
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (bool, int, float, str)) or obj is None:
        return obj
    if isinstance(obj, (bytes, bytearray)):
        return list(obj)
    names = getattr(obj, "__slots__", None) or list(vars(obj))
    return {n: plain(getattr(obj, n)) for n in names if not n.startswith("__") and n != "_type"}


def same(a, b):
    """Exact equality, also telling -0.0 from 0.0."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b and math.copysign(1, a) == math.copysign(1, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b and type(a) is type(b) or (isinstance(a, (int, float)) and a == b and not isinstance(a, bool))


def registry():
    lines = run("dynlab", "bag", "types").stdout.splitlines()
    return {d["type"]: d["definition"] for d in map(json.loads, lines)}


def to_rosbags(ts, type_name, value, types):
    """A rosbags message object from a plain value."""
    kwargs = {}
    for fname, base, kind, _ in types[type_name]:
        v = value[fname]
        if base in types:
            v = to_rosbags(ts, base, v, types) if kind is None else [to_rosbags(ts, base, x, types) for x in v]
        elif kind is not None and base.split("<=")[0] not in ("string", "wstring"):
            dtype = {"float64": np.float64, "float32": np.float32, "bool": np.bool_, "byte": np.uint8,
                     "char": np.uint8}.get(base, getattr(np, base, None))
            v = np.array(v, dtype=dtype)
        kwargs[fname] = v
    return ts.types[type_name](**kwargs)


def export(bag, *args):
    out = run("dynlab", "bag", "export", bag, *args).stdout
    return [json.loads(line) for line in out.splitlines()]


def jazzy_store_with(definitions):
    """rosbags' Jazzy store plus every type it lacks, registered from our schema text."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    for name, text in definitions.items():
        if name not in ts.types:
            ts.register(get_types_from_msg(text, name))
    return ts


# --- (a) peers write, we read ----------------------------------------------------------------

PEER_TYPES = ["geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Twist",
              "ackermann_msgs/msg/AckermannDriveStamped", "dynlab_msgs/msg/PushAction"]


def test_mcap_ros2_writer_bag_exports_identical_values(tmp_path):
    ours = registry()
    store = get_typestore(Stores.ROS2_JAZZY)
    rng = random.Random(7)
    path = tmp_path / "peer.mcap"
    written = []
    with open(path, "wb") as f:
        writer = McapRos2Writer(f)
        for k, type_name in enumerate(PEER_TYPES):
            # Standard types: rosbags' own schema text; PushAction: ours.
            text = (store.generate_msgdef(type_name, ros_version=2)[0]
                    if type_name in store.types else ours[type_name])
            types = parse_definition(type_name, text)
            schema = writer.register_msgdef(type_name, text)
            topic = f"/peer/t{k}"
            for i in range(25):
                value = random_value(rng, type_name, types)
                t = 1_000_000_000 + i * 40_000_000 + k
                writer.write_message(topic, schema, value, log_time=t, publish_time=t + 5)
                written.append((t, topic, type_name, value))
        writer.finish()
    rows = export(path)
    assert len(rows) == len(written)
    written.sort(key=lambda w: w[0])
    for row, (t, topic, type_name, value) in zip(rows, written):
        assert (row["topic"], row["type"], row["log_time_ns"], row["publish_time_ns"]) == (topic, type_name, t, t + 5)
        assert same(row["value"], value), (row["value"], value)
    info = run("dynlab", "bag", "info", path).stdout
    assert "ackermann_msgs/msg/AckermannDriveStamped" in info and "25" in info


def test_rosbags_writer_bag_reads_with_qos_and_values(tmp_path):
    ours = registry()
    ts = jazzy_store_with(ours)
    rng = random.Random(11)
    bag = tmp_path / "rosbags_bag"
    qos = Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
              INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)
    written = []
    with Rosbag2Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for k, type_name in enumerate(["geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry",
                                       "dynlab_msgs/msg/PushAction"]):
            types = parse_definition(type_name, ours[type_name])
            conn = writer.add_connection(f"/rb/t{k}", type_name, typestore=ts, offered_qos_profiles=[qos])
            for i in range(20):
                value = random_value(rng, type_name, types)
                t = 2_000_000_000 + i * 10_000_000 + k
                writer.write(conn, t, ts.serialize_cdr(to_rosbags(ts, type_name, value, types), type_name))
                written.append((t, f"/rb/t{k}", value))
    rows = export(bag)
    written.sort(key=lambda w: w[0])
    assert [(r["log_time_ns"], r["topic"]) for r in rows] == [(t, topic) for t, topic, _ in written]
    for row, (_, _, value) in zip(rows, written):
        assert same(row["value"], value), (row["value"], value)
    info = run("dynlab", "bag", "info", bag).stdout
    assert "nav_msgs/msg/Odometry" in info and "recovered" not in info


# --- (b) we write, peers read ----------------------------------------------------------------

def test_imported_bags_read_identically_by_rosbags_and_mcap_ros2(tmp_path):
    ours = registry()
    assert set(PEER_TYPES) <= set(ours)
    rng = random.Random(2024)
    lines, expected = [], []
    for k, (type_name, text) in enumerate(sorted(ours.items())):
        types = parse_definition(type_name, text)
        for i in range(6):
            value = random_value(rng, type_name, types)
            t = 3_000_000_000 + i * 1_000_000 + k
            topic = "/" + type_name.replace("/msg/", "/").lower()
            lines.append({"topic": topic, "type": type_name, "log_time_ns": t, "publish_time_ns": t - 7, "value": value})
            expected.append((t, topic, type_name, value))
    rng.shuffle(lines)  # written out of time order
    src = tmp_path / "in.jsonl"
    src.write_text("".join(json.dumps(line) + "\n" for line in lines))
    bag = tmp_path / "ours"
    run("dynlab", "bag", "import", src, "--out", bag, "--qos", "sensor-data", "--chunk-size", "2000")
    expected.sort(key=lambda e: e[0])

    # metadata.yaml: version 9, as rosbags parses it.
    meta = YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(expected)
    assert meta["relative_file_paths"] == ["ours_0.mcap"]

    # rosbags: register the types its Jazzy store lacks from the bag's own schemas.
    store = get_typestore(Stores.ROS2_JAZZY)
    with Rosbag2Reader(bag) as reader:
        for conn in reader.connections:
            if conn.msgtype not in store.types:
                store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
            assert conn.ext.offered_qos_profiles == [Qos(
                QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
                INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)]
            if conn.msgtype in get_typestore(Stores.ROS2_JAZZY).types:
                # Our RIHS01 type hash equals rosbags' for every standard type.
                assert conn.digest == store.hash_rihs01(conn.msgtype), conn.msgtype
        got = [(t, conn.topic, plain(store.deserialize_cdr(data, conn.msgtype)))
               for conn, t, data in reader.messages()]
        assert reader.message_count == len(expected)
    assert [(t, topic) for t, topic, _ in got] == [(t, topic) for t, topic, _, _ in expected]
    for (_, _, value), (_, _, type_name, want) in zip(got, expected):
        assert same(value, want), (type_name, value, want)

    # mcap-ros2-support, straight from the .mcap file.
    got = list(read_ros2_messages(bag / "ours_0.mcap"))
    assert len(got) == len(expected)
    for m, (t, topic, type_name, want) in zip(got, expected):
        assert (m.log_time_ns, m.publish_time_ns, m.channel.topic, m.schema.name) == (t, t - 7, topic, type_name)
        assert m.channel.message_encoding == "cdr" and m.schema.encoding == "ros2msg"
        assert same(plain(m.ros_msg), want), (type_name, plain(m.ros_msg), want)

    # The file layout rosbag2 Jazzy writes.
    with open(bag / "ours_0.mcap", "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        assert header.profile == "ros2"
        assert summary.statistics.message_count == len(expected)
        assert summary.statistics.chunk_count > 1
        assert all(c.compression == "zstd" for c in summary.chunk_indexes)
        # Every chunk with messages has their index (with 2000-byte chunks, a long schema such as
        # TFMessage's can fill a chunk with only schema and channel records: valid MCAP).
        with_messages = [c for c in summary.chunk_indexes if c.message_start_time > 0]
        assert len(with_messages) > 1
        assert all(c.message_index_length > 0 for c in with_messages)
        records = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert len(records) == 1
        inner = YAML(typ="safe").load(records[0].metadata["serialized_metadata"])
        assert inner["version"] == 9 and inner["message_count"] == len(expected)

    # And our own export gives back exactly what was imported.
    rows = export(bag)
    assert [same(r["value"], e[3]) for r, e in zip(rows, expected)] == [True] * len(expected)


# --- (c) a cut bag ---------------------------------------------------------------------------

def test_cut_bag_info_reports_recovery_and_never_panics(tmp_path):
    lines = [{"topic": "/car/pose", "type": "geometry_msgs/msg/PoseStamped", "log_time_ns": 10**9 + i * 10**7,
              "value": {"header": {"stamp": {"sec": 1, "nanosec": i}, "frame_id": "world"},
                        "pose": {"position": {"x": i * 0.1, "y": 0.0, "z": 0.0},
                                 "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}}}
             for i in range(2000)]
    src = tmp_path / "in.jsonl"
    src.write_text("".join(json.dumps(line) + "\n" for line in lines))
    bag = tmp_path / "whole"
    run("dynlab", "bag", "import", src, "--out", bag, "--chunk-size", "8192")
    data = (bag / "whole_0.mcap").read_bytes()
    counts = []
    for fraction in (0.0001, 0.02, 0.25, 0.5, 0.75, 0.999):
        cut = tmp_path / f"cut_{fraction}"
        shutil.copytree(bag, cut)
        (cut / "whole_0.mcap").write_bytes(data[: int(len(data) * fraction)])
        proc = run("dynlab", "bag", "info", cut, check=False)
        assert "panicked" not in proc.stderr
        if proc.returncode == 0:
            count = int(re.search(r"recovered (\d+)(?: of \d+)? messages", proc.stdout).group(1))
            assert re.search(r"^messages:\s+%d$" % count, proc.stdout, re.M)
            assert count <= 2000
            counts.append(count)
        else:
            assert proc.stderr.startswith("error: nothing readable in bag"), proc.stderr
            counts.append(0)
        export_proc = run("dynlab", "bag", "export", cut, check=False)
        assert "panicked" not in export_proc.stderr
    assert counts == sorted(counts) and counts[-1] > 1500, counts


# --- (d) tf from sim_node, recorded over DDS; a repaired bag ----------------------------------

def tf_by_stamp(bag, topic):
    """Stamp → [(parent, child, x, y, z, qx, qy, qz, qw)] of every TFMessage on `topic`, with rosbags."""
    store = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    with Rosbag2Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        assert conns, f"{topic} not in {[c.topic for c in reader.connections]}"
        assert conns[0].msgtype == "tf2_msgs/msg/TFMessage"
        for conn, _, raw in reader.messages(connections=conns):
            for t in store.deserialize_cdr(raw, conn.msgtype).transforms:
                tr, q = t.transform.translation, t.transform.rotation
                stamp = t.header.stamp.sec * 10**9 + t.header.stamp.nanosec
                out.setdefault(stamp, []).append(
                    (t.header.frame_id, t.child_frame_id, tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w))
    return out


def poses_by_stamp(bag, topic):
    store = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    with Rosbag2Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in reader.messages(connections=conns):
            m = store.deserialize_cdr(raw, conn.msgtype)
            p, q = m.pose.position, m.pose.orientation
            out[m.header.stamp.sec * 10**9 + m.header.stamp.nanosec] = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    return out


def test_sim_node_tf_recorded_over_dds_and_repaired_reads_with_rosbags(tmp_path):
    """sim_node publishes /tf (the measured pose of /car/pose, world → car) and, once, a latched
    /tf_static (the axles); the recorder, started first, gets both over DDS. rosbags reads /tf with
    the same values as /car/pose; a cut copy repaired by `dynlab bag repair` reads whole with
    rosbags and holds exactly what our reader recovered."""
    domain = 150 + uuid.uuid4().int % 60
    bag = tmp_path / "tf_dds"
    rec = start("recorder", "-o", bag, "/tf", "/tf_static", "/car/pose", domain=domain)
    time.sleep(1.0)
    sim = start("sim_node", "--ros-args", "-p", "world:=car", "-p", "rate:=5.0", domain=domain)
    time.sleep(5.0)
    stop(rec)
    stop(sim)

    tf = tf_by_stamp(bag, "/tf")
    poses = poses_by_stamp(bag, "/car/pose")
    common = sorted(set(tf) & set(poses))
    assert len(common) > 100, (len(tf), len(poses))
    for t in common:
        [(parent, child, *values)] = tf[t]
        assert (parent, child) == ("world", "car")
        assert tuple(values) == poses[t], t
    # the latched static transforms reached a subscriber that matched after they were published
    static = tf_by_stamp(bag, "/tf_static")
    frames = sorted((p, c) for links in static.values() for p, c, *_ in links)
    assert frames == [("car", "car/front_axle"), ("car", "car/rear_axle")], frames
    with Rosbag2Reader(bag) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/tf_static"]
        assert conn.ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL

    # cut the recording in the middle; repair it; rosbags reads the repaired bag whole
    cut = tmp_path / "tf_cut"
    shutil.copytree(bag, cut)
    [mcap] = list(cut.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    info = run("dynlab", "bag", "info", cut).stdout
    recovered = int(re.search(r"recovered (\d+) of \d+ messages", info).group(1))
    fixed = tmp_path / "tf_fixed"
    out = run("dynlab", "bag", "repair", cut, fixed).stdout
    assert f"kept {recovered} of {recovered} messages" in out, out
    with Rosbag2Reader(fixed) as reader:
        assert reader.message_count == recovered
        assert sum(1 for _ in reader.messages()) == recovered
    fixed_tf = tf_by_stamp(fixed, "/tf")
    assert 0 < len(fixed_tf) < len(tf)
    assert all(fixed_tf[t] == tf[t] for t in fixed_tf)
    # mcap-ros2-support decodes it too
    assert sum(1 for _ in read_ros2_messages(next(fixed.glob("*.mcap")))) == recovered
