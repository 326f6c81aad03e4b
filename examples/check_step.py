#!/usr/bin/env python3
"""Dev-only check of trispline's STEP output with an independent reader: OpenCASCADE
(pip package cadquery-ocp), as examples/check_iges.py does for IGES.

usage: check_step.py FILE.stp SURFACE.json [samples_per_side=40]
SURFACE.json is the B-spline surface.json the STEP file was written from (`bspline-fit`
writes DIR/surface.json beside DIR/surface.stp; `trispline export --step X.stp` writes the
converted B-spline to X.json). Reports the entity counts, the declared unit and the size
OpenCASCADE reads (it converts to millimetres on transfer), the degrees/knots/poles against
the JSON, and the largest distance between OpenCASCADE's S(u, v) and our own de Boor
evaluation of the JSON at samples^2 parameters. Exit 0 when everything agrees.
"""
import json
import re
import subprocess
import sys

try:
    from OCP.STEPControl import STEPControl_Reader
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "cadquery-ocp"])
    from OCP.STEPControl import STEPControl_Reader
from OCP.IFSelect import IFSelect_RetDone
from OCP.TopExp import TopExp_Explorer
from OCP.TopAbs import TopAbs_FACE
from OCP import TopoDS as _T
from OCP.BRep import BRep_Tool
from OCP.Bnd import Bnd_Box
from OCP.BRepBndLib import BRepBndLib
from OCP.Geom import Geom_BSplineSurface

TopoDS = _T.TopoDS


def declared_mm_per_unit(text):
    """The millimetres per declared length unit, read from the file's unit entities."""
    if "CONVERSION_BASED_UNIT('INCH'" in text:
        return 25.4, "inch"
    m = re.search(r"\(LENGTH_UNIT\(\)NAMED_UNIT\(\*\)SI_UNIT\(([^,]*),\.METRE\.\)\)", text)
    prefix = m.group(1) if m else None
    return {"$": (1000.0, "metre"), ".MILLI.": (1.0, "millimetre")}.get(prefix, (None, prefix))


def find_span(knots, p, n, t):
    if t >= knots[n]:
        return n - 1
    lo, hi = p, n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if knots[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


def basis(knots, p, span, t):
    """Cox-de Boor: the p + 1 non-zero basis functions at t."""
    left, right, nb = [0.0] * (p + 1), [0.0] * (p + 1), [1.0] + [0.0] * p
    for j in range(1, p + 1):
        left[j] = t - knots[span + 1 - j]
        right[j] = knots[span + j] - t
        saved = 0.0
        for r in range(j):
            tmp = nb[r] / (right[r + 1] + left[j - r])
            nb[r] = saved + right[r + 1] * tmp
            saved = left[j - r] * tmp
        nb[j] = saved
    return nb


def evaluate(s, u, v):
    p, q = s["degree_u"], s["degree_v"]
    nu, nv = s["control_grid"]
    su = find_span(s["knots_u"], p, nu, u)
    sv = find_span(s["knots_v"], q, nv, v)
    bu, bv = basis(s["knots_u"], p, su, u), basis(s["knots_v"], q, sv, v)
    out = [0.0, 0.0, 0.0]
    for a in range(p + 1):
        for b in range(q + 1):
            c = s["control_points"][(su - p + a) * nv + (sv - q + b)]
            w = bu[a] * bv[b]
            for k in range(3):
                out[k] += w * c[k]
    return out


def flat_knots(knots, mults):
    out = []
    for i in range(1, knots.Length() + 1):
        out += [knots.Value(i)] * mults.Value(i)
    return out


def main():
    stp, js = sys.argv[1], sys.argv[2]
    n = int(sys.argv[3]) if len(sys.argv) > 3 else 40
    ours = json.load(open(js))
    text = open(stp).read()
    ok = True

    def check(cond, what):
        nonlocal ok
        print(("ok   " if cond else "FAIL ") + what)
        ok &= bool(cond)

    mm, unit = declared_mm_per_unit(text)
    check(mm is not None, f"declared length unit: {unit}")
    reader = STEPControl_Reader()
    status = reader.ReadFile(stp)
    check(status == IFSelect_RetDone, f"STEPControl_Reader.ReadFile status {status}")
    model = reader.StepModel()
    print(f"     {model.NbEntities()} entities in the model "
          f"({text.count('B_SPLINE_SURFACE_WITH_KNOTS')} B_SPLINE_SURFACE_WITH_KNOTS)")
    roots = reader.NbRootsForTransfer()
    check(roots == 1, f"{roots} root for transfer")
    reader.TransferRoots()
    shape = reader.OneShape()
    faces = []
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        faces.append(TopoDS.Face(exp.Current()) if hasattr(TopoDS, "Face") else TopoDS.Face_s(exp.Current()))
        exp.Next()
    check(len(faces) == 1, f"{len(faces)} face(s) in the transferred shape")
    if not faces:
        sys.exit(1)
    bs = BRep_Tool.Surface_s(faces[0])
    if not isinstance(bs, Geom_BSplineSurface):
        bs = Geom_BSplineSurface.DownCast(bs)
    check(bs is not None, "face surface is a Geom_BSplineSurface")
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
    scale = max(max(abs(x) for x in c) for c in ours["control_points"])
    dp = 0.0
    for i in range(nu):
        for j in range(nv):
            p = bs.Pole(i + 1, j + 1)
            c = ours["control_points"][i * nv + j]
            dp = max(dp, max(abs(a - b) for a, b in zip([p.X() / mm, p.Y() / mm, p.Z() / mm], c)))
    check(dp <= 1e-13 * scale, f"poles equal the JSON control points (max difference {dp:.1e})")
    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    lo, hi = box.CornerMin(), box.CornerMax()
    x0, y0, z0, x1, y1, z1 = lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z()
    occ_size = max(x1 - x0, y1 - y0, z1 - z0)
    cps = ours["control_points"]
    our_size = max(max(c[k] for c in cps) - min(c[k] for c in cps) for k in range(3))
    ratio = occ_size / (our_size * mm)
    # The face's box holds the surface, not the control net: equal to within the fit's
    # overshoot of the hull, and nowhere near a unit factor of 1000 or 25.4.
    check(0.8 < ratio <= 1.0 + 1e-6,
          f"size: OpenCASCADE {occ_size:.6g} mm, control net {our_size:.6g} {unit} "
          f"= {our_size * mm:.6g} mm (ratio {ratio:.4f})")
    u0, u1 = ours["knots_u"][ours["degree_u"]], ours["knots_u"][nu]
    v0, v1 = ours["knots_v"][ours["degree_v"]], ours["knots_v"][nv]
    worst = 0.0
    for a in range(n + 1):
        for b in range(n + 1):
            u, v = u0 + (u1 - u0) * a / n, v0 + (v1 - v0) * b / n
            p = bs.Value(u, v)
            q = evaluate(ours, u, v)
            worst = max(worst, max(abs(x - y) for x, y in zip([p.X() / mm, p.Y() / mm, p.Z() / mm], q)))
    check(worst <= 1e-12 * max(scale, 1e-300),
          f"OpenCASCADE S(u,v) vs de Boor on the JSON at {(n + 1) ** 2} parameters: "
          f"max difference {worst:.2e} {unit}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
