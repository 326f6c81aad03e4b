"""Regenerates the sample patches of the README quick start (python3 generate.py).

Jittered grids clipped to a unit disk over smooth height fields, triangulated per cell on
the shorter diagonal: irregular connectivity, one boundary loop, like a small scan patch.
"""
import math
import random

random.seed(7)


def patch(f, n=40, r=1.0, jitter=0.3):
    h = 2 * r / n
    idx, pts = {}, []
    for j in range(n + 1):
        for i in range(n + 1):
            x = -r + i * h + (random.random() - 0.5) * jitter * h
            y = -r + j * h + (random.random() - 0.5) * jitter * h
            if x * x + y * y <= r * r:
                idx[(i, j)] = len(pts)
                pts.append((x, y, f(x, y)))
    tris = []

    def dist(p, q):
        return sum((pts[p][t] - pts[q][t]) ** 2 for t in range(3))

    for j in range(n):
        for i in range(n):
            cell = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            if all(k in idx for k in cell):
                a, b, c, d = (idx[k] for k in cell)
                if dist(a, c) <= dist(b, d):
                    tris += [(a, b, c), (a, c, d)]
                else:
                    tris += [(a, b, d), (b, c, d)]
    return pts, tris


def write_obj(name, pts, tris):
    with open(name, "w") as fh:
        fh.write("# trispline sample patch (generated)\n")
        for p in pts:
            fh.write("v %.6f %.6f %.6f\n" % p)
        for t in tris:
            fh.write("f %d %d %d\n" % tuple(k + 1 for k in t))


def write_ply(name, pts, tris):
    with open(name, "w") as fh:
        fh.write("ply\nformat ascii 1.0\ncomment trispline sample patch (generated)\n")
        fh.write("element vertex %d\nproperty float x\nproperty float y\nproperty float z\n" % len(pts))
        fh.write("element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(tris))
        for p in pts:
            fh.write("%.6f %.6f %.6f\n" % p)
        for t in tris:
            fh.write("3 %d %d %d\n" % t)


def write_off(name, pts, tris):
    with open(name, "w") as fh:
        fh.write("OFF\n# trispline sample patch (generated)\n%d %d 0\n" % (len(pts), len(tris)))
        for p in pts:
            fh.write("%.6f %.6f %.6f\n" % p)
        for t in tris:
            fh.write("3 %d %d %d\n" % t)


write_obj("dome.obj", *patch(lambda x, y: 0.35 * math.exp(-1.5 * (x * x + y * y))))
write_ply("saddle@0001.ply", *patch(lambda x, y: 0.2 * (x * x - y * y), n=36))
write_off("ripple.off", *patch(lambda x, y: 0.08 * math.sin(3 * x) * math.cos(2 * y), n=44))
