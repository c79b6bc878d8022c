"""Cyclone DDS (Python) counterpart of our `dds_probe`: same topics, type, QoS and JSON output.

    cyclone_probe.py pub --topic /probe --rate 1000 --count 3000 [--best-effort] [--keep-all]
    cyclone_probe.py sub --topic /probe --count 3000 [--skip 100] [--best-effort] [--keep-all]

`pub` stamps `header.stamp` with the send time (time.time_ns), `sub` subtracts it from the
receive time; both ends on one host read the same clock.
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests", "interop"))

from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet  # noqa: E402
from cyclonedds.util import duration  # noqa: E402
from peers.ros_types import RELIABLE, SENSOR_DATA, Header, Peer, PoseStamped, Time, wait_matched  # noqa: E402


def qos_for(args):
    if args.best_effort:
        return SENSOR_DATA
    if getattr(args, "keep_all", False):
        return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll)
    return RELIABLE


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="mode", required=True)
    p = sub.add_parser("pub")
    p.add_argument("--topic", default="/probe")
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--count", type=int, default=1000)
    p.add_argument("--best-effort", action="store_true")
    p.add_argument("--keep-all", action="store_true")
    p.add_argument("--wait", type=float, default=10.0)
    s = sub.add_parser("sub")
    s.add_argument("--topic", default="/probe")
    s.add_argument("--count", type=int, default=1000)
    s.add_argument("--idle-timeout", type=float, default=3.0)
    s.add_argument("--best-effort", action="store_true")
    s.add_argument("--skip", type=int, default=0)
    s.add_argument("--keep-all", action="store_true")
    args = ap.parse_args()
    peer = Peer(int(os.environ.get("ROS_DOMAIN_ID", "0")))

    if args.mode == "pub":
        w = peer.writer(args.topic, qos=qos_for(args))
        wait_matched(w, args.wait)
        time.sleep(0.3)
        period = 1.0 / args.rate if args.rate > 0 else 0.0
        msg = PoseStamped()
        start = time.perf_counter()
        for i in range(args.count):
            due = start + i * period
            now = time.perf_counter()
            if due > now:
                time.sleep(due - now)
            sec, nsec = divmod(time.time_ns(), 1_000_000_000)
            msg.header = Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=str(i))
            msg.pose.position.x = float(i)
            w.write(msg)
        elapsed = time.perf_counter() - start
        print(json.dumps({"sent": args.count, "seconds": elapsed}), flush=True)
        w.wait_for_acks(int(2e9))
        time.sleep(0.5)
    else:
        r = peer.reader(args.topic, qos=qos_for(args))
        ws = WaitSet(peer.dp)
        ws.attach(ReadCondition(r, SampleState.Any | ViewState.Any | InstanceState.Any))
        print(json.dumps({"ready": True}), flush=True)
        lat, received, first, last = [], 0, None, time.monotonic()
        while received < args.count:
            batch = r.take(N=1000)
            t = time.time_ns()
            if batch:
                for m in batch:
                    if not isinstance(m, PoseStamped):
                        continue  # InvalidSample: the writer left
                    received += 1
                    if received > args.skip:
                        lat.append(t - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))
                last = time.monotonic()
                first = first or last
            else:
                if first is not None and time.monotonic() - last > args.idle_timeout:
                    break
                ws.wait(duration(milliseconds=50))  # blocks until data arrives
        out = {"received": received, "seconds": (last - first) if first else 0.0}
        if lat:
            us = sorted(x / 1e3 for x in lat)
            rank = lambda q: us[max(1, min(len(us), int(-(-q * len(us) // 1)))) - 1]  # nearest rank
            out.update(p50_us=rank(0.5), p99_us=rank(0.99), max_us=us[-1], mean_us=sum(us) / len(us))
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
