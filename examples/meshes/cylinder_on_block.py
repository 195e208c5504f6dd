"""Make ``examples/cases/cylinder_on_block.msh`` with Gmsh: NAFEMS benchmark 1's bodies as a
half model, two regions and named boundaries (physical groups), meshed finer near the contact.

Needs the ``gmsh`` Python package (``pip install gmsh``; not a dependency of ddcm-casadi, which
reads the file with meshio)::

    python examples/meshes/cylinder_on_block.py [OUT.msh] [--size-near 0.5e-3]

Physical groups (what a case file names):

- regions (2-D): ``cylinder`` (quarter disc, radius 50 mm, centre (0, 50 mm), lowered by
  :data:`OVERLAP`), ``block``
  ([0, 100 mm] x [-100 mm, 0]);
- boundaries (1-D): ``cylinder_arc`` (its contact surface), ``cylinder_flat`` (the loaded face),
  ``cylinder_axis`` and ``block_axis`` (the symmetry line x = 0), ``block_top``, ``block_bottom``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

R = 0.05  # m
BLOCK = 0.1  # m
#: The cylinder starts this far into the block: it rests on the block only, and the pair there
#: holds it at the first step (its free vertical motion takes the overlap up; no stress changes).
OVERLAP = 1e-6  # m


def build(out: Path, size_near: float, size_far: float) -> None:
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cylinder_on_block")
        geo = gmsh.model.geo
        # quarter disc: centre c, bottom b (the contact point), right r
        c, b, r = geo.addPoint(0, R - OVERLAP, 0), geo.addPoint(0, -OVERLAP, 0), geo.addPoint(R, R - OVERLAP, 0)
        arc, flat, axis = geo.addCircleArc(b, c, r), geo.addLine(r, c), geo.addLine(c, b)
        cyl = geo.addPlaneSurface([geo.addCurveLoop([arc, flat, axis])])
        # block below, its top through the origin (its own node there: the bodies share no node)
        o, t, q, s = geo.addPoint(0, 0, 0), geo.addPoint(BLOCK, 0, 0), geo.addPoint(BLOCK, -BLOCK, 0), geo.addPoint(0, -BLOCK, 0)
        top, side, bottom, baxis = geo.addLine(o, t), geo.addLine(t, q), geo.addLine(q, s), geo.addLine(s, o)
        blk = geo.addPlaneSurface([geo.addCurveLoop([top, side, bottom, baxis])])
        geo.synchronize()
        for dim, tags, name in ((2, [cyl], "cylinder"), (2, [blk], "block"), (1, [arc], "cylinder_arc"),
                                (1, [flat], "cylinder_flat"), (1, [axis], "cylinder_axis"), (1, [top], "block_top"),
                                (1, [baxis], "block_axis"), (1, [bottom], "block_bottom")):
            gmsh.model.addPhysicalGroup(dim, tags, name=name)
        # element size: size_near within 15 mm of the contact point, growing to size_far
        field = gmsh.model.mesh.field
        dist = field.add("Distance")
        field.setNumbers(dist, "PointsList", [b, o])
        ramp = field.add("Threshold")
        field.setNumber(ramp, "InField", dist)
        for key, value in (("SizeMin", size_near), ("SizeMax", size_far), ("DistMin", 0.015), ("DistMax", 0.06)):
            field.setNumber(ramp, key, value)
        field.setAsBackgroundMesh(ramp)
        for key in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(key, 0)
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        out.parent.mkdir(parents=True, exist_ok=True)
        gmsh.write(str(out))
    finally:
        gmsh.finalize()


def main(argv: list[str] | None = None) -> int:
    here = Path(__file__).resolve().parent
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", type=Path, default=here.parent / "cases" / "cylinder_on_block.msh")
    parser.add_argument("--size-near", type=float, default=0.5e-3, help="element size at the contact (m)")
    parser.add_argument("--size-far", type=float, default=10e-3, help="element size far from it (m)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.size_near) and 0 < args.size_near <= args.size_far):
        parser.error("need 0 < --size-near <= --size-far")
    build(args.out, args.size_near, args.size_far)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
