#include "common/cam/raster.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace cnc::cam {

std::vector<std::vector<XY>> raster_passes(const Bounds& b, const RasterSpec& spec) {
  if (!(spec.pick_mm > 0) || !(spec.step_mm > 0) || !std::isfinite(spec.angle_deg))
    throw std::invalid_argument("raster: pick and step must be > 0 and the angle finite");
  const double a = spec.angle_deg * M_PI / 180;
  const double ux = std::cos(a), uy = std::sin(a);  // along the passes
  const double vx = -uy, vy = ux;                   // across them
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (double x : {b.min.x, b.max.x})
    for (double y : {b.min.y, b.max.y}) {
      umin = std::min(umin, x * ux + y * uy), umax = std::max(umax, x * ux + y * uy);
      vmin = std::min(vmin, x * vx + y * vy), vmax = std::max(vmax, x * vx + y * vy);
    }
  const auto n_pass = static_cast<std::size_t>(std::ceil((vmax - vmin) / spec.pick_mm - 1e-9)) + 1;
  const auto n_step = static_cast<std::size_t>(std::ceil((umax - umin) / spec.step_mm - 1e-9));
  const double step = n_step > 0 ? (umax - umin) / static_cast<double>(n_step) : 0;
  std::vector<std::vector<XY>> passes(n_pass);
  for (std::size_t k = 0; k < n_pass; ++k) {
    const double v = std::min(vmax, vmin + static_cast<double>(k) * spec.pick_mm);
    std::vector<XY>& p = passes[k];
    p.reserve(n_step + 1);
    for (std::size_t i = 0; i <= n_step; ++i) {
      const double u = i == n_step ? umax : umin + static_cast<double>(i) * step;
      p.push_back({u * ux + v * vx, u * uy + v * vy});
    }
    if (k % 2 == 1) std::reverse(p.begin(), p.end());
  }
  return passes;
}

RasterPath raster_fixed_step(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec, int threads) {
  const std::vector<std::vector<XY>> passes = raster_passes(bounds, spec);
  std::vector<XY> all;
  for (const auto& p : passes) all.insert(all.end(), p.begin(), p.end());
  std::vector<ClPoint> cl(all.size());
  dc.drop_batch(all, cl, threads);
  RasterPath path;
  path.passes = passes.size();
  path.points_dropped = all.size();
  std::size_t i = 0;
  for (const auto& p : passes) {
    std::vector<Vec3> cut;
    for (std::size_t k = 0; k < p.size(); ++k, ++i) {
      if (cl[i].touched()) {
        cut.push_back({all[i].x, all[i].y, cl[i].z});
      } else if (!cut.empty()) {
        path.cuts.push_back(std::move(cut));
        cut.clear();
      }
    }
    if (!cut.empty()) path.cuts.push_back(std::move(cut));
  }
  return path;
}

}  // namespace cnc::cam
