#!/usr/bin/env python3
"""Reads a STEP patchwork written by `trispline export` with OpenCASCADE (pip package
cadquery-ocp; scripts/install_ocp.sh), an independent reader, and prints what it found as
one JSON object: the faces it made, their surface degrees, the largest distance between
OpenCASCADE's S(u, v) and the patches' JSON (NAME.json beside the STEP file, evaluated
here as Bezier patches) at a lattice of parameters, and the free boundary of the shell that
BRepBuilderAPI_Sewing makes of the faces at a tight tolerance: a watertight patchwork of a
closed object has none, one of an object with holes one closed wire per hole.

usage: occ_patchwork.py FILE.stp PATCHES.json SEWING_TOLERANCE(in the file's unit)
"""
import json
import math
import sys

from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing
from OCP.Geom import Geom_BSplineSurface
from OCP.IFSelect import IFSelect_RetDone
from OCP.ShapeAnalysis import ShapeAnalysis_FreeBounds
from OCP.STEPControl import STEPControl_Reader
from OCP.TopAbs import TopAbs_FACE, TopAbs_WIRE
from OCP.TopExp import TopExp_Explorer
from OCP import TopoDS as _topods

TopoDS = _topods.TopoDS


def shapes(shape, kind):
    found = TopExp_Explorer(shape, kind)
    while found.More():
        yield found.Current()
        found.Next()


def as_face(shape):
    return TopoDS.Face_s(shape) if hasattr(TopoDS, "Face_s") else TopoDS.Face(shape)


def bezier(controls, s, t):
    """A degree (4, 4) Bezier patch (5 x 5 controls, row-major along s) at (s, t)."""
    b = lambda x: [math.comb(4, k) * x**k * (1 - x) ** (4 - k) for k in range(5)]
    bs, bt = b(s), b(t)
    out = [0.0, 0.0, 0.0]
    for i in range(5):
        for j in range(5):
            w = bs[i] * bt[j]
            for k in range(3):
                out[k] += w * controls[i * 5 + j][k]
    return out


def main():
    step, patches_json, tolerance = sys.argv[1], sys.argv[2], float(sys.argv[3])
    text = open(step).read()
    # OpenCASCADE converts to millimetres on transfer.
    mm = 25.4 if "CONVERSION_BASED_UNIT('INCH'" in text else (
        1.0 if ".MILLI.,.METRE." in text else 1000.0)
    patches = json.load(open(patches_json))["patches"]
    reader = STEPControl_Reader()
    if reader.ReadFile(step) != IFSelect_RetDone:
        print(json.dumps({"read": False}))
        return
    reader.TransferRoots()
    shape = reader.OneShape()
    faces = [as_face(f) for f in shapes(shape, TopAbs_FACE)]
    degrees = set()
    worst = 0.0
    for face, ours in zip(faces, patches):
        surface = BRep_Tool.Surface_s(face)
        if not isinstance(surface, Geom_BSplineSurface):
            degrees.add("not a B-spline")
            continue
        degrees.add(f"{surface.UDegree()}x{surface.VDegree()}")
        for a in range(5):
            for c in range(5):
                s, t = a / 4 * 0.98 + 0.01, c / 4 * 0.98 + 0.01
                p = surface.Value(s, t)
                q = bezier(ours["control_points"], s, t)
                worst = max(worst, max(abs(x / mm - y) for x, y in zip((p.X(), p.Y(), p.Z()), q)))
    sewing = BRepBuilderAPI_Sewing(tolerance * mm)
    for face in faces:
        sewing.Add(face)
    sewing.Perform()
    free = ShapeAnalysis_FreeBounds(sewing.SewedShape(), tolerance * mm)
    print(json.dumps({
        "read": True,
        "faces": len(faces),
        "degrees": sorted(degrees),
        "max_difference_from_json": worst,
        "free_edges": sewing.NbFreeEdges(),
        "closed_free_wires": sum(1 for _ in shapes(free.GetClosedWires(), TopAbs_WIRE)),
        "open_free_wires": sum(1 for _ in shapes(free.GetOpenWires(), TopAbs_WIRE)),
    }))


if __name__ == "__main__":
    main()
