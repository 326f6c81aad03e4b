#!/usr/bin/env python3
"""Dev-only check of `trispline bspline-fit` / `trispline curvature` output with an independent IGES reader:
OpenCASCADE (pip package cadquery-ocp). Reads DIR/surface.igs with IGESControl_Reader,
transfers it to a shape, takes the B-spline surface of its face and compares with
DIR/surface.json (degrees, knots, poles) and with our own evaluation (the vertices of
DIR/surface.glb, written at uniform parameters of the domain).

usage: check_iges.py DIR [tessellation_segments=64]
DIR holds surface.igs (+ surface.json, surface.glb) and/or boundaries.igs (+ boundaries.json):
the boundary curves (entity 126, degree 1) are transferred too and their vertices compared
with the polylines of boundaries.json.
Exit status 0 when everything agrees, 1 otherwise.
"""
import json
import struct
import subprocess
import sys

try:
    from OCP.IGESControl import IGESControl_Reader
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "cadquery-ocp"])
    from OCP.IGESControl import IGESControl_Reader
from OCP.IFSelect import IFSelect_RetDone
from OCP.TopExp import TopExp_Explorer
from OCP.TopAbs import TopAbs_FACE
from OCP import TopoDS as _T
TopoDS = _T.TopoDS
from OCP.BRep import BRep_Tool
from OCP.Geom import Geom_BSplineSurface


def glb_positions(path):
    data = open(path, "rb").read()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + jlen])
    bin_start = 20 + jlen + 8
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    off = bin_start + view.get("byteOffset", 0)
    vals = struct.unpack_from("<%df" % (3 * acc["count"]), data, off)
    return [vals[i:i + 3] for i in range(0, len(vals), 3)]


def global_params(text):
    """Splits the global section at ',' (and the final ';'), reading nH strings whole."""
    out, i = [], 0
    while i < len(text):
        j = i
        while j < len(text) and text[j].isdigit():
            j += 1
        if j > i and j < len(text) and text[j] == "H":
            n = int(text[i:j])
            out.append(text[j + 1:j + 1 + n])
            i = j + 1 + n + 1
            continue
        k = min([x for x in (text.find(",", i), text.find(";", i)) if x >= 0] or [len(text)])
        out.append(text[i:k])
        i = k + 1
        if k < len(text) and text[k] == ";":
            break
    return out


def flat_knots(knots, mults):
    out = []
    for i in range(1, knots.Length() + 1):
        out += [knots.Value(i)] * mults.Value(i)
    return out


def unit_scale(path):
    lines = open(path).read().splitlines()
    glob = "".join(l[:72] for l in lines if len(l) >= 73 and l[72] == "G")
    flag = int(global_params(glob)[13])
    return flag, {1: 25.4, 2: 1.0, 6: 1000.0}[flag]


def check_boundaries(d, check):
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom import Geom_BSplineCurve
    flag, mm = unit_scale(f"{d}/boundaries.igs")
    regions = json.load(open(f"{d}/boundaries.json"))["regions"]
    loops = [l for r in regions for l in r["loops"]]
    reader = IGESControl_Reader()
    status = reader.ReadFile(f"{d}/boundaries.igs")
    check(status == IFSelect_RetDone, f"boundaries.igs read (unit flag {flag})")
    check(reader.NbRootsForTransfer() == len(loops),
          f"{reader.NbRootsForTransfer()} root curves for {len(loops)} loops")
    # OpenCASCADE splits a C0 curve into one edge per knot span on transfer: gather the
    # poles of each root's edges in order and compare the concatenation with the loop.
    worst, edges = 0.0, 0
    for k, l in enumerate(loops):
        reader.TransferOneRoot(k + 1)
        shape = reader.Shape(reader.NbShapes())
        exp = TopExp_Explorer(shape, TopAbs_EDGE)
        pts = []
        while exp.More():
            edge = TopoDS.Edge(exp.Current()) if hasattr(TopoDS, "Edge") else TopoDS.Edge_s(exp.Current())
            c = BRepAdaptor_Curve(edge)
            a, b = c.Value(c.FirstParameter()), c.Value(c.LastParameter())
            for p in (a, b):
                q = [p.X() / mm, p.Y() / mm, p.Z() / mm]
                if not pts or max(abs(x - y) for x, y in zip(q, pts[-1])) > 0:
                    pts.append(q)
            edges += 1
            exp.Next()
        ref = [p for i, p in enumerate(l) if i == 0 or p != l[i - 1]]
        if len(pts) != len(ref):
            worst = float("inf")
            print(f"loop {k}: {len(pts)} points from OpenCASCADE, {len(ref)} in boundaries.json")
            continue
        worst = max(worst, max(abs(a - b) for p, q in zip(pts, ref) for a, b in zip(p, q)))
    check(worst < 1e-12, f"{edges} edges of {len(loops)} curves: their end points are the boundaries.json "
          f"loop points in order (max difference {worst:.1e})")


def main():
    d = sys.argv[1]
    import os
    if not os.path.exists(f"{d}/surface.igs"):
        ok = True

        def check(cond, what):
            nonlocal ok
            print(("ok   " if cond else "FAIL ") + what)
            ok &= bool(cond)
        check_boundaries(d, check)
        sys.exit(0 if ok else 1)
    seg = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    ours = json.load(open(f"{d}/surface.json"))
    # OpenCASCADE converts to millimetres on transfer: undo it with the file's unit flag
    # (global parameter 14), which also checks that the flag was read as written.
    lines = open(f"{d}/surface.igs").read().splitlines()
    glob = "".join(l[:72] for l in lines if len(l) >= 73 and l[72] == "G")
    unit_flag = int(global_params(glob)[13])
    mm_per_unit = {1: 25.4, 2: 1.0, 6: 1000.0}[unit_flag]
    reader = IGESControl_Reader()
    status = reader.ReadFile(f"{d}/surface.igs")
    ok = True

    def check(cond, what):
        nonlocal ok
        print(("ok   " if cond else "FAIL ") + what)
        ok &= bool(cond)

    print(f"unit flag {unit_flag}: OpenCASCADE coordinates divided by {mm_per_unit}")
    check(status == IFSelect_RetDone, f"IGESControl_Reader.ReadFile status {status}")
    n_roots = reader.NbRootsForTransfer()
    check(n_roots == 1, f"{n_roots} root entity")
    reader.TransferRoots()
    shape = reader.OneShape()
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    check(exp.More(), "transferred shape has a face")
    face = TopoDS.Face(exp.Current()) if hasattr(TopoDS, "Face") else TopoDS.Face_s(exp.Current())
    surf = BRep_Tool.Surface_s(face)
    bs = Geom_BSplineSurface.DownCast(surf) if not isinstance(surf, Geom_BSplineSurface) else surf
    check(bs is not None, f"face surface is a Geom_BSplineSurface ({type(surf).__name__})")
    check(not bs.IsURational() and not bs.IsVRational(), "non-rational (unit weights)")
    check((bs.UDegree(), bs.VDegree()) == (ours["degree_u"], ours["degree_v"]),
          f"degrees {bs.UDegree()},{bs.VDegree()}")
    nu, nv = ours["control_grid"]
    check((bs.NbUPoles(), bs.NbVPoles()) == (nu, nv), f"poles {bs.NbUPoles()}x{bs.NbVPoles()}")
    ku = flat_knots(bs.UKnots(), bs.UMultiplicities())
    kv = flat_knots(bs.VKnots(), bs.VMultiplicities())
    dk = max(max(abs(a - b) for a, b in zip(ku, ours["knots_u"])),
             max(abs(a - b) for a, b in zip(kv, ours["knots_v"])))
    check(len(ku) == len(ours["knots_u"]) and len(kv) == len(ours["knots_v"]) and dk < 1e-14,
          f"knot vectors equal (max difference {dk:.1e})")
    dp = 0.0
    for i in range(nu):
        for j in range(nv):
            p = bs.Pole(i + 1, j + 1)
            c = ours["control_points"][i * nv + j]
            p = [p.X() / mm_per_unit, p.Y() / mm_per_unit, p.Z() / mm_per_unit]
            dp = max(dp, max(abs(a - b) for a, b in zip(p, c)))
    scale = max(max(abs(x) for x in c) for c in ours["control_points"])
    check(dp < 1e-14 * scale * 8, f"poles equal to surface.json control points (max difference {dp:.1e})")
    pts = glb_positions(f"{d}/surface.glb")
    u0, u1 = ours["knots_u"][ours["degree_u"]], ours["knots_u"][nu]
    v0, v1 = ours["knots_v"][ours["degree_v"]], ours["knots_v"][nv]
    de = 0.0
    for a in range(seg + 1):
        for b in range(seg + 1):
            u = u0 + (u1 - u0) * a / seg
            v = v0 + (v1 - v0) * b / seg
            p = bs.Value(u, v)
            p = [p.X() / mm_per_unit, p.Y() / mm_per_unit, p.Z() / mm_per_unit]
            q = pts[a * (seg + 1) + b]
            de = max(de, max(abs(x - y) for x, y in zip(p, q)))
    check(de <= 1e-6 * scale,
          f"OpenCASCADE S(u,v) vs our evaluation at {(seg + 1) ** 2} parameters: max difference {de:.2e} "
          f"(ours stored as f32 in the GLB; coordinate scale {scale:.3g})")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
