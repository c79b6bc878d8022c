"""Our nodes as ROS 2 citizens, checked by an independent peer (Eclipse Cyclone DDS, Python):

- the parameter services (`rcl_interfaces/srv/*` on `rq/<node>/<service>Request` and
  `rr/<node>/<service>Reply`) list, get, describe and set parameters, refuse bad sets with a
  reason, and accepted sets appear on `/parameter_events` and reach the node loop;
- `ros_discovery_info` (`rmw_dds_common/msg/ParticipantEntitiesInfo`) names the node and the
  GIDs of its readers and writers, as DDS discovery (DCPSPublication/DCPSSubscription) sees them;
- `/rosout` (`rcl_interfaces/msg/Log`) carries the node's log lines under its name;
- SIGINT stops a node without an ERROR line on stderr.

The peer speaks the service protocol as a plain DDS client: it writes a request and takes the
reply (one request at a time, so no correlation is needed). The message classes are written here
from the rcl_interfaces and rmw_dds_common definitions of ROS 2 Jazzy.
"""

import re
import signal
import time
from dataclasses import dataclass, field

import cyclonedds.idl.annotations as annotate
import pytest
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
from cyclonedds.core import Policy, Qos
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int64, sequence, uint8, uint32, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from conftest import run, start, stop
from peers.ros_types import Header, Point, Pose, PoseStamped, Time, wait_matched

# --- rcl_interfaces ---------------------------------------------------------------------------


@dataclass
@annotate.final
class ParameterValue(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterValue_"):
    type: uint8 = 0
    bool_value: bool = False
    integer_value: int64 = 0
    double_value: float64 = 0.0
    string_value: str = ""
    byte_array_value: sequence[uint8] = field(default_factory=list)
    bool_array_value: sequence[bool] = field(default_factory=list)
    integer_array_value: sequence[int64] = field(default_factory=list)
    double_array_value: sequence[float64] = field(default_factory=list)
    string_array_value: sequence[str] = field(default_factory=list)


NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4


@dataclass
@annotate.final
class Parameter(IdlStruct, typename="rcl_interfaces::msg::dds_::Parameter_"):
    name: str = ""
    value: ParameterValue = field(default_factory=ParameterValue)


@dataclass
@annotate.final
class SetParametersResult(IdlStruct, typename="rcl_interfaces::msg::dds_::SetParametersResult_"):
    successful: bool = False
    reason: str = ""


@dataclass
@annotate.final
class FloatingPointRange(IdlStruct, typename="rcl_interfaces::msg::dds_::FloatingPointRange_"):
    from_value: float64 = 0.0
    to_value: float64 = 0.0
    step: float64 = 0.0


@dataclass
@annotate.final
class IntegerRange(IdlStruct, typename="rcl_interfaces::msg::dds_::IntegerRange_"):
    from_value: int64 = 0
    to_value: int64 = 0
    step: uint64 = 0


@dataclass
@annotate.final
class ParameterDescriptor(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterDescriptor_"):
    name: str = ""
    type: uint8 = 0
    description: str = ""
    additional_constraints: str = ""
    read_only: bool = False
    dynamic_typing: bool = False
    floating_point_range: sequence[FloatingPointRange, 1] = field(default_factory=list)
    integer_range: sequence[IntegerRange, 1] = field(default_factory=list)


@dataclass
@annotate.final
class ParameterEvent(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterEvent_"):
    stamp: Time = field(default_factory=Time)
    node: str = ""
    new_parameters: sequence[Parameter] = field(default_factory=list)
    changed_parameters: sequence[Parameter] = field(default_factory=list)
    deleted_parameters: sequence[Parameter] = field(default_factory=list)


@dataclass
@annotate.final
class Log(IdlStruct, typename="rcl_interfaces::msg::dds_::Log_"):
    stamp: Time = field(default_factory=Time)
    level: uint8 = 0
    name: str = ""
    msg: str = ""
    file: str = ""
    function: str = ""
    line: uint32 = 0


@dataclass
@annotate.final
class ListParametersResult(IdlStruct, typename="rcl_interfaces::msg::dds_::ListParametersResult_"):
    names: sequence[str] = field(default_factory=list)
    prefixes: sequence[str] = field(default_factory=list)


@dataclass
@annotate.final
class ListParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Request_"):
    prefixes: sequence[str] = field(default_factory=list)
    depth: uint64 = 0


@dataclass
@annotate.final
class ListParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::ListParameters_Response_"):
    result: ListParametersResult = field(default_factory=ListParametersResult)


@dataclass
@annotate.final
class GetParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Request_"):
    names: sequence[str] = field(default_factory=list)


@dataclass
@annotate.final
class GetParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameters_Response_"):
    values: sequence[ParameterValue] = field(default_factory=list)


@dataclass
@annotate.final
class GetParameterTypesRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameterTypes_Request_"):
    names: sequence[str] = field(default_factory=list)


@dataclass
@annotate.final
class GetParameterTypesResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::GetParameterTypes_Response_"):
    types: sequence[uint8] = field(default_factory=list)


@dataclass
@annotate.final
class SetParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::SetParameters_Request_"):
    parameters: sequence[Parameter] = field(default_factory=list)


@dataclass
@annotate.final
class SetParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::SetParameters_Response_"):
    results: sequence[SetParametersResult] = field(default_factory=list)


@dataclass
@annotate.final
class SetParametersAtomicallyRequest(IdlStruct,
                                     typename="rcl_interfaces::srv::dds_::SetParametersAtomically_Request_"):
    parameters: sequence[Parameter] = field(default_factory=list)


@dataclass
@annotate.final
class SetParametersAtomicallyResponse(IdlStruct,
                                      typename="rcl_interfaces::srv::dds_::SetParametersAtomically_Response_"):
    result: SetParametersResult = field(default_factory=SetParametersResult)


@dataclass
@annotate.final
class DescribeParametersRequest(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Request_"):
    names: sequence[str] = field(default_factory=list)


@dataclass
@annotate.final
class DescribeParametersResponse(IdlStruct, typename="rcl_interfaces::srv::dds_::DescribeParameters_Response_"):
    descriptors: sequence[ParameterDescriptor] = field(default_factory=list)


# --- rmw_dds_common ---------------------------------------------------------------------------


@dataclass
@annotate.final
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, 16] = field(default_factory=lambda: [0] * 16)


@dataclass
@annotate.final
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: str = ""
    node_name: str = ""
    reader_gid_seq: sequence[Gid] = field(default_factory=list)
    writer_gid_seq: sequence[Gid] = field(default_factory=list)


@dataclass
@annotate.final
class ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: Gid = field(default_factory=Gid)
    node_entities_info_seq: sequence[NodeEntitiesInfo] = field(default_factory=list)


# --- the peer ---------------------------------------------------------------------------------

# rmw_qos_profile_services_default; rmw_qos_profile_parameter_events; rcl's /rosout and
# ros_discovery_info profiles.
SERVICES = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10),
               Policy.Durability.Volatile)
EVENTS = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000),
             Policy.Durability.Volatile)
LATCHED = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000),
              Policy.Durability.TransientLocal)
DISCOVERY = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
                Policy.Durability.TransientLocal)


class ParamClient:
    """Calls a node's parameter services the way a ROS 2 client does, over plain DDS."""

    SERVICES = {
        "list_parameters": (ListParametersRequest, ListParametersResponse, "ListParameters"),
        "get_parameters": (GetParametersRequest, GetParametersResponse, "GetParameters"),
        "get_parameter_types": (GetParameterTypesRequest, GetParameterTypesResponse, "GetParameterTypes"),
        "set_parameters": (SetParametersRequest, SetParametersResponse, "SetParameters"),
        "set_parameters_atomically": (SetParametersAtomicallyRequest, SetParametersAtomicallyResponse,
                                      "SetParametersAtomically"),
        "describe_parameters": (DescribeParametersRequest, DescribeParametersResponse, "DescribeParameters"),
    }

    def __init__(self, dp, node: str):
        self.ends = {}
        for service, (req, resp, _) in self.SERVICES.items():
            w = DataWriter(dp, Topic(dp, f"rq{node}/{service}Request", req), qos=SERVICES)
            r = DataReader(dp, Topic(dp, f"rr{node}/{service}Reply", resp), qos=SERVICES)
            self.ends[service] = (w, r)

    def wait_ready(self, timeout=30.0):
        for service, (w, r) in self.ends.items():
            assert wait_matched(w, timeout), f"no server for {service}"
            assert wait_matched(r, timeout), f"no replies from {service}"

    def call(self, service: str, request, timeout=10.0):
        w, r = self.ends[service]
        r.take(N=100)  # nothing stale
        w.write(request)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = [s for s in r.take(N=10) if type(s).__name__ != "InvalidSample"]
            if got:
                assert len(got) == 1, got
                return got[0]
            time.sleep(0.005)
        pytest.fail(f"no reply from {service} within {timeout} s")


def double(v: float) -> ParameterValue:
    return ParameterValue(type=DOUBLE, double_value=v)


def integer(v: int) -> ParameterValue:
    return ParameterValue(type=INTEGER, integer_value=v)


def string(v: str) -> ParameterValue:
    return ParameterValue(type=STRING, string_value=v)


def take_all(reader, timeout: float, until=lambda got: False) -> list:
    got = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got.extend(s for s in reader.take(N=100) if type(s).__name__ != "InvalidSample")
        if until(got):
            break
        time.sleep(0.01)
    return got


def guid_bytes(key) -> bytes:
    """The 16 GUID bytes of a DCPS builtin-topic key."""
    return bytes(key.bytes) if hasattr(key, "bytes") else bytes(key)


@pytest.fixture(scope="module")
def pusher_model(tmp_path_factory):
    """A pushing model (the nominal physics fitted on a short simulated bag)."""
    d = tmp_path_factory.mktemp("model")
    explore = d / "explore.toml"
    explore.write_text("pose_rate = 0.5\n")
    run("dynlab", "collect", "push", "--explore", explore, "--episodes", 20, "--seed", 3,
        "--episode-gap", 30, "--out", d / "bag", timeout=120)
    run("dynlab", "train", "--bag", d / "bag", "--kind", "physics", "--steps", 1, "--out", d / "model",
        "--quiet", timeout=120)
    return d / "model"


def test_sim_node_discovery_info_lists_its_topics_and_rosout_carries_its_log(tmp_path):
    domain = 61
    from cyclonedds.domain import DomainParticipant
    dp = DomainParticipant(domain)
    disc = DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo), qos=DISCOVERY)
    rosout = DataReader(dp, Topic(dp, "rt/rosout", Log), qos=LATCHED)
    pubs = BuiltinDataReader(dp, BuiltinTopicDcpsPublication)
    subs = BuiltinDataReader(dp, BuiltinTopicDcpsSubscription)
    sim = start("sim_node", "--ros-args", "-r", "__node:=sim_citizen", "-p", "rate:=5.0", domain=domain)
    try:
        want_w = ["rt/push/block_pose", "rt/clock", "rt/rosout", "rt/parameter_events",
                  "rr/sim_citizen/set_parametersReply"]
        want_r = ["rt/push/action", "rq/sim_citizen/set_parametersRequest",
                  "rq/sim_citizen/list_parametersRequest"]
        # The node announces its entities as it creates them, so early samples list only some:
        # read until its latest sample lists every expected endpoint (or the time is up).
        nodes, topics_w, topics_r = [], {}, {}
        node_w, node_r = set(), set()
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            nodes += [(s, n) for s in disc.take(N=100) if type(s).__name__ != "InvalidSample"
                      for n in s.node_entities_info_seq if n.node_name == "sim_citizen"]
            topics_w.update({guid_bytes(p.key): p.topic_name for p in pubs.take(N=1000)
                             if type(p).__name__ != "InvalidSample"})
            topics_r.update({guid_bytes(p.key): p.topic_name for p in subs.take(N=1000)
                             if type(p).__name__ != "InvalidSample"})
            if nodes:
                node_w = {topics_w.get(bytes(g.data)) for g in nodes[-1][1].writer_gid_seq}
                node_r = {topics_r.get(bytes(g.data)) for g in nodes[-1][1].reader_gid_seq}
                if set(want_w) <= node_w and set(want_r) <= node_r:
                    break
            time.sleep(0.05)
        assert nodes, "sim_citizen not in ros_discovery_info"
        part, node = nodes[-1]
        assert node.node_namespace == "/"
        writers = {bytes(g.data) for g in node.writer_gid_seq}
        readers = {bytes(g.data) for g in node.reader_gid_seq}
        # every writer and reader GID of the node is a DDS endpoint of its participant
        prefix = bytes(part.gid.data)[:12]
        assert all(g[:12] == prefix for g in writers | readers)
        for t in want_w:
            assert t in node_w, f"{t} not among the node's writers: {sorted(map(str, node_w))}"
        for t in want_r:
            assert t in node_r, f"{t} not among the node's readers: {sorted(map(str, node_r))}"

        # a log line from the node itself, as the node logs it to stderr: its start line
        logs = take_all(rosout, 10, until=lambda got: any(l.name == "sim_citizen" for l in got))
        mine = [l for l in logs if l.name == "sim_citizen"]
        assert mine, f"no /rosout line from sim_citizen: {logs}"
        assert any("push world" in l.msg and l.level == 20 for l in mine), [l.msg for l in mine]
        assert all(l.level in (20, 30, 40) and l.stamp.sec > 1_600_000_000 for l in mine)
    finally:
        err = stop(sim, signal.SIGINT)
    assert not re.search(r"\bERROR\b", err), err


def values_of(resp) -> list:
    out = []
    for v in resp.values:
        out.append({NOT_SET: None, INTEGER: v.integer_value, DOUBLE: v.double_value,
                    STRING: v.string_value, BOOL: v.bool_value}.get(v.type, ("type", v.type)))
    return out


def test_mppi_pusher_parameters_list_get_describe_set_and_events(pusher_model):
    from cyclonedds.domain import DomainParticipant
    domain = 62
    dp = DomainParticipant(domain)
    events = DataReader(dp, Topic(dp, "rt/parameter_events", ParameterEvent), qos=EVENTS)
    rosout = DataReader(dp, Topic(dp, "rt/rosout", Log), qos=LATCHED)
    client = ParamClient(dp, "/mppi_pusher")
    pusher = start("mppi_pusher", "--ros-args", "-p", f"model:={pusher_model}", "-p", "samples:=64",
                   "-p", "horizon:=4", domain=domain)
    try:
        client.wait_ready()
        assert wait_matched(events), "no /parameter_events publisher"

        # list: the run-time parameters, what the node read at start (given or default), use_sim_time
        names = client.call("list_parameters", ListParametersRequest()).result.names
        for n in ["goal", "goal_tolerance", "angle_tolerance", "lambda", "model", "samples", "horizon",
                  "stale_timeout", "push_wait", "use_sim_time"]:
            assert n in names, f"{n} not listed: {names}"
        assert list(names) == sorted(names)

        got = client.call("get_parameters", GetParametersRequest(
            names=["goal_tolerance", "samples", "model", "push_wait", "not_a_parameter"]))
        assert values_of(got) == [0.02, 64, str(pusher_model), 1.8, None]
        types = client.call("get_parameter_types", GetParameterTypesRequest(
            names=["goal_tolerance", "samples", "goal", "not_a_parameter"])).types
        assert list(types) == [DOUBLE, INTEGER, STRING, NOT_SET]

        desc = client.call("describe_parameters", DescribeParametersRequest(
            names=["goal_tolerance", "samples"])).descriptors
        assert desc[0].name == "goal_tolerance" and desc[0].type == DOUBLE and not desc[0].read_only
        assert [(r.from_value, r.to_value) for r in desc[0].floating_point_range] == [(0.0, 10.0)]
        assert "xy distance" in desc[0].description
        assert desc[1].read_only and desc[1].type == INTEGER
        assert "-p samples:=value" in desc[1].description

        # set: each entry on its own, refusals with their reason
        res = client.call("set_parameters", SetParametersRequest(parameters=[
            Parameter("goal_tolerance", double(0.05)),
            Parameter("samples", integer(128)),
            Parameter("angle_tolerance", double(-1.0)),
            Parameter("goal", string("0.6,0.05")),
            Parameter("lambda", string("hot")),
            Parameter("not_a_parameter", double(1.0)),
        ])).results
        assert [r.successful for r in res] == [True, False, False, False, False, False], res
        assert res[1].reason.startswith("read-only: restart the node with -p samples:=value")
        assert res[2].reason == "`angle_tolerance`: -1 is not a finite angle ≥ 0 rad"
        assert "x,y,θ" in res[3].reason
        assert "wrong type" in res[4].reason and "double" in res[4].reason
        assert "not declared by /mppi_pusher" in res[5].reason
        assert values_of(client.call("get_parameters", GetParametersRequest(
            names=["goal_tolerance", "samples", "angle_tolerance"]))) == [0.05, 64, 0.1]

        ev = take_all(events, 10, until=lambda got: len(got) >= 1)
        assert len(ev) == 1, ev
        assert ev[0].node == "/mppi_pusher" and not ev[0].new_parameters and not ev[0].deleted_parameters
        assert [(p.name, p.value.type, p.value.double_value) for p in ev[0].changed_parameters] == [
            ("goal_tolerance", DOUBLE, 0.05)]

        # atomically: all or nothing
        r = client.call("set_parameters_atomically", SetParametersAtomicallyRequest(parameters=[
            Parameter("goal_tolerance", double(0.03)), Parameter("horizon", integer(9))])).result
        assert not r.successful and "read-only" in r.reason and "horizon" in r.reason
        r = client.call("set_parameters_atomically", SetParametersAtomicallyRequest(parameters=[
            Parameter("goal_tolerance", double(0.03)), Parameter("lambda", integer(2))])).result
        assert r.successful, r.reason
        assert values_of(client.call("get_parameters", GetParametersRequest(
            names=["goal_tolerance", "lambda"]))) == [0.03, 2.0]  # the integer stored as a double

        # a new goal reaches the node loop, which logs it (stderr and /rosout)
        r = client.call("set_parameters", SetParametersRequest(parameters=[
            Parameter("goal", string("0.6,0.05,0"))])).results
        assert r[0].successful, r[0].reason
        line = "goal (0.600, 0.050, 0.000) from the goal parameter"
        logs = take_all(rosout, 10, until=lambda got: any(line in l.msg for l in got))
        assert any(line in l.msg and l.name == "mppi_pusher" and l.level == 20 for l in logs), \
            [l.msg for l in logs]

        # a goal from /push/goal shows in the goal parameter and on /parameter_events
        goals = DataWriter(dp, Topic(dp, "rt/push/goal", PoseStamped), qos=SERVICES)
        assert wait_matched(goals), "mppi_pusher does not subscribe /push/goal"
        take_all(events, 0.2)
        goals.write(PoseStamped(header=Header(frame_id="table"),
                                pose=Pose(position=Point(x=0.5, y=0.1, z=0.0))))
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            (goal,) = values_of(client.call("get_parameters", GetParametersRequest(names=["goal"])))
            if goal == "0.5,0.1,0":
                break
            time.sleep(0.05)
        assert goal == "0.5,0.1,0", goal
        ev = take_all(events, 5, until=lambda got: any(
            p.name == "goal" for e in got for p in e.changed_parameters))
        assert [(p.name, p.value.string_value) for e in ev for p in e.changed_parameters] == [
            ("goal", "0.5,0.1,0")]
        assert pusher.poll() is None, "mppi_pusher exited"
    finally:
        err = stop(pusher, signal.SIGINT)
    assert line in err, err
    assert "parameter goal_tolerance set to 0.05" in err, err
    assert not re.search(r"\bERROR\b", err), err


def test_racer_reference_speed_changes_at_run_time_and_the_rest_is_read_only(tmp_path):
    from cyclonedds.domain import DomainParticipant
    from conftest import REPO
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", REPO / "bags" / "car_nominal", "--kind", "physics",
        "--steps", 1, "--physics-windows", 300, "--out", model, "--quiet", timeout=180)
    domain = 63
    dp = DomainParticipant(domain)
    client = ParamClient(dp, "/racer")
    racer = start("racer", "--ros-args", "-p", f"model:={model}",
                  "-p", f"track:={REPO / 'launch_scripts' / 'tracks' / 'default.json'}", domain=domain)
    try:
        client.wait_ready()
        assert values_of(client.call("get_parameters", GetParametersRequest(
            names=["reference_speed", "horizon", "optimizer"]))) == [2.0, 20, "sqp"]
        res = client.call("set_parameters", SetParametersRequest(parameters=[
            Parameter("reference_speed", double(2.5)),
            Parameter("reference_speed", double(100.0)),
            Parameter("horizon", integer(10)),
        ])).results
        assert [r.successful for r in res] == [True, False, False], res
        assert "outside the range [0.01, 50]" in res[1].reason
        assert res[2].reason.startswith("read-only: restart the node with -p horizon:=value")
        assert values_of(client.call("get_parameters", GetParametersRequest(
            names=["reference_speed"]))) == [2.5]
        time.sleep(0.5)
        assert racer.poll() is None, "racer exited"
    finally:
        err = stop(racer, signal.SIGINT)
    assert "reference speed 2.5 m/s from the next solve" in err, err
    assert not re.search(r"\bERROR\b", err), err


@pytest.mark.parametrize("name,args", [
    ("recorder", ["-o", "{tmp}/bag", "/citizen/pose"]),
    ("player", ["{repo}/bags/push_nominal", "--loop"]),
    ("sim_node", ["--ros-args", "-p", "world:=car"]),
])
def test_sigint_stops_the_node_without_an_error_line(tmp_path, name, args):
    from cyclonedds.domain import DomainParticipant
    from conftest import REPO
    domain = 65
    dp = DomainParticipant(domain)
    disc = DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo), qos=DISCOVERY)
    proc = start(name, *[a.format(tmp=tmp_path, repo=REPO) for a in args], domain=domain)
    try:
        # running, with its node announced: the shutdown below tears down a live participant
        seen = take_all(disc, 20, until=lambda got: any(
            n.node_name == name for s in got for n in s.node_entities_info_seq))
        assert any(n.node_name == name for s in seen for n in s.node_entities_info_seq), seen
    finally:
        err = stop(proc, signal.SIGINT)
    assert not re.search(r"\bERROR\b", err), err
