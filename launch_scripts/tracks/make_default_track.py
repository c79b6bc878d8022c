"""Writes default.json: dynlab's own test track (MPCC track.json layout, metres).

A closed polar curve r(θ) = 1.1 + 0.3 cos 2θ − 0.14 sin 3θ + 0.03 cos 5θ, stretched 1.25× in x:
two fast sweepers and two tighter bends (radius ≥ 0.33 m), about 9 m long and 0.36 m wide (the ORCA
track's width), for the 1:43 car. Regenerate with `python3 make_default_track.py`.
"""
import json
import math

N = 400
HALF_WIDTH = 0.18


def centre(t):
    r = 1.1 + 0.3 * math.cos(2 * t) - 0.14 * math.sin(3 * t) + 0.03 * math.cos(5 * t)
    return 1.25 * r * math.cos(t), r * math.sin(t)


pts = [centre(2 * math.pi * i / N) for i in range(N)]
# resample to equal arc length
seg = [math.dist(pts[i], pts[(i + 1) % N]) for i in range(N)]
total = sum(seg)
out, acc, i = [], 0.0, 0
M = int(total / 0.03)
for k in range(M):
    s = total * k / M
    while acc + seg[i] < s:
        acc += seg[i]
        i += 1
    f = (s - acc) / seg[i]
    a, b = pts[i], pts[(i + 1) % N]
    out.append((a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])))
X, Y, Xi, Yi, Xo, Yo = [], [], [], [], [], []
for k, (x, y) in enumerate(out):
    p, n = out[k - 1], out[(k + 1) % M]
    tx, ty = n[0] - p[0], n[1] - p[1]
    l = math.hypot(tx, ty)
    nx, ny = -ty / l, tx / l  # left normal (inside: the curve runs counter-clockwise)
    X.append(round(x, 6)); Y.append(round(y, 6))
    Xi.append(round(x + HALF_WIDTH * nx, 6)); Yi.append(round(y + HALF_WIDTH * ny, 6))
    Xo.append(round(x - HALF_WIDTH * nx, 6)); Yo.append(round(y - HALF_WIDTH * ny, 6))
json.dump({"X": X, "Y": Y, "X_i": Xi, "Y_i": Yi, "X_o": Xo, "Y_o": Yo},
          open("default.json", "w"))
# report length and tightest radius
kmax = 0.0
for k in range(M):
    a, b, c = out[k - 1], out[k], out[(k + 1) % M]
    ab, bc, ca = math.dist(a, b), math.dist(b, c), math.dist(c, a)
    area2 = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    kmax = max(kmax, 2 * area2 / (ab * bc * ca))
print(f"{M} points, length {total:.2f} m, tightest radius {1 / kmax:.2f} m, "
      f"x {min(X):.2f}..{max(X):.2f}, y {min(Y):.2f}..{max(Y):.2f}")
