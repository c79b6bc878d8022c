"""Writes dynlab's own test tracks (MPCC track.json layout, metres), 0.36 m wide (the ORCA
track's width), for the 1:43 car. Regenerate both with `python3 make_default_track.py`.

default.json: a closed polar curve r(θ) = 1.1 + 0.3 cos 2θ − 0.14 sin 3θ + 0.03 cos 5θ,
stretched 1.25× in x: two fast sweepers and two tighter bends, about 9 m long.

hairpin.json: straights and circular arcs (counter-clockwise), about 9 m long: a 1.9 m main
straight, two 90° bends of radius 0.35 m, and a pocket pushed into the loop from the top: a 90°
bend of radius 0.3 m in, a clockwise 180° hairpin of radius 0.3 m, a 90° bend of radius 0.3 m
out, then two 90° bends of radius 0.45 m back to the straight. The pocket's lanes run 0.6 m
apart (0.24 m of floor between their borders).
"""
import json
import math

N = 400
HALF_WIDTH = 0.18


def centre(t):
    r = 1.1 + 0.3 * math.cos(2 * t) - 0.14 * math.sin(3 * t) + 0.03 * math.cos(5 * t)
    return 1.25 * r * math.cos(t), r * math.sin(t)


def write_track(pts, path):
    """Resamples the closed polyline pts to 3 cm steps, adds the borders, writes path."""
    n_pts = len(pts)
    # resample to equal arc length
    seg = [math.dist(pts[i], pts[(i + 1) % n_pts]) for i in range(n_pts)]
    total = sum(seg)
    out, acc, i = [], 0.0, 0
    M = int(total / 0.03)
    for k in range(M):
        s = total * k / M
        while acc + seg[i] < s:
            acc += seg[i]
            i += 1
        f = (s - acc) / seg[i]
        a, b = pts[i], pts[(i + 1) % n_pts]
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
              open(path, "w"))
    # report length and tightest radius
    kmax = 0.0
    for k in range(M):
        a, b, c = out[k - 1], out[k], out[(k + 1) % M]
        ab, bc, ca = math.dist(a, b), math.dist(b, c), math.dist(c, a)
        area2 = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        kmax = max(kmax, 2 * area2 / (ab * bc * ca))
    print(f"{path}: {M} points, length {total:.2f} m, tightest radius {1 / kmax:.2f} m, "
          f"x {min(X):.2f}..{max(X):.2f}, y {min(Y):.2f}..{max(Y):.2f}")


def arcs_and_straights(segments, step=0.001):
    """The closed polyline of a turtle walk from (0, 0) heading +x: ("S", length) straights and
    ("A", radius, degrees) arcs (positive: left), points every `step` metres."""
    x = y = h = 0.0
    pts = [(x, y)]
    for s in segments:
        if s[0] == "S":
            n = max(1, round(s[1] / step))
            for _ in range(n):
                x += s[1] / n * math.cos(h)
                y += s[1] / n * math.sin(h)
                pts.append((x, y))
        else:
            r, phi = s[1], math.radians(s[2])
            n = max(1, round(abs(phi) * r / step))
            dh = phi / n
            for _ in range(n):
                chord = 2 * r * math.sin(abs(dh) / 2)
                x += chord * math.cos(h + dh / 2)
                y += chord * math.sin(h + dh / 2)
                h += dh
                pts.append((x, y))
    assert math.hypot(x, y) < 1e-9 and abs(h - 2 * math.pi) < 1e-9, "the walk does not close"
    return pts[:-1]


write_track([centre(2 * math.pi * i / N) for i in range(N)], "default.json")

HAIRPIN = [
    ("S", 1.9), ("A", 0.35, 90), ("S", 0.8), ("A", 0.35, 90),  # main straight, right end
    ("S", 0.3), ("A", 0.3, 90), ("S", 0.3), ("A", 0.3, -180),  # into the pocket, hairpin
    ("S", 0.3), ("A", 0.3, 90), ("S", 0.4),                    # out of the pocket
    ("A", 0.45, 90), ("S", 0.6), ("A", 0.45, 90),              # left end back to the straight
]
# centred on the origin (the walk spans x 0…2.7 − 0.45, y 0…1.5)
write_track([(x - 0.9, y - 0.75) for x, y in arcs_and_straights(HAIRPIN)], "hairpin.json")
