#!/usr/bin/python3
"""grid_stl.py OUT NX NY Z_EXPR: an ASCII STL of the surface z = Z_EXPR (a Python
expression in x, y and math) over a grid of NX x NY cells of 1 mm, two triangles a
cell, for the CAM integration tests."""
import math, sys

out, nx, ny, expr = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
z = eval("lambda x, y: " + expr, {"math": math})
with open(out, "w") as f:
    f.write("solid grid\n")
    for i in range(nx):
        for j in range(ny):
            a, b, c, d = (i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)
            for tri in ((a, b, c), (a, c, d)):
                f.write(" facet normal 0 0 1\n  outer loop\n")
                for (x, y) in tri:
                    f.write("   vertex %.6f %.6f %.6f\n" % (x, y, z(x, y)))
                f.write("  endloop\n endfacet\n")
    f.write("endsolid grid\n")
