"""PyTorch reference for control/benches/mppi_speed.rs: one MPPI step over a pushing NeuralODE
(6 -> 100 -> 100 -> 3 tanh, one RK4 step per push), the same work as dynlab's Mppi::step: K
clamped Gaussian perturbations of a warm-started T-step sequence, a batched rollout, per-sample
quadratic goal cost with wrapped angle, terminal cost, SAT collision cost against one obstacle,
importance weights, shift. Prints "K T median_ms" lines. Threads: torch.set_num_threads(2).

    python benches/torch_mppi.py
"""

import math
import time

import torch

torch.set_num_threads(2)
torch.manual_seed(0)

net = torch.nn.Sequential(
    torch.nn.Linear(6, 100), torch.nn.Tanh(),
    torch.nn.Linear(100, 100), torch.nn.Tanh(),
    torch.nn.Linear(100, 3),
)
LO = torch.tensor([-1.0, -math.pi / 2, 0.0])
HI = torch.tensor([1.0, math.pi / 2, 1.0])
SIGMA = torch.tensor([0.5, 0.6, 0.3])
Q = torch.tensor([1.0, 1.0, 0.1])
QF = torch.tensor([10.0, 10.0, 1.0])
GOAL = torch.tensor([0.8, -0.1, 0.0])
OBS_C = torch.tensor([0.6, 0.2])
OBS_H = torch.tensor([0.06, 0.26])
BLOCK_H = torch.tensor([0.05, 0.05])


def field(z, u):
    return net(torch.cat([z, u], dim=1)) * 0.02


def rk4(z, u):
    k1 = field(z, u)
    k2 = field(z + 0.5 * k1, u)
    k3 = field(z + 0.5 * k2, u)
    k4 = field(z + k3, u)
    return z + (k1 + 2 * k2 + 2 * k3 + k4) / 6


def collides(s):
    # separating axes: obstacle is axis-aligned, block rotated by theta
    d = s[:, :2] - OBS_C
    c, sn = torch.cos(s[:, 2]), torch.sin(s[:, 2])
    # block radius on world axes
    rbx = BLOCK_H[0] * c.abs() + BLOCK_H[1] * sn.abs()
    rby = BLOCK_H[0] * sn.abs() + BLOCK_H[1] * c.abs()
    sep = (d[:, 0].abs() > OBS_H[0] + rbx) | (d[:, 1].abs() > OBS_H[1] + rby)
    # block axes
    for ax, ay, hb in ((c, sn, BLOCK_H[0]), (-sn, c, BLOCK_H[1])):
        dist = (d[:, 0] * ax + d[:, 1] * ay).abs()
        ro = OBS_H[0] * ax.abs() + OBS_H[1] * ay.abs()
        sep = sep | (dist > ro + hb)
    return ~sep


def wrap(a):
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


@torch.no_grad()
def mppi_step(nominal, s0, K, T, lam=0.005):
    eps = torch.randn(K, T, 3) * SIGMA
    eps[0] = 0
    u = torch.max(torch.min(nominal.unsqueeze(0) + eps, HI), LO)
    s = s0.expand(K, 3).clone()
    cost = torch.zeros(K)
    for t in range(T):
        s = rk4(s, u[:, t])
        e = s - GOAL
        e[:, 2] = wrap(e[:, 2])
        cost += (e * e * Q).sum(1) + 100.0 * collides(s).float()
    cost += (e * e * QF).sum(1)
    w = torch.softmax(-(cost - cost.min()) / lam, 0)
    new = (w[:, None, None] * u).sum(0)
    return torch.cat([new[1:], new[-1:]]), new[0]


def bench(K, T):
    nominal = torch.zeros(T, 3)
    s0 = torch.tensor([[0.4, 0.0, -0.2 * math.pi]])
    for _ in range(3):
        nominal, _ = mppi_step(nominal, s0, K, T)
    reps = 15 if K * T >= 10000 else 200
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        nominal, _ = mppi_step(nominal, s0, K, T)
        times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    return times[len(times) // 2]


if __name__ == "__main__":
    for K, T in ((1000, 20), (100, 10)):
        print(K, T, f"{bench(K, T):.3f}")
