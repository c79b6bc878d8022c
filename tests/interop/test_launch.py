"""The ROS 2 launch files and the package layout, checked without a ROS installation.

What `ros2 launch dynlab <file>` would do is reproduced here from launch_ros's documented
behaviour, not from ROS code (none is installed):

- every launch/*.launch.xml parses as XML in the `launch_xml` dialect of ROS 2 Jazzy (only the
  elements and attributes we use: `<launch>`, `<arg name default description>`,
  `<node pkg exec name output args if unless>`, `<param name value>`, `<remap from to>`, and the
  substitutions `$(var …)` and `$(find-pkg-share dynlab)`);
- every `exec` is a binary of the workspace (nodes/src/bin/<exec>.rs) and is installed;
- every `<param>` is a parameter its node reads: its name is in the node's source and the node,
  started the way launch_ros (Jazzy) starts it (`<exec> [args] --ros-args -r __node:=<name>
  --params-file <file with /**: ros__parameters:> -r <name>:from:=to`, values typed as YAML), prints no
  "unknown parameter" warning and does not fail on a value (nodes without a required argument
  run until stopped);
- every remap's target is a topic of the topic contract (the table in README.md);
- launch_scripts/install_ros.sh lays out PREFIX/lib/dynlab/<bin>, PREFIX/share/dynlab/{launch,
  package.xml}, PREFIX/share/ament_index/resource_index/packages/dynlab, and with PREFIX/setup.sh
  sourced the ament index lookup that `ros2 launch` and `ros2 run` use finds the package, its
  launch files, the files they name and the executables;
- package.xml is format 3, names `dynlab`, and agrees with the workspace's version and license;
- racer.launch.xml as a whole (sim_node, racer, recorder from the prefix, a model fitted here):
  a Cyclone DDS peer sees the racer accelerate and rosbags reads the recorded bag.

Not checked (needs ROS): `ros2 launch` itself, `colcon build` of CMakeLists.txt.
"""
from __future__ import annotations

import os
import pathlib
import re
import shlex
import shutil
import signal
import subprocess
import time
import xml.etree.ElementTree as ET

import pytest

from conftest import REPO, bin_dir

DOMAIN = 93
LAUNCH_DIR = REPO / "launch"
LAUNCH_FILES = sorted(LAUNCH_DIR.glob("*.launch.xml"))

ALLOWED = {
    "arg": {"name", "default", "description"},
    "node": {"pkg", "exec", "name", "output", "args", "if", "unless"},
    "param": {"name", "value"},
    "remap": {"from", "to"},
}
# read by every node: dynlab_ros's node clock follows /clock when it is true
COMMON_PARAMS = {"use_sim_time"}


def contract_topics() -> set[str]:
    """The topic contract: the topics of README.md's topic table."""
    topics = set(re.findall(r"^\| `(/[^`]+)` \|", (REPO / "README.md").read_text(), re.M))
    assert "/car/pose" in topics and "/push/block_pose" in topics, "topic table not found in README.md"
    return topics


def yaml_scalar(text: str):
    """A parameter value typed as launch_ros types it (YAML 1.1 scalars, as PyYAML reads them)."""
    if text in ("true", "True", "TRUE", "yes", "Yes", "on", "On"):
        return True
    if text in ("false", "False", "FALSE", "no", "No", "off", "Off"):
        return False
    if re.fullmatch(r"[-+]?(0|[1-9][0-9_]*)", text):
        return int(text.replace("_", ""))
    if re.fullmatch(r"[-+]?([0-9][0-9_]*)?\.[0-9_]*([eE][-+][0-9]+)?", text) and text not in (".", "+.", "-."):
        return float(text.replace("_", ""))
    return text


def yaml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'


class Launch:
    """One launch file, with its arguments resolved (defaults, `given`, or a placeholder for a
    required argument) and `$(find-pkg-share dynlab)` pointing at `share`."""

    def __init__(self, path: pathlib.Path, share: pathlib.Path, given: dict[str, str]):
        self.path = path
        self.root = ET.parse(path).getroot()
        assert self.root.tag == "launch", f"{path.name}: root element <{self.root.tag}>, want <launch>"
        self.share = share
        self.args: dict[str, str] = {}
        self.required: set[str] = set()
        for el in self.root.iter():
            if el.tag == "launch":
                continue
            assert el.tag in ALLOWED, f"{path.name}: element <{el.tag}> is not used by our launch files"
            extra = set(el.attrib) - ALLOWED[el.tag]
            assert not extra, f"{path.name}: <{el.tag}> attributes {extra} (allowed: {ALLOWED[el.tag]})"
        for el in self.root:
            assert el.tag in ("arg", "node"), f"{path.name}: <{el.tag}> at the top level"
        for el in self.root.findall("arg"):
            name = el.get("name")
            assert name and re.fullmatch(r"[a-z_][a-z0-9_]*", name), f"{path.name}: arg name {name!r}"
            assert el.get("description"), f"{path.name}: arg {name} has no description"
            if el.get("default") is None:
                self.required.add(name)
                self.args[name] = given.get(name, f"/nonexistent/required_{name}")
            else:
                self.args[name] = given.get(name, self.sub(el.get("default")))

    def sub(self, text: str) -> str:
        """Performs the substitutions launch_xml would."""
        def one(m):
            kind, _, rest = m.group(1).partition(" ")
            if kind == "var":
                assert rest in self.args, f"{self.path.name}: $(var {rest}) before or without <arg name=\"{rest}\">"
                return self.args[rest]
            if kind == "find-pkg-share":
                assert rest == "dynlab", f"{self.path.name}: $(find-pkg-share {rest}): only our own package"
                return str(self.share)
            raise AssertionError(f"{self.path.name}: substitution $({m.group(1)}) not supported here")
        return re.sub(r"\$\(([^)]*)\)", one, text)

    def uses_required(self, text: str) -> bool:
        return any(f"$(var {r})" in text for r in self.required)

    def nodes(self):
        """(element, condition holds) for every node."""
        for el in self.root.findall("node"):
            active = True
            if el.get("if") is not None:
                active = yaml_scalar(self.sub(el.get("if"))) is True
            if el.get("unless") is not None:
                active = yaml_scalar(self.sub(el.get("unless"))) is not True
            yield el, active


def test_there_is_a_launch_file_for_each_main_setup():
    names = {p.name for p in LAUNCH_FILES}
    assert {"sim_record.launch.xml", "push_mppi.launch.xml", "racer.launch.xml",
            "model_server.launch.xml"} <= names, names


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_names_our_binaries_their_parameters_and_contract_topics(path):
    share = REPO / "tests" / "never"  # paths are checked against the install in the test below
    launch = Launch(path, share, {})
    topics = contract_topics()
    for el, _ in launch.nodes():
        assert el.get("pkg") == "dynlab", f"{path.name}: pkg {el.get('pkg')!r}"
        exe = el.get("exec")
        src = REPO / "nodes" / "src" / "bin" / f"{exe}.rs"
        assert src.exists(), f"{path.name}: exec {exe!r} is not a binary of the workspace (no {src})"
        assert el.get("name"), f"{path.name}: node {exe} has no name"
        source = src.read_text()
        for p in el.findall("param"):
            name = p.get("name")
            assert name in COMMON_PARAMS or f'"{name}"' in source, \
                f"{path.name}: {exe} does not read parameter {name!r} (not named in {src.name})"
            value = launch.sub(p.get("value", ""))
            assert value != "", f"{path.name}: {exe} parameter {name} is empty (launch_ros cannot type it)"
        for r in el.findall("remap"):
            to = launch.sub(r.get("to"))
            assert to in topics, f"{path.name}: {exe} remaps {r.get('from')} to {to}, not a topic of the contract {sorted(topics)}"


@pytest.fixture(scope="module")
def prefix(tmp_path_factory):
    """launch_scripts/install_ros.sh into a fresh prefix, from the binaries under test."""
    prefix = tmp_path_factory.mktemp("ros_prefix")
    env = dict(os.environ, DYNLAB_BIN_DIR=str(bin_dir()))
    proc = subprocess.run(["bash", str(REPO / "launch_scripts" / "install_ros.sh"), str(prefix), "--no-build"],
                          capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 0, proc.stderr
    yield prefix
    shutil.rmtree(prefix, ignore_errors=True)  # ≈ 0.7 GB of binaries with debug info


def ament_lookup(prefix: pathlib.Path, package: str) -> pathlib.Path | None:
    """ament_index_python's get_package_prefix: the first prefix on AMENT_PREFIX_PATH (after
    sourcing PREFIX/setup.sh) holding the package's marker."""
    out = subprocess.run(["sh", "-c", f'AMENT_PREFIX_PATH=/opt/elsewhere; . "{prefix}/setup.sh"; . "{prefix}/setup.sh"; '
                          'printf %s "$AMENT_PREFIX_PATH"'], capture_output=True, text=True, check=True).stdout
    parts = out.split(":")
    assert parts == [str(prefix), "/opt/elsewhere"], f"AMENT_PREFIX_PATH={out} (sourced twice)"
    for p in parts:
        if (pathlib.Path(p) / "share" / "ament_index" / "resource_index" / "packages" / package).is_file():
            return pathlib.Path(p)
    return None


def test_the_install_script_lays_out_a_ros_prefix(prefix):
    found = ament_lookup(prefix, "dynlab")
    assert found == prefix, "ament index marker share/ament_index/resource_index/packages/dynlab missing"
    assert (prefix / "share/ament_index/resource_index/packages/dynlab").read_text() == ""
    share = prefix / "share" / "dynlab"
    assert (share / "package.xml").read_bytes() == (REPO / "package.xml").read_bytes()
    for src in (REPO / "nodes" / "src" / "bin").glob("*.rs"):
        exe = prefix / "lib" / "dynlab" / src.stem
        assert exe.is_file() and os.access(exe, os.X_OK), f"{exe} not installed"
        assert exe.read_bytes() == (bin_dir() / src.stem).read_bytes()
    for lf in LAUNCH_FILES:
        # `ros2 launch dynlab <file>` looks for the file name under the package's share directory
        hits = list(share.rglob(lf.name))
        assert hits == [share / "launch" / lf.name], hits
        assert hits[0].read_bytes() == lf.read_bytes()


def test_package_xml_is_format_3_and_agrees_with_the_workspace():
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "dynlab"
    assert root.findtext("export/build_type") == "ament_cmake"
    assert root.findtext("buildtool_depend") == "ament_cmake"
    assert root.find("maintainer").get("email")
    cargo = (REPO / "Cargo.toml").read_text()
    version = re.search(r'^\[workspace\.package\][^\[]*?^version = "([^"]+)"', cargo, re.M | re.S).group(1)
    license_ = re.search(r'^\[workspace\.package\][^\[]*?^license = "([^"]+)"', cargo, re.M | re.S).group(1)
    assert root.findtext("version") == version
    assert root.findtext("license") == license_
    cmake = (REPO / "CMakeLists.txt").read_text()
    assert "project(dynlab" in cmake and "ament_package()" in cmake
    assert "DESTINATION lib/${PROJECT_NAME}" in cmake and "share/${PROJECT_NAME}/launch" in cmake


def launch_ros_command(exe: pathlib.Path, el, launch: Launch, params_file: pathlib.Path) -> list[str]:
    """The command line launch_ros builds for a <node>."""
    cmd = [str(exe)] + shlex.split(launch.sub(el.get("args", "")))
    cmd += ["--ros-args", "-r", f"__node:={el.get('name')}"]
    if el.findall("param"):
        cmd += ["--params-file", str(params_file)]
    for r in el.findall("remap"):
        # launch_ros writes node-specific rules, prefixed with the node's name
        cmd += ["-r", f"{el.get('name')}:{launch.sub(r.get('from'))}:={launch.sub(r.get('to'))}"]
    return cmd


def start_launch(launch: Launch, prefix: pathlib.Path, tmp_path: pathlib.Path, domain: int) -> list:
    """Starts every node of `launch` from the installed `prefix` as launch_ros would (both
    branches of an if/unless pair: each is checked); returns (element, whether it got a required
    argument, process, log file) for each."""
    share = prefix / "share" / "dynlab"
    procs = []
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    for i, (el, _) in enumerate(launch.nodes()):
        exe = prefix / "lib" / "dynlab" / el.get("exec")
        assert exe.is_file(), f"{exe} not installed"
        params = {p.get("name"): yaml_scalar(launch.sub(p.get("value"))) for p in el.findall("param")}
        for name, v in params.items():
            if isinstance(v, str) and str(share) in v:
                assert pathlib.Path(v).exists(), f"{launch.path.name}: {name} = {v} not installed"
        pf = tmp_path / f"launch_params_{i}"
        pf.write_text("/**:\n  ros__parameters:\n" +
                      "".join(f"    {k}: {yaml_value(v)}\n" for k, v in params.items()))
        needs_required = any(launch.uses_required(p.get("value")) for p in el.findall("param")) \
            or launch.uses_required(el.get("args", ""))
        log = tmp_path / f"node_{i}.log"
        with open(log, "w") as f:
            proc = subprocess.Popen(launch_ros_command(exe, el, launch, pf), env=env, cwd=tmp_path,
                                    stdout=subprocess.DEVNULL, stderr=f, text=True)
        procs.append((el, needs_required, proc, log))
    return procs


def stop_launch(procs, first: str | None = None) -> list:
    """SIGINT to every node (`first` before the others) and their (element, needs_required, exit
    code, log text)."""
    order = sorted(procs, key=lambda p: p[0].get("exec") != first)
    results = []
    for el, needs_required, proc, log in order:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        results.append((el, needs_required, proc.returncode, log.read_text()))
    return results


def plain(text: str) -> str:
    return re.sub(r"\x1b\[[0-9;]*m", "", text)  # colours off


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_each_node_starts_as_launch_ros_would_start_it_and_knows_its_parameters(path, prefix, tmp_path):
    share = prefix / "share" / "dynlab"
    # a bag to record into, or to play (model_server.launch.xml)
    given = {"bag": str(REPO / "bags" / "car_nominal" if path.name.startswith("model_server")
                        else tmp_path / "bag")}
    launch = Launch(path, share, given)
    procs = []
    try:
        procs = start_launch(launch, prefix, tmp_path, DOMAIN)
        # until each node has failed or logged its first line of its own (after the parameter
        # check: the unknown-parameter warnings come first)
        deadline = time.monotonic() + 30

        def settled(el, proc, log):
            return proc.poll() is not None or re.search(rf" {el.get('exec')}: ", plain(log.read_text()))
        while time.monotonic() < deadline and not all(settled(e, p, lg) for e, _, p, lg in procs):
            time.sleep(0.1)
        for el, _, proc, log in procs:
            assert settled(el, proc, log), f"{path.name}: {el.get('exec')} logged nothing in 30 s:\n{log.read_text()}"
    finally:
        results = stop_launch(procs)
    for el, needs_required, rc, err in results:
        who = f"{path.name}: {el.get('exec')} ({el.get('name')})"
        assert "unknown parameter" not in err, f"{who}:\n{err[-2000:]}"
        if not needs_required:
            assert rc == 0, f"{who} exited {rc}:\n{err[-2000:]}"
        else:
            # the placeholder of a required argument is what it may fail on, nothing else
            assert rc == 0 or "/nonexistent/required_" in err, f"{who} exited {rc}:\n{err[-2000:]}"


def test_racer_launch_races_the_simulated_car_and_records_the_run(prefix, tmp_path):
    """racer.launch.xml as a whole, from the installed prefix: a Cyclone DDS peer sees the racer
    accelerate, and rosbags reads the recorder's bag."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration
    from peers.ros_types import AckermannDriveStamped, Peer, wait_matched
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from conftest import run

    model = tmp_path / "model"
    run("dynlab", "train", "--bag", REPO / "bags" / "car_nominal", "--kind", "physics",
        "--steps", 1, "--physics-windows", 300, "--out", model, "--quiet", timeout=180)
    bag = tmp_path / "race_bag"
    launch = Launch(LAUNCH_DIR / "racer.launch.xml", prefix / "share" / "dynlab",
                    {"model": str(model), "bag": str(bag), "sim_rate": "0.2"})
    peer = Peer(DOMAIN + 1)
    cmds = peer.reader("/car/cmd", AckermannDriveStamped,
                       Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000)))
    procs = []
    got = []
    try:
        procs = start_launch(launch, prefix, tmp_path, DOMAIN + 1)
        assert wait_matched(cmds, timeout=30), "racer did not publish /car/cmd"
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and sum(c.drive.acceleration > 0 for c in got) < 20:
            got += [c for c in cmds.take(N=1000) if type(c).__name__ != "InvalidSample"]
            time.sleep(0.05)
            assert all(p.poll() is None for _, _, p, _ in procs), "a node exited"
    finally:
        results = stop_launch(procs, first="recorder")
    logs = "\n".join(f"{el.get('exec')}: {err[-1500:]}" for el, _, _, err in results)
    assert sum(c.drive.acceleration > 0 for c in got) >= 20, logs
    for el, _, rc, err in results:
        assert rc == 0, f"{el.get('exec')} exited {rc}\n{err[-2000:]}"
    store = get_typestore(Stores.ROS2_JAZZY)
    counts, throttles = {}, []
    with Reader(bag) as reader:
        for conn in reader.connections:
            if conn.msgtype not in store.types:
                store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        for conn, _, raw in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic == "/car/cmd":
                throttles.append(store.deserialize_cdr(raw, conn.msgtype).drive.acceleration)
    assert {"/car/pose", "/car/cmd", "/car/odom", "/clock"} <= set(counts), counts
    assert sum(t > 0 for t in throttles) >= 20, throttles
