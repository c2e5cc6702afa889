#include "core/mesh_primitives.h"

#include <cmath>
#include <map>
#include <numbers>
#include <vector>

#include "core/error.h"

namespace crease {

TriMesh MakeGrid(int nx, int ny, double size_x, double size_y, bool alternate_diagonals) {
  Require(nx >= 1 && ny >= 1, "MakeGrid: nx and ny must be >= 1");
  TriMesh m;
  const int vx = nx + 1, vy = ny + 1;
  m.V.resize(vx * vy, 3);
  m.UV.resize(vx * vy, 2);
  m.N.resize(vx * vy, 3);
  for (int j = 0; j < vy; ++j) {
    for (int i = 0; i < vx; ++i) {
      const int id = j * vx + i;
      const double u = static_cast<double>(i) / nx, v = static_cast<double>(j) / ny;
      m.V.row(id) << u * size_x, v * size_y, 0.0;
      m.UV.row(id) << u, v;
      m.N.row(id) << 0.0, 0.0, 1.0;
    }
  }
  m.F.resize(2 * nx * ny, 3);
  int f = 0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int a = j * vx + i, b = a + 1, c = a + vx, d = c + 1;
      if (!alternate_diagonals || (i + j) % 2 == 0) {
        m.F.row(f++) << a, b, d;
        m.F.row(f++) << a, d, c;
      } else {
        m.F.row(f++) << a, b, c;
        m.F.row(f++) << b, d, c;
      }
    }
  }
  return m;
}

TriMesh MakeUVSphere(double radius, int rings, int segments) {
  Require(rings >= 2 && segments >= 3, "MakeUVSphere: need rings >= 2 and segments >= 3");
  const double pi = std::numbers::pi;
  TriMesh m;
  const int vx = segments + 1, vy = rings + 1;
  m.V.resize(vx * vy, 3);
  m.UV.resize(vx * vy, 2);
  m.N.resize(vx * vy, 3);
  for (int j = 0; j < vy; ++j) {
    const double theta = pi * j / rings;  // colatitude from +z
    for (int i = 0; i < vx; ++i) {
      // The seam column (i = segments) and the poles repeat positions bit for bit,
      // as the seam copies of an imported mesh do.
      const double phi = i == segments ? 0.0 : 2.0 * pi * i / segments;
      Eigen::Vector3d n(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                        std::cos(theta));
      if (j == 0) n = Eigen::Vector3d::UnitZ();
      if (j == rings) n = -Eigen::Vector3d::UnitZ();
      const int id = j * vx + i;
      m.V.row(id) = radius * n.transpose();
      m.N.row(id) = n.transpose();
      m.UV.row(id) << static_cast<double>(i) / segments, static_cast<double>(j) / rings;
    }
  }
  std::vector<Eigen::Vector3i> faces;
  for (int j = 0; j < rings; ++j) {
    for (int i = 0; i < segments; ++i) {
      const int a = j * vx + i, b = a + 1, c = a + vx, d = c + 1;
      // Outward orientation: a (top-left), c (below), d, b.
      if (j != 0) faces.emplace_back(a, c, b);
      if (j != rings - 1) faces.emplace_back(b, c, d);
    }
  }
  // Pole vertices at j = 0 and j = rings are duplicated per segment (one per UV);
  // they are unreferenced except by the fans above, which is what we want.
  m.F.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) m.F.row(static_cast<int>(f)) = faces[f].transpose();
  return m;
}

TriMesh MakeIcosphere(double radius, int level) {
  Require(level >= 0 && level <= 9, "MakeIcosphere: level must be in [0, 9]");
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0},
                                    {0, -1, t}, {0, 1, t},  {0, -1, -t}, {0, 1, -t},
                                    {t, 0, -1}, {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      const int id = static_cast<int>(v.size()) - 1;
      mid.emplace(key, id);
      return id;
    };
    std::vector<Eigen::Vector3i> nf;
    nf.reserve(f.size() * 4);
    for (const auto& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                c = midpoint(tri[2], tri[0]);
      nf.emplace_back(tri[0], a, c);
      nf.emplace_back(tri[1], b, a);
      nf.emplace_back(tri[2], c, b);
      nf.emplace_back(a, b, c);
    }
    f.swap(nf);
  }
  TriMesh m;
  m.V.resize(static_cast<int>(v.size()), 3);
  m.N.resize(static_cast<int>(v.size()), 3);
  m.UV.resize(static_cast<int>(v.size()), 2);
  const double pi = std::numbers::pi;
  for (size_t i = 0; i < v.size(); ++i) {
    const int r = static_cast<int>(i);
    m.N.row(r) = v[i].transpose();
    m.V.row(r) = radius * v[i].transpose();
    m.UV.row(r) << (std::atan2(v[i].y(), v[i].x()) + pi) / (2 * pi), std::acos(std::clamp(v[i].z(), -1.0, 1.0)) / pi;
  }
  m.F.resize(static_cast<int>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(static_cast<int>(i)) = f[i].transpose();
  return m;
}

}  // namespace crease
