#include "common/cam/shapes.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace cnc::cam {

Mesh make_height_field(const std::function<double(double, double)>& z, double x0, double y0, double x1, double y1,
                       int nx, int ny) {
  const auto cols = static_cast<std::size_t>(nx) + 1, rows = static_cast<std::size_t>(ny) + 1;
  std::vector<Vec3> g(cols * rows);
  for (std::size_t j = 0; j < rows; ++j)
    for (std::size_t i = 0; i < cols; ++i) {
      const double x = x0 + (x1 - x0) * static_cast<double>(i) / nx, y = y0 + (y1 - y0) * static_cast<double>(j) / ny;
      g[j * cols + i] = {x, y, z(x, y)};
    }
  Mesh m;
  m.triangles.reserve(2 * (cols - 1) * (rows - 1));
  for (std::size_t j = 0; j + 1 < rows; ++j)
    for (std::size_t i = 0; i + 1 < cols; ++i) {
      const Vec3 &a = g[j * cols + i], &b = g[j * cols + i + 1], &c = g[(j + 1) * cols + i + 1], &d = g[(j + 1) * cols + i];
      m.triangles.push_back({{a, b, c}});
      m.triangles.push_back({{a, c, d}});
    }
  return m;
}

Mesh make_box(double x0, double y0, double z0, double x1, double y1, double z1) {
  const Vec3 p[8] = {{x0, y0, z0}, {x1, y0, z0}, {x1, y1, z0}, {x0, y1, z0},
                     {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}};
  const int f[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                        {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
  Mesh m;
  for (const auto& t : f) m.triangles.push_back({{p[t[0]], p[t[1]], p[t[2]]}});
  return m;
}

Mesh make_frustum(double base_side, double top_side, double h) {
  const double b = base_side / 2, t = top_side / 2;
  const Vec3 lo[4] = {{-b, -b, 0}, {b, -b, 0}, {b, b, 0}, {-b, b, 0}};
  const Vec3 hi[4] = {{-t, -t, h}, {t, -t, h}, {t, t, h}, {-t, t, h}};
  Mesh m;
  for (int k = 0; k < 4; ++k) {
    const int n = (k + 1) % 4;
    m.triangles.push_back({{lo[k], lo[n], hi[n]}});
    if (t > 0) m.triangles.push_back({{lo[k], hi[n], hi[k]}});
  }
  if (t > 0) {
    m.triangles.push_back({{hi[0], hi[1], hi[2]}});
    m.triangles.push_back({{hi[0], hi[2], hi[3]}});
  }
  return m;
}

Mesh make_hemisphere(double R, int rings, int segments) {
  auto pt = [&](int i, int j) {  // ring i (0: equator, rings: pole), segment j
    const double lat = M_PI / 2 * i / rings, lon = 2 * M_PI * (j % segments) / segments;
    return Vec3{R * std::cos(lat) * std::cos(lon), R * std::cos(lat) * std::sin(lon), R * std::sin(lat)};
  };
  Mesh m;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const Vec3 a = pt(i, j), b = pt(i, j + 1), c = pt(i + 1, j + 1), d = pt(i + 1, j);
      if (i + 1 == rings) {
        m.triangles.push_back({{a, b, Vec3{0, 0, R}}});
      } else {
        m.triangles.push_back({{a, b, c}});
        m.triangles.push_back({{a, c, d}});
      }
    }
  return m;
}

Mesh make_table1_part(const std::string& which, int n) {
  double H = 0;
  if (which == "a") {
    H = 43.9;
  } else if (which == "b") {
    H = 32.4;
  } else {
    throw std::invalid_argument("Table 1 part must be a or b, not " + which);
  }
  return make_height_field(
      [H](double x, double y) {
        return std::min(H, 1.25 * H * std::cos(M_PI * x / 50) * std::cos(M_PI * y / 50));
      },
      -25, -25, 25, 25, n, n);
}

}  // namespace cnc::cam
