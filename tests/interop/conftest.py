"""Shared helpers for the interop tests.

The tests drive our release binaries (built by tests/run.sh) and check them against independent
peers: Eclipse Cyclone DDS for DDS, rosbags and mcap-ros2-support for bags.
"""
import os
import pathlib
import signal
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]

# Modules whose tests talk DDS (or read the session's trained model, `car_nominal_model`): run on
# two workers (`pytest -n 2`, tests/run.sh) they form one unit of work, on one worker one after
# another, as two DDS tests at once would see each other's participants. Every other module is a
# unit of its own (its module fixtures are made once), run beside them.
SERIAL = {
    "test_bag_peers", "test_control_checks", "test_dds", "test_launch", "test_model_server",
    "test_mppi_dds", "test_other_data", "test_racer_dds", "test_ros_citizen", "test_sim_dds",
    "test_stale_dds",
}

try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # pytest without workers runs every test in turn
    LoadScopeScheduling = None

if LoadScopeScheduling is not None:

    class SerialDdsScheduling(LoadScopeScheduling):
        """xdist's per-module scheduling with the `SERIAL` modules as one unit."""

        def _split_scope(self, nodeid):
            module = nodeid.split("::", 1)[0]
            return "serial" if pathlib.PurePosixPath(module).stem in SERIAL else module

    def pytest_xdist_make_scheduler(config, log):
        return SerialDdsScheduling(config, log)


def bin_dir() -> pathlib.Path:
    return pathlib.Path(os.environ.get("DYNLAB_BIN_DIR", REPO / "target" / "release"))


def binary(name: str) -> pathlib.Path:
    """Path of one of our release binaries; fails the test with the build command if missing."""
    path = bin_dir() / name
    if not path.exists():
        pytest.fail(f"{path} not built: run `cargo build --release --workspace --bins` (tests/run.sh does)")
    return path


def run(name: str, *args, timeout=60, check=True, **kw) -> subprocess.CompletedProcess:
    """Runs one of our binaries, capturing output; on failure shows its stderr."""
    proc = subprocess.run([str(binary(name)), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, **kw)
    if check and proc.returncode != 0:
        raise AssertionError(f"{name} {' '.join(map(str, args))} exited {proc.returncode}:\n{proc.stderr}")
    return proc


def start(name: str, *args, domain: int, **kw) -> subprocess.Popen:
    """Starts one of our binaries on DDS domain `domain`, capturing its output."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    return subprocess.Popen([str(binary(name)), *map(str, args)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def stop(proc: subprocess.Popen, sig=signal.SIGINT, timeout=20.0, check=True) -> str:
    """Signals a process, waits for it and returns its stderr; with `check`, fails the test when it
    does not exit in time or exits non-zero."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        if check:
            pytest.fail(f"process did not exit {timeout} s after {sig!r}:\n{err}")
    if check:
        assert proc.returncode == 0, f"exit {proc.returncode}:\n{err}"
    return err


@pytest.fixture(scope="session")
def car_nominal_model(tmp_path_factory) -> pathlib.Path:
    """The physics model `dynlab train` fits with its defaults on the bundled nominal car bag,
    trained once for every test that reads it (none writes to it)."""
    out = tmp_path_factory.mktemp("model") / "car_physics"
    run("dynlab", "train", "--bag", REPO / "bags" / "car_nominal", "--kind", "physics", "--out", out,
        timeout=300)
    return out
