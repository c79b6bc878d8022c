#!/usr/bin/env python3
"""PyTorch CPU reference for `cargo bench -p dynlab-nn` (run by hand, not by CI).

Measures, with the same networks, batch sizes and definitions as nn/benches/nn_speed.rs:

  train_residual   samples/s, forward + backward + Adam, batch 500, MLP 6 -> 100 -> 100 -> 3 tanh,
                   residual model s' = s + f(s, u)  (one network evaluation per sample)
  train_rk4_k1     samples/s, NeuralODE RK4, 1 step  (4 evaluations per sample)
  train_rk4_k3     samples/s, NeuralODE RK4, 3 steps (12 evaluations per sample), loss
                   sum_n gamma^(n-1) mse(s_n, target_n), gamma = 0.9
  mppi_ms          ms for 1000 samples x 20 RK4 steps, forward only (torch.no_grad)
  car_jac_ms       ms for 20 input Jacobians of 8 -> 8 x 64 GELU (exact erf) -> 3
                   (best of torch.func vmap(jacrev) and vmap(jacfwd))

Usage (torch is large; keep it out of the repository's .venv):
    python3 -m venv $HOME/torchvenv && $HOME/torchvenv/bin/pip install torch
    $HOME/torchvenv/bin/python benches/torch_reference.py            # table
    $HOME/torchvenv/bin/python benches/torch_reference.py --json     # one JSON line (the Rust
                                                                     # bench reads this)
Threads: 2 (torch.set_num_threads; --threads N to change), as the Rust benchmark's parallel parts;
the JSON reports torch.get_num_threads() after setting it. cargo bench -p dynlab-learn runs this
with 2 and with 1 thread in every round.
"""

import argparse
import json
import statistics
import time

import torch
from torch import nn

BATCH = 500
DT = 0.1
GAMMA = 0.9


def pushing_mlp():
    return nn.Sequential(nn.Linear(6, 100), nn.Tanh(), nn.Linear(100, 100), nn.Tanh(), nn.Linear(100, 3))


def car_mlp():
    layers = [nn.Linear(8, 64), nn.GELU()]
    for _ in range(7):
        layers += [nn.Linear(64, 64), nn.GELU()]
    layers.append(nn.Linear(64, 3))
    return nn.Sequential(*layers)


def rk4_step(f, s, u):
    k1 = f(torch.cat([s, u], 1))
    k2 = f(torch.cat([s + 0.5 * DT * k1, u], 1))
    k3 = f(torch.cat([s + 0.5 * DT * k2, u], 1))
    k4 = f(torch.cat([s + DT * k3, u], 1))
    return s + DT / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def timed(fn, min_seconds=0.4):
    """Seconds per call: 3 warm-up calls, then blocks of at least 30 ms (and 3 calls) for at least
    min_seconds; the fastest block counts (as in nn_speed.rs: other processes only slow blocks)."""
    for _ in range(3):
        fn()
    start = time.perf_counter()
    best = float("inf")
    while time.perf_counter() - start < min_seconds or best == float("inf"):
        t0 = time.perf_counter()
        n = 0
        while n < 3 or time.perf_counter() - t0 < 0.03:
            fn()
            n += 1
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def bench_train(kind, steps):
    g = torch.Generator().manual_seed(0)
    model = pushing_mlp()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    s0 = torch.rand(BATCH, 3, generator=g) * 2 - 1
    us = [torch.rand(BATCH, 3, generator=g) * 2 - 1 for _ in range(steps)]
    targets = [torch.rand(BATCH, 3, generator=g) * 2 - 1 for _ in range(steps)]

    def it():
        opt.zero_grad(set_to_none=True)
        s = s0
        loss = 0.0
        for n in range(steps):
            if kind == "residual":
                s = s + model(torch.cat([s, us[n]], 1))
            else:
                s = rk4_step(model, s, us[n])
            loss = loss + GAMMA**n * ((s - targets[n]) ** 2).mean()
        loss.backward()
        opt.step()

    return BATCH / timed(it)


def bench_mppi():
    g = torch.Generator().manual_seed(1)
    model = pushing_mlp()
    s0 = torch.rand(1000, 3, generator=g) * 2 - 1
    us = torch.rand(20, 1000, 3, generator=g) * 2 - 1

    def it():
        with torch.no_grad():
            s = s0
            for n in range(20):
                s = rk4_step(model, s, us[n])
        return s

    return 1e3 * timed(it)


def bench_car_jac():
    from torch.func import jacfwd, jacrev, vmap

    g = torch.Generator().manual_seed(2)
    model = car_mlp()
    x = torch.rand(20, 8, generator=g) * 2 - 1
    best = float("inf")
    for jac in (jacrev, jacfwd):
        f = vmap(jac(model))
        with torch.no_grad():
            best = min(best, 1e3 * timed(lambda: f(x)))
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", action="store_true", help="print one JSON line")
    ap.add_argument("--rounds", type=int, default=5, help="median over this many rounds")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    benches = {
        "train_residual": lambda: bench_train("residual", 1),
        "train_rk4_k1": lambda: bench_train("rk4", 1),
        "train_rk4_k3": lambda: bench_train("rk4", 3),
        "mppi_ms": bench_mppi,
        "car_jac_ms": bench_car_jac,
    }
    rounds = {k: [] for k in benches}
    for _ in range(a.rounds):
        for k, f in benches.items():
            rounds[k].append(f())
    res = {k: statistics.median(v) for k, v in rounds.items()}
    res["torch"] = torch.__version__
    # what torch actually runs with (intra-op threads), not just what was asked for
    res["threads"] = torch.get_num_threads()
    if a.json:
        print(json.dumps(res))
    else:
        for k, v in res.items():
            print(f"{k:16} {v}")


if __name__ == "__main__":
    main()
