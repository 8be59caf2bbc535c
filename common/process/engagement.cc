#include "common/process/engagement.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cnc::process {
namespace {
constexpr double kPi = std::numbers::pi;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
}  // namespace

double EngagementProfile::max_depth() const {
  double m = 0;
  for (double d : depth) m = std::max(m, d);
  return m;
}

double EngagementProfile::arc_start() const {
  const double half = phi.size() > 1 ? 0.5 * (phi[1] - phi[0]) : 0.0;
  for (size_t b = 0; b < depth.size(); ++b) {
    if (depth[b] > 0) return std::max(0.0, phi[b] - half);
  }
  return 0.0;
}

double EngagementProfile::arc_exit() const {
  const double half = phi.size() > 1 ? 0.5 * (phi[1] - phi[0]) : 0.0;
  for (size_t b = depth.size(); b-- > 0;) {
    if (depth[b] > 0) return std::min(kPi, phi[b] + half);
  }
  return 0.0;
}

EngagementProfile engagement_from_stock(const ZMap& stock, const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir,
                                        double radius, double flute_length, int bins, double feed_per_tooth) {
  EngagementProfile p;
  engagement_from_stock(stock, tip, feed_dir, radius, flute_length, bins, feed_per_tooth, &p);
  return p;
}

void engagement_from_stock(const ZMap& stock, const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir,
                           double radius, double flute_length, int bins, double feed_per_tooth, EngagementProfile* out) {
  EngagementProfile& p = *out;
  bins = std::max(2, bins);
  const Eigen::Vector2d f = feed_dir.norm() > 0 ? Eigen::Vector2d(feed_dir.normalized()) : Eigen::Vector2d(1.0, 0.0);
  const Eigen::Vector2d n(-f.y(), f.x());
  p.feed_dir = f;
  p.feed_per_tooth_mm = feed_per_tooth;
  p.phi.resize(static_cast<size_t>(bins));
  p.depth.resize(static_cast<size_t>(bins));
  // One cell outside the periphery: a column there is never one this step or the
  // previous ones removed (in the front half the periphery is outside every earlier
  // position of the tool), so it holds material exactly where the edge meets stock.
  // Just inside, the crescent a step leaves is thinner than a cell near φ = 0 and π
  // and the arc's ends would be lost. The price: a radial depth below one cell reads
  // as about sqrt(2·pitch/R) of arc at the wall.
  const double rs = radius + stock.pitch();
  for (int b = 0; b < bins; ++b) {
    const double phi = (b + 0.5) * kPi / bins;
    const Eigen::Vector2d q = tip.head<2>() + rs * (std::sin(phi) * f + std::cos(phi) * n);
    const double zs = stock.sample(q.x(), q.y());
    const double d = std::isnan(zs) ? 0.0 : std::clamp(zs - tip.z(), 0.0, flute_length);
    p.phi[static_cast<size_t>(b)] = phi;
    p.depth[static_cast<size_t>(b)] = d;
  }
}

void remove_flat_envelope(ZMap& stock, const Eigen::Vector3d& tip0, const Eigen::Vector3d& tip1, double radius) {
  const double p = stock.pitch();
  const Eigen::Vector2d a = tip0.head<2>(), b = tip1.head<2>();
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double r2 = radius * radius;
  const int i0 = std::max(0, static_cast<int>(std::floor((std::min(a.x(), b.x()) - radius - stock.x0()) / p)));
  const int i1 = std::min(stock.nx() - 1, static_cast<int>(std::ceil((std::max(a.x(), b.x()) + radius - stock.x0()) / p)));
  const int j0 = std::max(0, static_cast<int>(std::floor((std::min(a.y(), b.y()) - radius - stock.y0()) / p)));
  const int j1 = std::min(stock.ny() - 1, static_cast<int>(std::ceil((std::max(a.y(), b.y()) + radius - stock.y0()) / p)));
  for (int j = j0; j <= j1; ++j) {
    const double y = stock.y(j);
    for (int i = i0; i <= i1; ++i) {
      const Eigen::Vector2d c(stock.x(i), y);
      const double t = len2 > 0 ? std::clamp((c - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
      if ((c - a - t * ab).squaredNorm() > r2) continue;
      const auto z = static_cast<float>(tip0.z() + t * (tip1.z() - tip0.z()));
      float& cell = stock.cell(i, j);
      if (z < cell) cell = z;
    }
  }
}

Eigen::Vector3d force_from_profile(const CuttingForceModel& model, const EngagementProfile& p, double dz_max, double theta,
                                   std::vector<Eigen::Vector3d>* disc_forces, double* dz_used) {
  const EndMill& tool = model.tool();
  const double amax = p.max_depth();
  const int discs = amax > 0 ? std::max(1, static_cast<int>(std::ceil(amax / dz_max))) : 0;
  const double dz = discs > 0 ? amax / discs : dz_max;
  if (dz_used) *dz_used = dz;
  if (disc_forces) disc_forces->assign(static_cast<size_t>(discs), Eigen::Vector3d::Zero());
  const Eigen::Vector2d f = p.feed_dir, n(-p.feed_dir.y(), p.feed_dir.x());
  const double tan_h = std::tan(tool.helix_deg * kPi / 180.0);
  const double pitch = kTwoPi / tool.flutes;
  const int bins = static_cast<int>(p.depth.size());
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  for (int i = 0; i < discs; ++i) {
    const double z = (i + 0.5) * dz;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int k = 0; k < tool.flutes; ++k) {
      double phi = std::fmod(theta + k * pitch - z * tan_h / tool.radius(), kTwoPi);
      if (phi < 0) phi += kTwoPi;
      if (!(phi > 0.0 && phi < kPi)) continue;
      const int b = std::min(bins - 1, static_cast<int>(phi / kPi * bins));
      if (!(z < p.depth[static_cast<size_t>(b)])) continue;
      const double h = p.feed_per_tooth_mm * std::sin(phi);
      const Eigen::Vector3d local = project(element_force(model.material(), model.model(), h, dz), phi);
      sum += Eigen::Vector3d(local.x() * f.x() + local.y() * n.x(), local.x() * f.y() + local.y() * n.y(), local.z());
    }
    if (disc_forces) (*disc_forces)[static_cast<size_t>(i)] = sum;
    total += sum;
  }
  return total;
}

}  // namespace cnc::process
