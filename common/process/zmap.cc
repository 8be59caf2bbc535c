#include "common/process/zmap.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/util/parallel_for.h"

namespace cnc::process {
namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr int kTile = 64;           // cells per tile side
constexpr int kRecomputeEvery = 1024;  // steps between tile-maximum refreshes

struct Step {
  double x, y, z, theta;
};

std::vector<Step> make_steps(const std::vector<ToolSample>& path, const ZMapCutOptions& opt) {
  std::vector<Step> steps;
  if (path.empty()) return steps;
  const double omega = kTwoPi * opt.spindle_rpm / 60.0;  // rad/s, clockwise: θ decreases
  const double max_step = opt.max_step_rad > 0 ? opt.max_step_rad : 0.01;
  auto at = [&](const ToolSample& s) { return Step{s.center.x(), s.center.y(), s.center.z(), opt.theta0_rad - omega * s.t_s}; };
  steps.push_back(at(path.front()));
  for (size_t p = 1; p < path.size(); ++p) {
    const Step a = at(path[p - 1]);
    const Step b = at(path[p]);
    const int n = std::max(1, static_cast<int>(std::ceil(std::abs(b.theta - a.theta) / max_step)));
    for (int k = 1; k <= n; ++k) {
      const double f = static_cast<double>(k) / n;
      steps.push_back({a.x + f * (b.x - a.x), a.y + f * (b.y - a.y), a.z + f * (b.z - a.z), a.theta + f * (b.theta - a.theta)});
    }
  }
  return steps;
}
}  // namespace

// One thread's rows [j0, j1) of the grid (j0 a multiple of kTile), with its tile maxima.
struct ZMapBand {
  ZMap& m;
  int j0, j1;
  int ntx, nty, ty0;
  std::vector<float> tmax;     // per tile (rows of tiles from ty0)
  std::vector<float> dilated;  // max over the 3x3 tile neighbourhood
  std::vector<char> dirty;
  float band_max = 0;
  ZMapStats stats;

  ZMapBand(ZMap& map, int row0, int row1) : m(map), j0(row0), j1(row1) {
    ntx = (m.nx_ + kTile - 1) / kTile;
    ty0 = j0 / kTile;
    nty = (j1 - 1) / kTile - ty0 + 1;
    tmax.assign(static_cast<size_t>(ntx * nty), -std::numeric_limits<float>::infinity());
    dilated = tmax;
    // The map keeps its tile maxima between cuts (a program's passes are separate
    // cuts); they are recomputed only after fill() or cell() changed the columns.
    const bool valid = m.tiles_valid_ && m.tile_max_.size() == static_cast<size_t>(ntx) * static_cast<size_t>((m.ny_ + kTile - 1) / kTile);
    if (valid) std::copy_n(m.tile_max_.begin() + static_cast<long>(ty0) * ntx, tmax.size(), tmax.begin());
    dirty.assign(tmax.size(), valid ? 0 : 1);
    refresh(true);
  }

  // The band's tiles back into the map's.
  void store() const {
    const size_t total = static_cast<size_t>(ntx) * static_cast<size_t>((m.ny_ + kTile - 1) / kTile);
    if (m.tile_max_.size() != total) return;
    std::copy(tmax.begin(), tmax.end(), m.tile_max_.begin() + static_cast<long>(ty0) * ntx);
  }

  void refresh(bool force = false) {
    bool any = force;
    for (int ty = 0; ty < nty; ++ty) {
      for (int tx = 0; tx < ntx; ++tx) {
        const size_t t = static_cast<size_t>(ty * ntx + tx);
        if (!dirty[t]) continue;
        any = true;
        float mx = -std::numeric_limits<float>::infinity();
        const int ja = std::max(j0, (ty0 + ty) * kTile), jb = std::min(j1, (ty0 + ty + 1) * kTile);
        const int ia = tx * kTile, ib = std::min(m.nx_, (tx + 1) * kTile);
        for (int j = ja; j < jb; ++j) {
          const float* row = &m.z_[static_cast<size_t>(j) * static_cast<size_t>(m.nx_)];
          for (int i = ia; i < ib; ++i) mx = std::max(mx, row[i]);
        }
        tmax[t] = mx;
      }
    }
    if (!any) return;
    band_max = -std::numeric_limits<float>::infinity();
    for (int ty = 0; ty < nty; ++ty) {
      for (int tx = 0; tx < ntx; ++tx) {
        float mx = -std::numeric_limits<float>::infinity();
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int a = tx + dx, b = ty + dy;
            if (a < 0 || b < 0 || a >= ntx || b >= nty) continue;
            mx = std::max(mx, tmax[static_cast<size_t>(b * ntx + a)]);
          }
        }
        dilated[static_cast<size_t>(ty * ntx + tx)] = mx;
        band_max = std::max(band_max, tmax[static_cast<size_t>(ty * ntx + tx)]);
      }
    }
    std::fill(dirty.begin(), dirty.end(), 0);
  }

  // The dilated tile maximum at (x, y) clamped into the band (clamping does not move
  // the point away from any cell of the band, so the dilation still covers the cells
  // within a tile of it).
  float local_max(double px, double py) const {
    const double fi = std::clamp((px - m.x0_) / m.pitch_, 0.0, m.nx_ - 0.5);
    const double fj = std::clamp((py - m.y0_) / m.pitch_, static_cast<double>(j0), j1 - 0.5);
    const int tx = static_cast<int>(fi) / kTile;
    const int ty = static_cast<int>(fj) / kTile - ty0;
    return dilated[static_cast<size_t>(ty * ntx + tx)];
  }

  void sweep(const std::vector<Step>& steps, const BallCutter& tool) {
    const double r = tool.radius_mm;
    const double r2 = r * r;
    const double p = m.pitch_;
    const double bx0 = m.x0_, bx1 = m.x0_ + m.nx_ * p;
    const double by0 = m.y0_ + j0 * p, by1 = m.y0_ + j1 * p;
    const double walk = 0.5 * kTile * p;
    int units = 0;
    for (size_t s = 0; s + 1 < steps.size(); ++s) {
      const Step& a = steps[s];
      const Step& b = steps[s + 1];
      stats.steps++;
      // Distance from the step's centres to the band: no edge point nearer than that.
      auto dist_rect = [&](double x, double y) {
        const double dx = std::max({bx0 - x, 0.0, x - bx1});
        const double dy = std::max({by0 - y, 0.0, y - by1});
        return std::sqrt(dx * dx + dy * dy);
      };
      const double move = std::hypot(b.x - a.x, b.y - a.y);
      const double rho_lo = std::max(0.0, std::min(dist_rect(a.x, a.y), dist_rect(b.x, b.y)) - move);
      if (rho_lo > r) continue;
      const double czmin = std::min(a.z, b.z);
      const double depth = czmin - band_max;  // the ball centre's height above the highest column
      if (depth >= r) continue;
      const double rho_hi = depth <= 0 ? r : std::sqrt(std::max(0.0, r2 - depth * depth));
      if (rho_lo > rho_hi) continue;
      for (int k = 0; k < tool.flutes; ++k) {
        const double off = kTwoPi * k / tool.flutes;
        const double u0x = std::cos(a.theta + off), u0y = std::sin(a.theta + off);
        const double u1x = std::cos(b.theta + off), u1y = std::sin(b.theta + off);
        // Walk out along the edge: radii where the edge can be below the tiles' maxima.
        double ia_lo = -1, ia_hi = -1;
        auto flush = [&](double lo, double hi) { rasterise(a, b, u0x, u0y, u1x, u1y, lo, hi, r2); };
        for (double rho = rho_lo; rho <= rho_hi + walk; rho += walk) {
          const double lo = std::max(rho_lo, rho - 0.5 * walk);
          const double hi = std::min(rho_hi, rho + 0.5 * walk);
          if (lo > hi) break;
          const double ze = czmin - std::sqrt(std::max(0.0, r2 - lo * lo));
          const double mid = std::min(rho, rho_hi);
          const float lm = std::max(local_max(a.x + mid * u0x, a.y + mid * u0y), local_max(b.x + mid * u1x, b.y + mid * u1y));
          if (ze < lm) {
            if (ia_lo < 0) ia_lo = lo;
            ia_hi = hi;
          } else if (ia_lo >= 0) {
            flush(ia_lo, ia_hi);
            ia_lo = ia_hi = -1;
          }
        }
        if (ia_lo >= 0) flush(ia_lo, ia_hi);
      }
      if (++units % kRecomputeEvery == 0) refresh();
    }
    refresh();
  }

  void rasterise(const Step& a, const Step& b, double u0x, double u0y, double u1x, double u1y, double rho_a,
                 double rho_b, double r2) {
    const double p = m.pitch_;
    const double qx[4] = {a.x + rho_a * u0x, a.x + rho_b * u0x, b.x + rho_b * u1x, b.x + rho_a * u1x};
    const double qy[4] = {a.y + rho_a * u0y, a.y + rho_b * u0y, b.y + rho_b * u1y, b.y + rho_a * u1y};
    const double ymin = std::min({qy[0], qy[1], qy[2], qy[3]}) - p;
    const double ymax = std::max({qy[0], qy[1], qy[2], qy[3]}) + p;
    int ja = static_cast<int>(std::floor((ymin - m.y0_) / p - 0.5));
    int jb = static_cast<int>(std::ceil((ymax - m.y0_) / p - 0.5));
    ja = std::max(ja, j0);
    jb = std::min(jb, j1 - 1);
    const double r = std::sqrt(r2);
    for (int j = ja; j <= jb; ++j) {
      const double yc = m.y0_ + (j + 0.5) * p;
      double xlo = std::numeric_limits<double>::infinity(), xhi = -xlo;
      for (int e = 0; e < 4; ++e) {
        const int f = (e + 1) % 4;
        const double ya = qy[e], yb = qy[f];
        const double lo = std::min(ya, yb) - p, hi = std::max(ya, yb) + p;
        if (yc < lo || yc > hi) continue;
        if (std::abs(yb - ya) < 1e-12) {
          xlo = std::min({xlo, qx[e], qx[f]});
          xhi = std::max({xhi, qx[e], qx[f]});
          continue;
        }
        const double t = std::clamp((yc - ya) / (yb - ya), 0.0, 1.0);
        const double xi = qx[e] + t * (qx[f] - qx[e]);
        xlo = std::min(xlo, xi);
        xhi = std::max(xhi, xi);
      }
      if (!(xlo <= xhi)) continue;
      int ia = static_cast<int>(std::floor((xlo - p - m.x0_) / p - 0.5));
      int ib = static_cast<int>(std::ceil((xhi + p - m.x0_) / p - 0.5));
      ia = std::max(ia, 0);
      ib = std::min(ib, m.nx_ - 1);
      float* row = &m.z_[static_cast<size_t>(j) * static_cast<size_t>(m.nx_)];
      const double pya0 = yc - a.y, pyb0 = yc - b.y;
      for (int i = ia; i <= ib; ++i) {
        const double xc = m.x0_ + (i + 0.5) * p;
        const double d0 = u0x * pya0 - u0y * (xc - a.x);
        const double d1 = u1x * pyb0 - u1y * (xc - b.x);
        stats.cells_visited++;
        if ((d0 > 0 && d1 > 0) || (d0 < 0 && d1 < 0)) continue;
        const double den = d0 - d1;
        if (den == 0.0) continue;
        const double l = d0 / den;
        const double cx = a.x + l * (b.x - a.x), cy = a.y + l * (b.y - a.y);
        double ux = u0x + l * (u1x - u0x), uy = u0y + l * (u1y - u0y);
        const double inv = 1.0 / std::sqrt(ux * ux + uy * uy);
        ux *= inv;
        uy *= inv;
        const double rho = (xc - cx) * ux + (yc - cy) * uy;
        if (rho < 0 || rho > r) continue;
        const double z = a.z + l * (b.z - a.z) - std::sqrt(r2 - rho * rho);
        const auto zf = static_cast<float>(z);
        if (zf < row[i]) {
          row[i] = zf;
          stats.cells_cut++;
          dirty[static_cast<size_t>((j / kTile - ty0) * ntx + i / kTile)] = 1;
        }
      }
    }
  }
};

ZMap::ZMap(double x0, double y0, double pitch, int nx, int ny, double z_init)
    : x0_(x0), y0_(y0), pitch_(pitch), nx_(std::max(1, nx)), ny_(std::max(1, ny)),
      z_(static_cast<size_t>(nx_) * static_cast<size_t>(ny_), static_cast<float>(z_init)) {}

double ZMap::sample(double px, double py) const {
  const double fi = std::floor((px - x0_) / pitch_), fj = std::floor((py - y0_) / pitch_);
  if (!(fi >= 0 && fj >= 0 && fi < nx_ && fj < ny_)) return std::numeric_limits<double>::quiet_NaN();
  return z(static_cast<int>(fi), static_cast<int>(fj));
}

void ZMap::reset(double z) {
  tiles_valid_ = false;
  std::fill(z_.begin(), z_.end(), static_cast<float>(z));
}

void ZMap::fill(const std::function<double(double, double)>& z_of_xy) {
  tiles_valid_ = false;
  for (int j = 0; j < ny_; ++j) {
    for (int i = 0; i < nx_; ++i) z_[static_cast<size_t>(j) * static_cast<size_t>(nx_) + static_cast<size_t>(i)] = static_cast<float>(z_of_xy(x(i), y(j)));
  }
}

ZMapStats ZMap::cut(const BallCutter& tool, const std::vector<ToolSample>& path, const ZMapCutOptions& opt) {
  const std::vector<Step> steps = make_steps(path, opt);
  const int tile_rows = (ny_ + kTile - 1) / kTile;
  const int threads = std::clamp(opt.threads, 1, tile_rows);
  std::vector<ZMapBand> bands;
  bands.reserve(static_cast<size_t>(threads));
  for (int t = 0; t < threads; ++t) {
    const int tr0 = tile_rows * t / threads, tr1 = tile_rows * (t + 1) / threads;
    bands.emplace_back(*this, tr0 * kTile, std::min(ny_, tr1 * kTile));
  }
  util::parallel_for(bands.size(), threads, [&](std::size_t k) { bands[k].sweep(steps, tool); });
  const size_t tiles = static_cast<size_t>((nx_ + kTile - 1) / kTile) * static_cast<size_t>(tile_rows);
  tile_max_.assign(tiles, 0.0f);
  for (const ZMapBand& b : bands) b.store();
  tiles_valid_ = true;
  ZMapStats total;
  total.steps = bands[0].stats.steps;
  for (const ZMapBand& b : bands) {
    total.cells_visited += b.stats.cells_visited;
    total.cells_cut += b.stats.cells_cut;
  }
  return total;
}

double zmap_rmax(const ZMap& m, const std::function<double(double, double, double)>& dev, int i0, int i1, int j0,
                 int j1) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int j = std::max(0, j0); j < std::min(m.ny(), j1); ++j) {
    for (int i = std::max(0, i0); i < std::min(m.nx(), i1); ++i) {
      const double d = dev(m.x(i), m.y(j), m.z(i, j));
      lo = std::min(lo, d);
      hi = std::max(hi, d);
    }
  }
  return hi >= lo ? hi - lo : 0.0;
}

RmaxMap zmap_rmax_map(const ZMap& m, const std::function<double(double, double, double)>& dev, int bx, int by) {
  RmaxMap out;
  out.bx = std::max(1, bx);
  out.by = std::max(1, by);
  out.nbx = m.nx() / out.bx;
  out.nby = m.ny() / out.by;
  for (int b = 0; b < out.nby; ++b) {
    for (int a = 0; a < out.nbx; ++a) {
      out.rmax.push_back(zmap_rmax(m, dev, a * out.bx, (a + 1) * out.bx, b * out.by, (b + 1) * out.by));
    }
  }
  return out;
}

InclinedPlaneResult simulate_inclined_plane(const InclinedPlaneCase& c, ZMap* keep) {
  const double r = c.radius_mm;
  const double sa = std::sin(c.alpha_rad), ca = std::cos(c.alpha_rad);
  const int nx = static_cast<int>(std::lround(c.window_x_mm / c.pitch_mm));
  const int ny = static_cast<int>(std::lround(c.window_y_mm / c.pitch_mm));
  ZMap map(0.0, 0.0, c.pitch_mm, nx, ny, 0.0);
  const double lift = c.allowance_mm / ca;
  map.fill([&](double x, double) { return x * sa / ca + lift; });
  // Passes along d = (cos α, 0, sin α); centre = s·d + r·n + (0, y, 0), n = (−sin α, 0, cos α).
  const double margin = r + 2 * c.feed_per_tooth_mm;
  const double s0 = (-margin + r * sa) / ca;
  const double s1 = (c.window_x_mm + margin + r * sa) / ca;
  const double rpm = 10000.0;
  const double v = c.flutes * rpm * c.feed_per_tooth_mm / 60.0;  // mm/s
  ZMapCutOptions opt;
  opt.spindle_rpm = rpm;
  opt.max_step_rad = c.max_step_rad;
  opt.threads = c.threads;
  const int q0 = static_cast<int>(std::floor(-r / c.pick_feed_mm)) - 1;
  const int q1 = static_cast<int>(std::ceil((c.window_y_mm + r) / c.pick_feed_mm)) + 1;
  InclinedPlaneResult res;
  const auto t0 = std::chrono::steady_clock::now();
  for (int q = q0; q <= q1; ++q) {
    const double y = q * c.pick_feed_mm;
    auto centre = [&](double s) { return Eigen::Vector3d(s * ca - r * sa, y, s * sa + r * ca); };
    const std::vector<ToolSample> path{{0.0, centre(s0)}, {(s1 - s0) / v, centre(s1)}};
    opt.theta0_rad = q * c.pass_phase_rad;
    const ZMapStats st = map.cut({r, c.flutes}, path, opt);
    res.stats.steps += st.steps;
    res.stats.cells_visited += st.cells_visited;
    res.stats.cells_cut += st.cells_cut;
  }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  res.cells = static_cast<long long>(nx) * ny;
  res.rmax_mm = zmap_rmax(map, [&](double x, double, double z) { return -x * sa + z * ca; }, 0, nx, 0, ny);
  if (keep) *keep = std::move(map);
  return res;
}

}  // namespace cnc::process
