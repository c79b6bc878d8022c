"""DDS benchmarks: our node runtime (ros2-client / RustDDS) beside Eclipse Cyclone DDS, same run.

    DYNLAB_BIN_DIR=target/release .venv/bin/python benches/dds/bench.py [--quick]

1. Publish → receive latency of `PoseStamped` on loopback at 100 Hz and 1 kHz (reliable QoS),
   p50 / p99 over the messages after a warm-up: ours → ours (`dds_probe`), Cyclone → Cyclone
   (`cyclone_probe.py`, Cyclone's Python API), and the two mixed.
2. Recorder throughput: a Cyclone publisher (reliable, keep all) sends `PoseStamped` at a fixed
   rate or as fast as it can; our `recorder` writes them to a bag, and beside it a Cyclone
   subscriber only counts them. Sustained = every message arrived.

Prints markdown tables. Needs the release binaries (`cargo build --release -p dynlab-nodes`)
and the test venv (`tests/setup_python.sh`); installs nothing else.
"""
import argparse
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time
import uuid

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[1]
BIN = pathlib.Path(os.environ.get("DYNLAB_BIN_DIR", REPO / "target" / "release"))
PY = sys.executable
DOMAIN = "23"


def env():
    return dict(os.environ, ROS_DOMAIN_ID=DOMAIN)


def ours(*args):
    return [str(BIN / "dds_probe"), *map(str, args)]


def cyclone(*args):
    return [PY, str(HERE / "cyclone_probe.py"), *map(str, args)]


def last_json(text: str) -> dict:
    for line in reversed(text.strip().splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"no JSON in output:\n{text}")


def latency(pub_cmd, sub_cmd, rate, count, skip):
    topic = f"/bench/lat_{uuid.uuid4().hex[:8]}"
    sub = subprocess.Popen(sub_cmd("sub", "--topic", topic, "--count", count, "--skip", skip),
                           env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sub.stdout.readline()  # {"ready": true}
    pub = subprocess.run(pub_cmd("pub", "--topic", topic, "--rate", rate, "--count", count),
                         env=env(), capture_output=True, text=True, timeout=120)
    out, err = sub.communicate(timeout=60)
    if pub.returncode or sub.returncode:
        raise RuntimeError(pub.stderr + err)
    return last_json(out)


def bag_stats(bag: pathlib.Path):
    from mcap.reader import make_reader
    (path,) = bag.glob("*.mcap")
    n, size = 0, 0
    with open(path, "rb") as f:
        for _, _, msg in make_reader(f).iter_messages():
            n += 1
            size += len(msg.data)
    return n, size


def throughput_recorder(rate, count, publisher=None):
    publisher = publisher or (lambda *a: cyclone(*a, "--keep-all"))
    topic = f"/bench/thr_{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory() as d:
        bag = pathlib.Path(d) / "bag"
        rec = subprocess.Popen([str(BIN / "recorder"), "-o", bag, topic], env=env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        pub = subprocess.run(publisher("pub", "--topic", topic, "--rate", rate, "--count", count),
                             env=env(), capture_output=True, text=True, timeout=300)
        time.sleep(1.0)
        rec.send_signal(signal.SIGINT)
        _, err = rec.communicate(timeout=60)
        if pub.returncode or rec.returncode:
            raise RuntimeError(pub.stderr + err)
        sent = last_json(pub.stdout)
        n, size = bag_stats(bag)
        return sent, n, size


def throughput_cyclone(rate, count):
    topic = f"/bench/thr_{uuid.uuid4().hex[:8]}"
    sub = subprocess.Popen(cyclone("sub", "--topic", topic, "--count", count, "--idle-timeout", 2, "--keep-all"),
                           env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sub.stdout.readline()
    pub = subprocess.run(cyclone("pub", "--topic", topic, "--rate", rate, "--count", count, "--keep-all"),
                         env=env(), capture_output=True, text=True, timeout=300)
    out, err = sub.communicate(timeout=120)
    if pub.returncode or sub.returncode:
        raise RuntimeError(pub.stderr + err)
    return last_json(pub.stdout), last_json(out)["received"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer messages")
    args = ap.parse_args()
    scale = 0.3 if args.quick else 1.0

    print("## Publish → receive latency, PoseStamped, reliable, loopback\n")
    print("| rate | path | received | p50 [µs] | p99 [µs] | p50 / Cyclone→Cyclone |")
    print("|---|---|---|---|---|---|")
    pairs = [("ours → ours", ours, ours), ("Cyclone → Cyclone", cyclone, cyclone),
             ("Cyclone → ours", cyclone, ours), ("ours → Cyclone", ours, cyclone)]
    for rate, seconds in ((100, 5), (1000, 4)):
        count = int(rate * seconds * scale)
        skip = count // 10
        results = {name: latency(p, s, rate, count, skip) for name, p, s in pairs}
        base = results["Cyclone → Cyclone"].get("p50_us")
        for name, r in results.items():
            ratio = f"{r['p50_us'] / base:.2f}" if base and "p50_us" in r else "-"
            print(f"| {rate} Hz | {name} | {r['received']}/{count} | {r.get('p50_us', float('nan')):.0f} "
                  f"| {r.get('p99_us', float('nan')):.0f} | {ratio} |")
    print()

    print("## Recorder throughput, PoseStamped from a Cyclone publisher (reliable, keep all)\n")
    print("| offered rate | receiver | received/sent | msgs/s | payload MB/s | lossless |")
    print("|---|---|---|---|---|---|")
    for rate, seconds in ((1000, 3), (5000, 3), (0, 2)):
        count = int((rate or 20000) * seconds * scale)
        sent, n, size = throughput_recorder(rate, count)
        per_msg = size / max(n, 1)
        rps = n / sent["seconds"]
        label = f"{rate}/s" if rate else "max"
        print(f"| {label} | recorder → bag | {n}/{count} | {rps:.0f} | {rps * per_msg / 1e6:.2f} | {n == count} |")
        sent_c, got_c = throughput_cyclone(rate, count)
        rps_c = got_c / sent_c["seconds"]
        print(f"| {label} | Cyclone subscriber | {got_c}/{count} | {rps_c:.0f} | {rps_c * per_msg / 1e6:.2f} "
              f"| {got_c == count} |")
    count = int(100000 * scale)
    sent, n, size = throughput_recorder(0, count, publisher=ours)
    rps = n / sent["seconds"]
    print(f"| max, our publisher (reliable, keep last 10) | recorder → bag | {n}/{count} | {rps:.0f} "
          f"| {rps * size / max(n, 1) / 1e6:.2f} | {n == count} |")
    print("\nmsgs/s = received / publisher's sending time; payload = CDR bytes per message in the bag.")


if __name__ == "__main__":
    main()
