#include "common/cam/rough.h"

#include <polyclipping/clipper.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "common/util/parallel_for.h"

namespace cnc::cam {
namespace {

namespace cl = ClipperLib;
constexpr double kScale = 1e5;  // Clipper integers per mm

cl::cInt to_int(double v) { return static_cast<cl::cInt>(std::llround(v * kScale)); }
double to_mm(cl::cInt v) { return static_cast<double>(v) / kScale; }

cl::Path to_path(const Loop& loop) {
  cl::Path p;
  p.reserve(loop.size());
  for (const XY& q : loop) p.push_back({to_int(q.x), to_int(q.y)});
  return p;
}
cl::Paths to_paths(const Polygons& polys) {
  cl::Paths ps;
  ps.reserve(polys.size());
  for (const Loop& l : polys) ps.push_back(to_path(l));
  return ps;
}
Loop to_loop(const cl::Path& p) {
  Loop l;
  l.reserve(p.size());
  for (const cl::IntPoint& q : p) l.push_back({to_mm(q.X), to_mm(q.Y)});
  return l;
}
Polygons to_polys(const cl::Paths& ps) {
  Polygons out;
  out.reserve(ps.size());
  for (const cl::Path& p : ps) out.push_back(to_loop(p));
  return out;
}

cl::Paths boolean(const cl::Paths& a, const cl::Paths& b, cl::ClipType op, cl::PolyFillType fill) {
  cl::Clipper c;
  c.AddPaths(a, cl::ptSubject, true);
  if (!b.empty()) c.AddPaths(b, cl::ptClip, true);
  cl::Paths out;
  c.Execute(op, out, fill, fill);
  return out;
}

// Round joins: Clipper rounds a join's step count to the nearest integer, which can make a
// step 1.5 times the one its arc tolerance asks for and the chord's sagitta 2.25 times the
// tolerance; asking for a quarter keeps every chord within arc_tol of the true arc.
cl::Paths offset(const cl::Paths& ps, double delta_mm, double arc_tol_mm) {
  cl::ClipperOffset co(2.0, 0.25 * arc_tol_mm * kScale);
  co.AddPaths(ps, cl::jtRound, cl::etClosedPolygon);
  cl::Paths out;
  co.Execute(out, delta_mm * kScale);
  return out;
}

// Length of the parts of open polyline `line` inside `region`.
double length_inside(const cl::Path& line, const cl::Paths& region) {
  if (region.empty()) return 0;
  cl::Clipper c;
  c.AddPath(line, cl::ptSubject, false);
  c.AddPaths(region, cl::ptClip, true);
  cl::PolyTree tree;
  c.Execute(cl::ctIntersection, tree, cl::pftNonZero, cl::pftNonZero);
  cl::Paths open;
  cl::OpenPathsFromPolyTree(tree, open);
  double len = 0;
  for (const cl::Path& p : open)
    for (std::size_t i = 1; i < p.size(); ++i)
      len += std::hypot(to_mm(p[i].X - p[i - 1].X), to_mm(p[i].Y - p[i - 1].Y));
  return len;
}

double dist2(const XY& a, const XY& b) { return (a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y); }

}  // namespace

const char* level_kind_name(LevelKind k) {
  switch (k) {
    case LevelKind::kSlope: return "slope";
    case LevelKind::kFlat: return "flat";
    case LevelKind::kFloor: return "floor";
    case LevelKind::kFacing: return "facing";
  }
  return "?";
}

Stock parse_stock(const std::string& spec, const Bounds& part) {
  Stock s{part.min.x, part.min.y, part.min.z, part.max.x, part.max.y, part.max.z};
  if (spec == "box") return s;
  double m = 2;
  if (spec.rfind("margin", 0) == 0 && (spec.size() == 6 || spec[6] == ':')) {
    if (spec.size() > 6) {
      std::size_t used = 0;
      const std::string num = spec.substr(7);
      try {
        m = std::stod(num, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (num.empty() || used != num.size() || !std::isfinite(m) || m < 0)
        throw std::invalid_argument("--stock " + spec + ": the margin must be a number >= 0 (mm)");
    }
    s.xmin -= m, s.ymin -= m, s.xmax += m, s.ymax += m, s.zmax += m;
    return s;
  }
  throw std::invalid_argument("--stock " + spec + ": expected box, margin or margin:MM");
}

std::vector<Level> choose_levels(const SlopeProfile& profile, const Cutter& cutter, double cusp_mm,
                                 double max_stepdown_mm, double zbot, double ztop, double stock_top,
                                 bool wall_at_base, double slack_mm) {
  if (!(cusp_mm > 0)) throw std::invalid_argument("cusp height must be > 0");
  if (!(max_stepdown_mm > 0)) throw std::invalid_argument("largest step-down must be > 0");
  const std::size_t bands = profile.min_slope.size();
  auto limit = [&](double th) { return std::max(cusp_mm - slack_mm * std::sin(th), 0.1 * cusp_mm); };
  std::vector<double> step(bands);  // the z-step the cusp allows at each band's smallest slope
  for (std::size_t i = 0; i < bands; ++i) {
    const double th = profile.min_slope[i];
    step[i] = std::isfinite(th) ? zstep_for_cusp(cutter, th, limit(th), max_stepdown_mm) : max_stepdown_mm;
  }
  std::vector<double> flats;
  for (double f : profile.flat_z)
    if (f > zbot + 1e-6 && f <= ztop + 1e-9) flats.push_back(f);
  std::vector<Level> out;
  const double eps = 1e-9;
  double z = zbot;
  for (;;) {
    double allowed = max_stepdown_mm, slope = std::numeric_limits<double>::infinity();
    const auto first = static_cast<std::size_t>(std::max(0.0, std::floor((z - profile.z0) / profile.dz + 1e-9)));
    const bool first_band = out.empty() && wall_at_base;
    const Cutter flat = make_cutter(cutter.diameter_mm, 0, cutter.flute_length_mm);
    for (std::size_t i = first; i < bands; ++i) {
      const double lo = profile.z0 + static_cast<double>(i) * profile.dz;
      if (lo >= z + allowed) break;
      double st = step[i];
      if (first_band && std::isfinite(profile.min_slope[i]))
        st = std::min(st, zstep_for_cusp(flat, profile.min_slope[i], limit(profile.min_slope[i]), max_stepdown_mm));
      if (st < allowed) allowed = st;
      slope = std::min(slope, profile.min_slope[i]);
    }
    double next = z + allowed;
    LevelKind kind = LevelKind::kSlope;
    const auto f = std::upper_bound(flats.begin(), flats.end(), z + eps);
    if (f != flats.end() && *f <= next + eps) {
      next = *f;
      kind = LevelKind::kFlat;
    } else if (next >= ztop - eps) {
      break;  // the cusp limit holds up to the part's top
    }
    out.push_back({next, kind, slope, next - z});
    z = next;
  }
  if (stock_top > ztop + 1e-6) {  // stock above the part: a level at the top, then up in steps
    const double zt = out.empty() ? zbot : out.back().z;
    if (ztop > zt + eps) out.push_back({ztop, LevelKind::kFacing, std::numeric_limits<double>::infinity(), ztop - zt});
    const int n = static_cast<int>(std::ceil((stock_top - ztop) / max_stepdown_mm - 1e-9));
    for (int k = 1; k < n; ++k) {
      const double zk = ztop + (stock_top - ztop) * k / n;
      out.push_back({zk, LevelKind::kFacing, std::numeric_limits<double>::infinity(), (stock_top - ztop) / n});
    }
  }
  return out;
}

Polygons keep_out(const Mesh& mesh, const Cutter& cutter, double z, int corner_samples, double arc_tol_mm) {
  return keep_out(MeshSlicer(mesh), cutter, z, corner_samples, arc_tol_mm);
}

Polygons keep_out(const MeshSlicer& slicer, const Cutter& cutter, double z, int corner_samples, double arc_tol_mm) {
  const double R = cutter.radius(), r = cutter.corner_radius_mm, a = R - r;
  const int n = r > 0 ? std::max(1, corner_samples) : 1;
  std::vector<cl::Paths> grown_all;
  for (int i = 0; i < n; ++i) {
    // Sub-level i: the part above z + h_i, grown by the radius at h_{i+1}.
    const double rho_i = a + r * i / n, rho_next = r > 0 ? a + r * (i + 1) / n : R;
    const double h_i = r > 0 ? r - std::sqrt(std::max(0.0, r * r - (rho_i - a) * (rho_i - a))) : 0;
    const Slice s = slicer.slice(z + h_i + 1e-9);
    if (s.loops.empty()) continue;
    const cl::Paths region = boolean(to_paths(s.loops), {}, cl::ctUnion, cl::pftNonZero);
    grown_all.push_back(offset(region, rho_next + arc_tol_mm, arc_tol_mm));
  }
  // Union pairwise, neighbours first: neighbouring sub-levels are nearly the same curve,
  // and merging them early keeps each union's edge count (and crossings) small.
  while (grown_all.size() > 1) {
    std::vector<cl::Paths> next;
    for (std::size_t i = 0; i + 1 < grown_all.size(); i += 2)
      next.push_back(boolean(grown_all[i], grown_all[i + 1], cl::ctUnion, cl::pftNonZero));
    if (grown_all.size() % 2) next.push_back(std::move(grown_all.back()));
    grown_all.swap(next);
  }
  if (grown_all.empty()) return {};
  return to_polys(boolean(grown_all.front(), {}, cl::ctUnion, cl::pftNonZero));
}

namespace {

cl::Paths stock_outline(const Stock& st, double grow_mm, double arc_tol_mm) {
  const cl::Path rect{{to_int(st.xmin), to_int(st.ymin)},
                      {to_int(st.xmax), to_int(st.ymin)},
                      {to_int(st.xmax), to_int(st.ymax)},
                      {to_int(st.xmin), to_int(st.ymax)}};
  if (grow_mm <= 0) return {rect};
  return offset({rect}, grow_mm, arc_tol_mm);
}

}  // namespace

std::vector<Ring> pocket_rings(const Polygons& keepout, const Stock& stock, const Cutter& cutter, double stepover_mm,
                               double arc_tol_mm, Polygons* region_out) {
  if (!(stepover_mm > 0)) throw std::invalid_argument("stepover must be > 0");
  const double R = cutter.radius();
  const cl::Paths outer = stock_outline(stock, R, arc_tol_mm);
  const cl::Paths region = boolean(outer, to_paths(keepout), cl::ctDifference, cl::pftNonZero);
  if (region_out) *region_out = to_polys(region);
  // Where the tool still cuts: inside the outline grown by R less a hair (offset-0 rings
  // along the grown outline itself are air).
  const cl::Paths inner = stock_outline(stock, R - std::min(0.01, 0.5 * stepover_mm), arc_tol_mm);
  std::vector<Ring> rings;
  const double min_area = 1e-4 * kScale * kScale;  // 0.01 mm x 0.01 mm: slivers of rounding
  for (int j = 0;; ++j) {
    const cl::Paths off = j == 0 ? region : offset(region, -j * stepover_mm, arc_tol_mm);
    bool any = false;
    for (const cl::Path& p : off) {
      if (std::fabs(cl::Area(p)) < min_area) continue;
      any = true;
      const bool hole = !cl::Orientation(p);
      if (j > 0 || hole) {
        rings.push_back({to_loop(p), j, hole, true});
        continue;
      }
      // An outer ring at offset 0: keep what lies inside `inner`, as open pieces (or the
      // whole ring if nothing of it is on the grown outline).
      cl::Path line = p;
      line.push_back(p.front());
      cl::Clipper c;
      c.AddPath(line, cl::ptSubject, false);
      c.AddPaths(inner, cl::ptClip, true);
      cl::PolyTree tree;
      c.Execute(cl::ctIntersection, tree, cl::pftNonZero, cl::pftNonZero);
      cl::Paths pieces;
      cl::OpenPathsFromPolyTree(tree, pieces);
      double kept = 0, whole = 0;
      for (std::size_t i = 1; i < line.size(); ++i)
        whole += std::hypot(to_mm(line[i].X - line[i - 1].X), to_mm(line[i].Y - line[i - 1].Y));
      for (const cl::Path& q : pieces)
        for (std::size_t i = 1; i < q.size(); ++i)
          kept += std::hypot(to_mm(q[i].X - q[i - 1].X), to_mm(q[i].Y - q[i - 1].Y));
      if (kept >= whole - 1e-6) {
        rings.push_back({to_loop(p), j, false, true});
        continue;
      }
      for (const cl::Path& q : pieces)
        if (q.size() >= 2) rings.push_back({to_loop(q), j, false, false});
    }
    if (!any) break;
  }
  // Cutting order: outer rings by rising offset, then hole rings by falling offset; within
  // one offset the nearest ring next, each started at its vertex nearest the tool.
  std::vector<Ring> ordered;
  ordered.reserve(rings.size());
  XY at{stock.xmin - cutter.radius(), stock.ymin - cutter.radius()};
  auto take_group = [&](bool hole, int j) {
    std::vector<Ring*> group;
    for (Ring& rg : rings)
      if (rg.hole == hole && rg.offset_index == j) group.push_back(&rg);
    while (!group.empty()) {
      std::size_t best = 0, best_v = 0;
      double bd = std::numeric_limits<double>::infinity();
      for (std::size_t g = 0; g < group.size(); ++g) {
        const Loop& pts = group[g]->points;
        for (std::size_t v = 0; v < pts.size(); ++v) {
          if (!group[g]->closed && v != 0 && v + 1 != pts.size()) continue;  // open pieces start at an end
          const double d = dist2(pts[v], at);
          if (d < bd) bd = d, best = g, best_v = v;
        }
      }
      Ring rg = std::move(*group[best]);
      if (rg.closed) {
        std::rotate(rg.points.begin(), rg.points.begin() + static_cast<std::ptrdiff_t>(best_v), rg.points.end());
      } else if (best_v != 0) {
        std::reverse(rg.points.begin(), rg.points.end());
      }
      at = rg.closed ? rg.points.front() : rg.points.back();
      ordered.push_back(std::move(rg));
      group.erase(group.begin() + static_cast<std::ptrdiff_t>(best));
    }
  };
  int jmax = 0;
  for (const Ring& rg : rings) jmax = std::max(jmax, rg.offset_index);
  for (int j = 0; j <= jmax; ++j) take_group(false, j);
  for (int j = jmax; j >= 0; --j) take_group(true, j);
  return ordered;
}

RoughPlan plan_roughing(const Mesh& mesh, const Stock& stock, const RoughSpec& spec,
                        const std::function<void(std::size_t, std::size_t)>& progress) {
  const Cutter& c = spec.cutter;
  if (!(spec.stepover_frac > 0 && spec.stepover_frac <= 0.9))
    throw std::invalid_argument("stepover must be a fraction of the diameter in (0, 0.9]");
  if (mesh.triangles.empty()) throw std::invalid_argument("the mesh has no triangles");
  const Bounds b = mesh_bounds(mesh);
  const double stepdown = spec.max_stepdown_mm > 0 ? spec.max_stepdown_mm : c.flute_length_mm;
  const double stepover = spec.stepover_frac * c.diameter_mm;
  RoughPlan plan;
  plan.stock = stock;
  const SlopeProfile prof = slope_profile(mesh, spec.band_mm, spec.flat_deg * M_PI / 180);
  // The floor: the part's base level, when the stock reaches beyond the part's footprint
  // there (more than stepover² of it).
  bool floor = false;
  {
    const Slice base = slice_mesh(mesh, b.min.z + 1e-9);
    const cl::Paths foot = boolean(to_paths(base.loops), {}, cl::ctUnion, cl::pftNonZero);
    double area = 0;
    for (const cl::Path& p : boolean(stock_outline(stock, 0, spec.arc_tol_mm), foot, cl::ctDifference, cl::pftNonZero))
      area += cl::Area(p) / (kScale * kScale);
    floor = area > stepover * stepover;
  }
  const int samples = spec.corner_samples > 0
                          ? spec.corner_samples
                          : std::clamp(static_cast<int>(std::ceil(c.corner_radius_mm / (0.02 * spec.cusp_mm))), 16, 64);
  const double slack = (c.corner_radius_mm > 0 ? c.corner_radius_mm / samples : 0) + spec.arc_tol_mm;
  std::vector<Level> levels =
      choose_levels(prof, c, spec.cusp_mm, stepdown, b.min.z, b.max.z, stock.zmax, !floor, slack);
  if (floor) levels.insert(levels.begin(), Level{b.min.z, LevelKind::kFloor, 0, 0});
  plan.levels = levels;
  const MeshSlicer slicer(mesh);
  const std::size_t total = levels.size();
  // Each level on its own (the keep-out, the rings, the chains), on `threads` workers
  // taking levels top-down in turn; then joined in cutting order.
  std::vector<LevelPath> per_level(total);
  auto plan_level = [&](std::size_t k) {
    const Level& lv = levels[k];
    LevelPath& lp = per_level[k];
    lp.z = lv.z;
    lp.kind = lv.kind;
    if (lv.z >= stock.zmax - 1e-9) return;  // a level at the stock's top has nothing above it to cut
    const Polygons ko = keep_out(slicer, c, lv.z, samples, spec.arc_tol_mm);
    Polygons region;
    const std::vector<Ring> rings = pocket_rings(ko, stock, c, stepover, spec.arc_tol_mm, &region);
    lp.rings = rings.size();
    // The tool-offset contour: the keep-out's boundary where the tool may be (inside the
    // stock's outline grown by R).
    const cl::Paths reach = stock_outline(stock, c.radius(), spec.arc_tol_mm);
    for (const Loop& l : ko) {
      cl::Path p = to_path(l);
      p.push_back(p.front());
      lp.contour_mm += length_inside(p, reach);
    }
    const cl::Paths ko_paths = to_paths(ko);
    std::vector<XY> chain;
    std::size_t first_end = 0;
    for (const Ring& rg : rings) {
      if (!chain.empty()) {
        const XY& from = chain.back();
        const XY& to = rg.points.front();
        const double len = std::sqrt(dist2(from, to));
        const bool ok = len <= 3 * stepover &&
                        length_inside({{to_int(from.x), to_int(from.y)}, {to_int(to.x), to_int(to.y)}}, ko_paths) < 1e-4;
        if (!ok) {
          lp.chains.push_back(std::move(chain));
          lp.ring_end.push_back(first_end);
          chain.clear();
        }
      }
      const bool starts = chain.empty();
      chain.insert(chain.end(), rg.points.begin(), rg.points.end());
      if (rg.closed) chain.push_back(rg.points.front());  // close the ring
      if (starts) first_end = rg.closed ? chain.size() - 1 : 0;
    }
    if (!chain.empty()) {
      lp.chains.push_back(std::move(chain));
      lp.ring_end.push_back(first_end);
    }
  };
  std::atomic<std::size_t> done{0};
  std::mutex report;
  auto level_done = [&] {
    const std::size_t d = done.fetch_add(1) + 1;
    if (progress) {
      const std::lock_guard<std::mutex> lock(report);
      progress(d, total);
    }
  };
  // Levels top-down; a level that fails still counts as done, and the first
  // failure is rethrown once every level has run.
  util::parallel_for(total, spec.threads, [&](std::size_t i) {
    try {
      plan_level(total - 1 - i);
    } catch (...) {
      level_done();
      throw;
    }
    level_done();
  });
  double above = stock.zmax;
  for (std::size_t k = total; k-- > 0;) {
    LevelPath& lp = per_level[k];
    lp.approach_z = std::min(above, stock.zmax) + 1;
    for (const auto& ch : lp.chains)
      for (std::size_t i = 1; i < ch.size(); ++i) plan.feed_mm += std::sqrt(dist2(ch[i - 1], ch[i]));
    plan.contour_mm += lp.contour_mm;
    plan.retracts += lp.chains.size();
    if (!lp.chains.empty()) {
      above = lp.z;
      plan.paths.push_back(std::move(lp));
    }
  }
  return plan;
}

std::vector<Vec3> ramp_into(const std::vector<XY>& chain, std::size_t ring_end, double z_from, double z_to,
                            double ramp_rad) {
  if (!(ramp_rad > 0) || ring_end < 3 || ring_end >= chain.size() || !(z_from > z_to)) return {};
  double perimeter = 0;
  for (std::size_t i = 1; i <= ring_end; ++i) perimeter += std::sqrt(dist2(chain[i - 1], chain[i]));
  const double need = (z_from - z_to) / std::tan(ramp_rad);
  if (!(perimeter > 1e-3) || need > 20 * perimeter) return {};
  // Backwards from chain[0] = chain[ring_end]: chain[ring_end − 1], …, chain[0], wrapping.
  std::vector<XY> back{chain[0]};
  double walked = 0;
  std::size_t i = ring_end;
  while (walked < need) {
    const XY& p = chain[i];
    const XY& q = chain[i - 1];
    const double seg = std::sqrt(dist2(p, q));
    if (walked + seg >= need) {
      const double f = seg > 0 ? (need - walked) / seg : 0;
      back.push_back({p.x + f * (q.x - p.x), p.y + f * (q.y - p.y)});
      walked = need;
      break;
    }
    walked += seg;
    back.push_back(q);
    i = i - 1 == 0 ? ring_end : i - 1;
  }
  std::vector<Vec3> out;
  out.reserve(back.size());
  double s = walked;  // arc length still to go to the chain's start, from the far end
  for (std::size_t k = back.size(); k-- > 0;) {
    out.push_back({back[k].x, back[k].y, z_to + (z_from - z_to) * (need > 0 ? s / need : 0)});
    if (k > 0) s -= std::sqrt(dist2(back[k], back[k - 1]));
  }
  out.back().z = z_to;
  return out;
}

PlanTime plan_time(const RoughPlan& plan, double clear_z, const TimeModel& m, double ramp_deg) {
  PlanTime t;
  bool first = true;
  XY at{};
  for (const LevelPath& lp : plan.paths)
    for (std::size_t c = 0; c < lp.chains.size(); ++c) {
      const auto& ch = lp.chains[c];
      const double approach = std::min(clear_z, lp.approach_z);
      const std::vector<Vec3> ramp =
          ramp_into(ch, c < lp.ring_end.size() ? lp.ring_end[c] : 0, approach, lp.z, ramp_deg * M_PI / 180);
      const XY s = ramp.empty() ? ch.front() : XY{ramp.front().x, ramp.front().y};
      if (!first) t.rapid_mm += std::sqrt(dist2(at, s));
      first = false;
      t.rapid_mm += (clear_z - approach) + (clear_z - lp.z);  // down to the approach height; up at the end
      if (ramp.empty()) {
        t.plunge_mm += approach - lp.z;
      } else {
        for (std::size_t i = 1; i < ramp.size(); ++i)
          t.ramp_mm += std::sqrt(dist2({ramp[i - 1].x, ramp[i - 1].y}, {ramp[i].x, ramp[i].y}) +
                                 (ramp[i].z - ramp[i - 1].z) * (ramp[i].z - ramp[i - 1].z));
      }
      for (std::size_t i = 1; i < ch.size(); ++i) t.feed_mm += std::sqrt(dist2(ch[i - 1], ch[i]));
      at = ch.back();
    }
  t.seconds = 60 * ((t.feed_mm + t.ramp_mm) / m.feed_mm_per_min + t.plunge_mm / m.plunge_mm_per_min +
                    t.rapid_mm / m.rapid_mm_per_min);
  return t;
}

std::string rough_gcode(const RoughPlan& plan, const GcodeSetup& setup, const Vec3& zero, double ramp_deg) {
  GcodeWriter w(setup);
  const double clear = setup.safe_z_mm;
  for (const LevelPath& lp : plan.paths) {
    const double z = lp.z - zero.z, approach = std::min(clear, lp.approach_z - zero.z);
    for (std::size_t c = 0; c < lp.chains.size(); ++c) {
      const auto& ch = lp.chains[c];
      std::vector<Vec3> ramp =
          ramp_into(ch, c < lp.ring_end.size() ? lp.ring_end[c] : 0, approach + zero.z, lp.z, ramp_deg * M_PI / 180);
      for (Vec3& p : ramp) p = {p.x - zero.x, p.y - zero.y, p.z - zero.z};
      const XY s = ramp.empty() ? XY{ch.front().x - zero.x, ch.front().y - zero.y} : XY{ramp.front().x, ramp.front().y};
      w.rapid({s.x, s.y, clear});
      if (approach < clear) w.rapid({s.x, s.y, approach});
      if (ramp.empty()) {
        w.feed({s.x, s.y, z}, setup.plunge_mm_per_min);
      } else {
        for (std::size_t i = 1; i < ramp.size(); ++i) w.feed(ramp[i], setup.feed_mm_per_min);
      }
      for (std::size_t i = 1; i < ch.size(); ++i) w.feed({ch[i].x - zero.x, ch[i].y - zero.y, z}, setup.feed_mm_per_min);
      w.rapid({ch.back().x - zero.x, ch.back().y - zero.y, clear});
    }
  }
  return w.finish();
}

}  // namespace cnc::cam
