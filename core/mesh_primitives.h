// Analytic meshes for tests, benchmarks and demos. All carry per-vertex UVs.
#pragma once

#include "core/tri_mesh.h"

namespace crease {

// Regular grid in the plane z = 0 spanning [0, size_x] × [0, size_y] mm with
// nx × ny quads, each split into two triangles along the diagonal (alternating
// diagonals when `alternate_diagonals`, which makes the triangulation symmetric).
// UV = (x / size_x, y / size_y). Normals point to +z.
TriMesh MakeGrid(int nx, int ny, double size_x, double size_y, bool alternate_diagonals = true);

// Latitude-longitude sphere of `radius` mm centred at the origin with
// `rings` × `segments` quads (poles are fans). The UV chart is the
// equirectangular map with a seam: the vertices on the seam are duplicated so
// that UVs are per-vertex. Triangles are counter-clockwise seen from outside.
TriMesh MakeUVSphere(double radius, int rings, int segments);

// Icosphere of `radius` mm: an icosahedron subdivided `level` times
// (20·4^level triangles), no seam duplicates; UVs are the spherical
// coordinates (u = longitude, v = colatitude) and are only meaningful away from the seam.
TriMesh MakeIcosphere(double radius, int level);

}  // namespace crease
