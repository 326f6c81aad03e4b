#!/usr/bin/env python3
"""Reads a STEP or IGES patchwork written by `trispline export` with OpenCASCADE (pip
package cadquery-ocp; scripts/install_ocp.sh), an independent reader, and prints what it
found as one JSON object: the faces it made, their surface degrees, the millimetres per
declared unit (OpenCASCADE converts to millimetres on transfer), the largest distance between
OpenCASCADE's S(u, v) and the patches' JSON (NAME.json beside the STEP file, evaluated
here as Bezier patches) at a lattice of parameters, and the free boundary of the shell that
BRepBuilderAPI_Sewing makes of the faces at a tight tolerance: a watertight patchwork of a
closed object has none, one of an object with holes one closed wire per hole.

usage: occ_patchwork.py FILE.stp|FILE.igs PATCHES.json|- SEWING_TOLERANCE(in the file's unit)
With - (the daemon writes no patches' JSON) the comparison and the unit are left out.
"""
import json
import math
import sys

from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing
from OCP.Geom import Geom_BSplineSurface
from OCP.IFSelect import IFSelect_RetDone
from OCP.IGESControl import IGESControl_Reader
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
    path, patches_json, tolerance = sys.argv[1], sys.argv[2], float(sys.argv[3])
    patches = json.load(open(patches_json))["patches"] if patches_json != "-" else None
    iges = path.lower().endswith((".igs", ".iges"))
    reader = IGESControl_Reader() if iges else STEPControl_Reader()
    if reader.ReadFile(path) != IFSelect_RetDone:
        print(json.dumps({"read": False}))
        return
    reader.TransferRoots()
    shape = reader.OneShape()
    faces = [as_face(f) for f in shapes(shape, TopAbs_FACE)]
    surfaces = [BRep_Tool.Surface_s(face) for face in faces]
    degrees = sorted({
        f"{s.UDegree()}x{s.VDegree()}" if isinstance(s, Geom_BSplineSurface) else "not a B-spline"
        for s in surfaces
    })
    if not faces or degrees != ["4x4"]:
        print(json.dumps({"read": True, "faces": len(faces), "degrees": degrees}))
        return
    found = {"read": True, "faces": len(faces), "degrees": degrees}
    mm = 1.0
    if patches is not None:
        # The unit as OpenCASCADE understood it: its pole over ours, at the largest of ours.
        first = patches[0]["control_points"]
        k = max(range(25), key=lambda k: sum(x * x for x in first[k]))
        pole = surfaces[0].Pole(k // 5 + 1, k % 5 + 1)
        mm = math.sqrt(pole.X() ** 2 + pole.Y() ** 2 + pole.Z() ** 2) / math.sqrt(
            sum(x * x for x in first[k]))
        worst = 0.0
        for surface, ours in zip(surfaces, patches):
            for a in range(5):
                for c in range(5):
                    s, t = a / 4 * 0.98 + 0.01, c / 4 * 0.98 + 0.01
                    p = surface.Value(s, t)
                    q = bezier(ours["control_points"], s, t)
                    worst = max(worst, max(abs(x / mm - y) for x, y in zip((p.X(), p.Y(), p.Z()), q)))
        found["mm_per_unit"] = mm
        found["max_difference_from_json"] = worst
    else:
        # Only the sewing tolerance needs it: the unit the file declares.
        text = open(path, errors="replace").read()
        mm = 25.4 if "'INCH'" in text else 1.0 if ".MILLI." in text else 1000.0
    sewing = BRepBuilderAPI_Sewing(tolerance * mm)
    for face in faces:
        sewing.Add(face)
    sewing.Perform()
    free = ShapeAnalysis_FreeBounds(sewing.SewedShape(), tolerance * mm)
    found["free_edges"] = sewing.NbFreeEdges()
    found["closed_free_wires"] = sum(1 for _ in shapes(free.GetClosedWires(), TopAbs_WIRE))
    found["open_free_wires"] = sum(1 for _ in shapes(free.GetOpenWires(), TopAbs_WIRE))
    print(json.dumps(found))


if __name__ == "__main__":
    main()
