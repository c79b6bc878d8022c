"""Our CDR and message definitions against independent peers.

For every message type, seeded random values (extreme floats, empty and non-ASCII strings, empty
and long sequences) are serialized by `rosbags` (ROS 2 Jazzy type store) and by our `msg_cdr`
tool from the same JSON form; the bytes must be identical. Decoding rosbags' bytes with
`msg_cdr --decode` must give back the exact values. Our definition texts must describe the same
fields as rosbags' built-in Jazzy definitions, and `mcap-ros2-support`'s parser must accept every
schema and decode our bytes with it.
"""
import json
import math
import struct

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from conftest import run

SEED = 20240607
SAMPLES_PER_TYPE = 12

# Types that are not in rosbags' Jazzy store: registered from our own definition text.
OURS_ONLY = {
    "dynlab_msgs/msg/PushAction",
    "ackermann_msgs/msg/AckermannDrive",
    "ackermann_msgs/msg/AckermannDriveStamped",
}

EXTREME_F64 = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-310, 1.7976931348623157e308,
               -1.7976931348623157e308, math.inf, -math.inf, math.nan, 1.0, -1.0, math.pi]
EXTREME_F32 = [0.0, -0.0, float(np.float32(1e-45)), float(np.finfo(np.float32).tiny),
               float(np.finfo(np.float32).max), float(-np.finfo(np.float32).max),
               math.inf, -math.inf, math.nan, float(np.float32(0.1))]
STRINGS = ["", "world", "table", "base_link", "ü", "Ωmega/ロボット", "🚗 car", "a" * 300,
           "tab\tand\nnewline", "quote\"backslash\\"]
INT_RANGES = {"int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1)}


def non_finite_json(x: float):
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "Infinity" if x > 0 else "-Infinity"
    return x


@pytest.fixture(scope="module")
def schemas():
    out = run("msg_cdr", "--schemas").stdout
    return {d["type"]: d for d in map(json.loads, out.splitlines())}


@pytest.fixture(scope="module")
def store(schemas):
    ts = get_typestore(Stores.ROS2_JAZZY)
    for name in sorted(OURS_ONLY):
        assert name not in ts.fielddefs, f"{name} is in rosbags' store now: compare against it instead"
        types = get_types_from_msg(schemas[name]["definition"], name)
        ts.register({k: v for k, v in types.items() if k not in ts.fielddefs})
    return ts


class Generator:
    """Seeded random values of a type as (rosbags object, our JSON form)."""

    def __init__(self, store, seed):
        self.store = store
        self.rng = np.random.RandomState(seed)

    def f64(self):
        if self.rng.rand() < 0.3:
            return EXTREME_F64[self.rng.randint(len(EXTREME_F64))]
        return float(self.rng.normal(0.0, 10.0 ** self.rng.randint(-5, 6)))

    def f32(self):
        if self.rng.rand() < 0.3:
            return EXTREME_F32[self.rng.randint(len(EXTREME_F32))]
        return float(np.float32(self.rng.normal(0.0, 10.0)))

    def base(self, typ):
        if typ == "float64":
            v = self.f64()
            return v, non_finite_json(v)
        if typ == "float32":
            v = self.f32()
            return v, non_finite_json(v)
        if typ == "string":
            v = STRINGS[self.rng.randint(len(STRINGS))]
            return v, v
        if typ in INT_RANGES:
            lo, hi = INT_RANGES[typ]
            pick = self.rng.randint(4)
            v = lo if pick == 0 else hi if pick == 1 else int(self.rng.randint(lo, hi, dtype=np.int64))
            return v, v
        raise AssertionError(f"no generator for {typ}")

    def message(self, typename):
        _, fields = self.store.fielddefs[typename]
        kwargs, value = {}, {}
        for name, (kind, arg) in fields:
            if kind == Nodetype.BASE:
                kwargs[name], value[name] = self.base(arg[0])
            elif kind == Nodetype.NAME:
                kwargs[name], value[name] = self.message(arg)
            elif kind == Nodetype.ARRAY:
                (sub_kind, sub), length = arg
                assert sub_kind == Nodetype.BASE and sub[0] == "float64", (typename, name)
                items = [self.f64() for _ in range(length)]
                kwargs[name] = np.array(items, dtype=np.float64)
                value[name] = [non_finite_json(x) for x in items]
            elif kind == Nodetype.SEQUENCE:
                (sub_kind, sub), _ = arg
                assert sub_kind == Nodetype.NAME, (typename, name)
                count = [0, 0, 1, 2, 5, 300][self.rng.randint(6)]
                pairs = [self.message(sub) for _ in range(count)]
                kwargs[name] = [p[0] for p in pairs]
                value[name] = [p[1] for p in pairs]
            else:
                raise AssertionError(f"unexpected field kind {kind} in {typename}.{name}")
        return self.store.types[typename](**kwargs), value


def same_float(a, b, bits32):
    """Bit-exact float comparison (NaN equals NaN; -0.0 differs from 0.0)."""
    def as_float(x):
        if isinstance(x, str):
            return {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}[x]
        return float(x)
    a, b = as_float(a), as_float(b)
    if bits32:
        return np.float32(a).tobytes() == np.float32(b).tobytes()
    return struct.pack("<d", a) == struct.pack("<d", b)


def assert_same(store, typename, expected, actual, path=""):
    """Compares two JSON forms of `typename` field by field, floats bit-exactly."""
    _, fields = store.fielddefs[typename]
    assert set(actual) == {name for name, _ in fields}, f"{typename} at {path or '.'}: fields {sorted(actual)}"
    for name, (kind, arg) in fields:
        where = f"{path}.{name}" if path else name
        exp, act = expected[name], actual[name]
        if kind == Nodetype.BASE and arg[0] in ("float64", "float32"):
            assert same_float(exp, act, arg[0] == "float32"), f"{typename}.{where}: {exp!r} != {act!r}"
        elif kind == Nodetype.BASE:
            assert exp == act and type(exp) is type(act), f"{typename}.{where}: {exp!r} != {act!r}"
        elif kind == Nodetype.NAME:
            assert_same(store, arg, exp, act, where)
        elif kind == Nodetype.ARRAY:
            assert len(act) == len(exp) == arg[1], where
            for i, (e, a) in enumerate(zip(exp, act)):
                assert same_float(e, a, False), f"{typename}.{where}[{i}]: {e!r} != {a!r}"
        else:
            assert len(act) == len(exp), f"{typename}.{where}: {len(act)} elements, expected {len(exp)}"
            for i, (e, a) in enumerate(zip(exp, act)):
                assert_same(store, arg[0][1], e, a, f"{where}[{i}]")


def samples(store, typename):
    seed = SEED + sorted(store.fielddefs).index(typename)
    gen = Generator(store, seed)
    return [gen.message(typename) for _ in range(SAMPLES_PER_TYPE)]


def all_type_names():
    # The same list as `msg_cdr --list`, kept literal so that a type silently dropped from the
    # registry fails here.
    return [
        "builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration", "std_msgs/msg/Header",
        "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion", "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Vector3", "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/msg/TwistWithCovariance", "nav_msgs/msg/Odometry", "nav_msgs/msg/Path",
        "ackermann_msgs/msg/AckermannDrive", "ackermann_msgs/msg/AckermannDriveStamped",
        "rosgraph_msgs/msg/Clock", "dynlab_msgs/msg/PushAction",
        "geometry_msgs/msg/Transform", "geometry_msgs/msg/TransformStamped", "tf2_msgs/msg/TFMessage",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
    ]


def test_registry_lists_exactly_these_types():
    listed = run("msg_cdr", "--list").stdout.split()
    assert sorted(listed) == sorted(all_type_names())


@pytest.mark.parametrize("typename", all_type_names())
def test_bytes_match_rosbags_and_decode_exactly(store, typename):
    pairs = samples(store, typename)
    # Encode: our bytes from the JSON form must equal rosbags' bytes from the same values.
    lines = "".join(json.dumps({"type": typename, "value": v}) + "\n" for _, v in pairs)
    ours = run("msg_cdr", input=lines).stdout.split()
    assert len(ours) == len(pairs)
    theirs = [bytes(store.serialize_cdr(obj, typename)).hex() for obj, _ in pairs]
    for i, (a, b) in enumerate(zip(ours, theirs)):
        assert a == b, f"{typename} sample {i}: our CDR differs from rosbags'\nours   {a}\ntheirs {b}"
    # Decode: rosbags' bytes through `msg_cdr --decode` give back the values exactly.
    lines = "".join(json.dumps({"type": typename, "hex": h}) + "\n" for h in theirs)
    decoded = [json.loads(line) for line in run("msg_cdr", "--decode", input=lines).stdout.splitlines()]
    assert len(decoded) == len(pairs)
    for (_, expected), got in zip(pairs, decoded):
        assert got["type"] == typename
        assert_same(store, typename, expected, got["value"])


def test_samples_cover_the_edge_cases(store):
    """The generator really produces what the byte comparisons claim to cover."""
    seen = set()
    for typename in all_type_names():
        for obj, value in samples(store, typename):
            text = json.dumps(value, ensure_ascii=False)
            for tag, needle in [("nan", '"NaN"'), ("inf", '"Infinity"'), ("-inf", '"-Infinity"'),
                                ("-0", "-0.0"), ("subnormal", "5e-324"), ("empty string", '""'),
                                ("non-ascii", "ロボット")]:
                if needle in text:
                    seen.add(tag)
            if typename == "nav_msgs/msg/Path":
                seen.add(f"path-{'empty' if not obj.poses else 'long' if len(obj.poses) >= 300 else 'some'}")
    assert seen >= {"nan", "inf", "-inf", "-0", "subnormal", "empty string", "non-ascii",
                    "path-empty", "path-long", "path-some"}, seen


@pytest.mark.parametrize("typename", sorted(set(all_type_names()) - OURS_ONLY))
def test_definition_fields_match_rosbags_jazzy(schemas, typename):
    store = get_typestore(Stores.ROS2_JAZZY)
    ours = get_types_from_msg(schemas[typename]["definition"], typename)
    assert typename in ours
    for name, fielddefs in ours.items():
        assert fielddefs == store.fielddefs[name], f"{name} in the definition of {typename}"
    # Every dependency rosbags knows for this type is present in ours, and nothing else.
    needed, todo = set(), [typename]
    while todo:
        for _, (kind, arg) in store.fielddefs[todo.pop()][1]:
            sub = arg if kind == Nodetype.NAME else arg[0][1] if kind == Nodetype.SEQUENCE else None
            if sub and sub not in needed:
                needed.add(sub)
                todo.append(sub)
    assert set(ours) == needed | {typename}


@pytest.mark.parametrize("typename", all_type_names())
def test_mcap_ros2_accepts_schema_and_decodes_our_bytes(store, schemas, typename):
    definition = schemas[typename]["definition"]
    decoders = generate_dynamic(typename, definition)
    encoders = serialize_dynamic(typename, definition)
    assert typename in decoders and typename in encoders
    pairs = samples(store, typename)[:4]
    lines = "".join(json.dumps({"type": typename, "value": v}) + "\n" for _, v in pairs)
    for (obj, _), hex_line in zip(pairs, run("msg_cdr", input=lines).stdout.split()):
        msg = decoders[typename](bytes.fromhex(hex_line))
        assert_same_object(store, typename, obj, msg)


def assert_same_object(store, typename, ref, msg, path=""):
    """Compares a rosbags object with an mcap_ros2 decoded object, floats bit-exactly."""
    for name, (kind, arg) in store.fielddefs[typename][1]:
        where = f"{path}.{name}" if path else name
        a, b = getattr(ref, name), getattr(msg, name)
        if kind == Nodetype.BASE and arg[0] in ("float64", "float32"):
            assert same_float(a, b, arg[0] == "float32"), f"{typename}.{where}"
        elif kind == Nodetype.BASE and typename == "builtin_interfaces/msg/Time" and name == "sec":
            # mcap_ros2 reads builtin Time.sec as uint32 (a known quirk of its built-in definition).
            assert a % 2**32 == b % 2**32, where
        elif kind == Nodetype.BASE:
            assert a == b, f"{typename}.{where}: {a!r} != {b!r}"
        elif kind == Nodetype.NAME:
            assert_same_object(store, arg, a, b, where)
        elif kind == Nodetype.ARRAY:
            assert all(same_float(x, y, False) for x, y in zip(a, b)) and len(a) == len(b), where
        else:
            assert len(a) == len(b), where
            for i, (x, y) in enumerate(zip(a, b)):
                assert_same_object(store, arg[0][1], x, y, f"{where}[{i}]")


def test_mcap_ros2_sees_quaternion_defaults(schemas):
    """Default values survive in our text: rosbags' parser drops them, mcap_ros2's keeps them."""
    from mcap_ros2._vendor.rosidl_adapter.parser import parse_message_string
    text = schemas["geometry_msgs/msg/Quaternion"]["definition"]
    spec = parse_message_string("geometry_msgs", "Quaternion", text)
    defaults = {f.name: f.default_value for f in spec.fields}
    assert defaults == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def test_push_action_and_ackermann_field_types(store):
    assert [(n, a[0]) for n, (_, a) in store.fielddefs["dynlab_msgs/msg/PushAction"][1][1:]] == [
        ("location", "float64"), ("angle", "float64"), ("length", "float64")]
    drive = store.fielddefs["ackermann_msgs/msg/AckermannDrive"][1]
    assert [(n, a[0]) for n, (_, a) in drive] == [
        ("steering_angle", "float32"), ("steering_angle_velocity", "float32"), ("speed", "float32"),
        ("acceleration", "float32"), ("jerk", "float32")]
