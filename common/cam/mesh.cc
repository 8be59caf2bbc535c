#include "common/cam/mesh.h"

#include <algorithm>
#include <cmath>

namespace cnc::cam {

Bounds mesh_bounds(const Mesh& mesh) {
  Bounds b;
  if (mesh.triangles.empty()) return b;
  b.min = b.max = mesh.triangles.front().v[0];
  for (const Triangle& t : mesh.triangles) {
    for (const Vec3& p : t.v) {
      b.min.x = std::min(b.min.x, p.x);
      b.min.y = std::min(b.min.y, p.y);
      b.min.z = std::min(b.min.z, p.z);
      b.max.x = std::max(b.max.x, p.x);
      b.max.y = std::max(b.max.y, p.y);
      b.max.z = std::max(b.max.z, p.z);
    }
  }
  return b;
}

namespace {
Vec3 sub(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
double norm2(const Vec3& a) { return a.x * a.x + a.y * a.y + a.z * a.z; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
}  // namespace

double twice_area(const Triangle& t) {
  return std::sqrt(norm2(cross(sub(t.v[1], t.v[0]), sub(t.v[2], t.v[0]))));
}

bool is_zero_area(const Triangle& t) {
  const double longest2 = std::max({norm2(sub(t.v[1], t.v[0])), norm2(sub(t.v[2], t.v[1])),
                                    norm2(sub(t.v[0], t.v[2]))});
  // |cross| <= 1e-12·longest², squared (no square root: this runs on every triangle read).
  return norm2(cross(sub(t.v[1], t.v[0]), sub(t.v[2], t.v[0]))) <= 1e-24 * longest2 * longest2;
}

}  // namespace cnc::cam
