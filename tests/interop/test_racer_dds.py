"""The racer closes the loop over DDS: `sim_node` (car on the default track) and `racer` as
separate processes, and an independent peer (Eclipse Cyclone DDS, Python) that watches /car/cmd
and /car/pose: commands at the control rate of simulation time, each acting a known delay after
its pose, within the input limits, and the car driving along the track without leaving it.

The model is the nominal car physics fitted by `dynlab train --kind physics` on the bundled
bag bags/car_nominal (a few seconds), so the test needs no data outside the repository.
"""
from __future__ import annotations

import sys
import time

from conftest import REPO, run, start, stop
from peers.ros_types import AckermannDriveStamped, Peer, PoseStamped, wait_matched

sys.path.insert(0, str(REPO / "launch_scripts"))
from race_check import load_track, locate  # noqa: E402

DOMAIN = 58






def stamp(m) -> float:
    return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec


def test_racer_drives_the_simulated_car_along_the_track_over_dds(tmp_path):
    model = tmp_path / "model"
    run("dynlab", "train", "--bag", REPO / "bags" / "car_nominal", "--kind", "physics",
        "--steps", 1, "--physics-windows", 300, "--out", model, "--quiet", timeout=180)
    track_file = REPO / "launch_scripts" / "tracks" / "default.json"
    scenario = REPO / "launch_scripts" / "scenarios" / "car_track.toml"
    peer = Peer(DOMAIN)
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration
    cmd_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000))
    pose_qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000))
    cmds = peer.reader("/car/cmd", AckermannDriveStamped, cmd_qos)
    poses = peer.reader("/car/pose", PoseStamped, pose_qos)
    racer = start("racer", "--ros-args", "-p", f"model:={model}", "-p", f"track:={track_file}",
                  "-p", "use_sim_time:=true", domain=DOMAIN)
    time.sleep(1.0)
    sim = start("sim_node", "--ros-args", "-p", "world:=car", "-p", f"scenario:={scenario}",
                "-p", "rate:=0.2", domain=DOMAIN)
    got_cmds, got_poses = [], []
    try:
        assert wait_matched(cmds, timeout=30), "racer did not publish /car/cmd"
        deadline = time.monotonic() + 20  # ≈ 4 s of simulation time
        while time.monotonic() < deadline:
            got_cmds += cmds.take(N=1000)
            got_poses += poses.take(N=1000)
            time.sleep(0.05)
    finally:
        sim_err = stop(sim, check=False)
        racer_err = stop(racer, check=False)
    assert len(got_cmds) >= 40, f"{len(got_cmds)} commands\nracer: {racer_err[-2000:]}\nsim: {sim_err[-1000:]}"
    ts = sorted(stamp(c) for c in got_cmds)
    gaps = sorted(b - a for a, b in zip(ts, ts[1:]))
    assert abs(gaps[len(gaps) // 2] - 0.05) < 1e-6, f"median command period {gaps[len(gaps) // 2]}"
    # stamped with simulation time (the 10 ms tick grid), not wall time
    assert all(abs(t * 100 - round(t * 100)) < 1e-4 for t in ts), ts[:10]
    for c in got_cmds:
        assert abs(c.drive.steering_angle) <= 0.35 + 1e-6
        assert -0.1 - 1e-6 <= c.drive.acceleration <= 1.0 + 1e-6
    assert got_cmds[0].drive.acceleration > 0.0, "the racer starts by accelerating"
    # the car drives along the track and stays on it (measured poses, noise ≈ 0.5 mm)
    track = load_track(track_file)
    got_poses.sort(key=stamp)
    assert len(got_poses) > 200, f"{len(got_poses)} poses"
    start_arc = locate(track, (got_poses[0].pose.position.x, got_poses[0].pose.position.y))[0]
    travelled, last = 0.0, start_arc
    length = track[2][-1]
    for p in got_poses:
        arc, lat, half = locate(track, (p.pose.position.x, p.pose.position.y))
        assert abs(lat) < half, f"off the track at t = {stamp(p):.2f} s: lateral {lat:.3f} m"
        d = arc - last
        d -= length * round(d / length)
        travelled += d
        last = arc
    assert travelled > 3.0, f"only {travelled:.2f} m along the track in {stamp(got_poses[-1]):.1f} s"
