// cnc-cam: offline CAM on triangle meshes (seeds 002, 003).
//
//   cnc-cam drop --stl MESH --tool ball:D|flat:D|bull:D:r --points XY.csv --out XYZ.csv [--threads N]
//   cnc-cam rough --stl MESH --stock box|margin[:MM] --tool SPEC --cusp H --out rough.ngc
//                 [--png FILE] [--compare SPEC,SPEC,...] [--stepover F] [--max-stepdown MM]
//                 [--origin corner|mesh] [--feed F] [--plunge F] [--rapid F] [--spindle S] [--safe-z Z]
//                 [--ramp DEG] [--threads N]
//   cnc-cam part --shape table1-a|table1-b|hemisphere|frustum --out MESH.stl [--cells N]
//   cnc-cam raster --stl MESH --tool SPEC --pick P --step S [--angle A] --out part.ngc
//                  [--tol-beta B [--tol-alpha A] [--min-step M] [--compare-fixed]]
//                  [--origin corner|mesh] [--feed F] [--plunge F] [--spindle S] [--safe-z Z] [--threads N]
//                  [--nurbs TOL]
//
// drop: the drop-cutter's CL height for each point of XY.csv, in order, into XYZ.csv
// (x and y echoed as written, z empty where nothing is touched); prints
// "points=N seconds=S pts_per_s=R" on stdout (S: the queries only), and on stderr
// the mesh's load and the index's build, and progress for runs over a second.
//
// rough: seed 002's z-level roughing (common/cam/rough.h): levels bottom-up from the
// smallest slope on each contour and the cusp limit, plus flat areas; per level the
// tool-offset contour (Clipper) and rings stepping in from the stock by --stepover
// (a fraction of D, default 0.4), linked at the level or via the clearance plane;
// G-code through the common writer. Prints one line per level and the totals; with
// --compare, the same plan for each listed tool: levels, path length and the time of
// a constant-speed model (feed, plunge, rapid; no acceleration). --png draws the levels
// (tools/cam/plot_rough.py, Debian's python3 and matplotlib).
//
// part: writes an analytic test part as binary STL (common/cam/shapes.h).
//
// raster: parallel passes written as G-code (common/cam/gcode_writer.h), with a fixed
// step, or with --tol-beta seed 003's step control up to --step (common/cam/raster.h);
// then the path's measured deviation from the exact CL surface (32 CL points inside
// every segment) is printed, and with --compare-fixed the point count of the largest
// fixed step (--step halved until it holds) that is as accurate. --tol-alpha is the
// mesh's own tolerance against the design surface, which the mesh does not tell: it is
// only reported with the budget α + β. --origin corner (default) puts the program's zero at
// the mesh's lowest x and y and its highest z (the part's top), so cuts are at Z <= 0;
// --origin mesh keeps the mesh's coordinates. --nurbs TOL writes each cut as G6.2 cubic
// NURBS fitted to its CL points within TOL (GcodeWriter::cut_nurbs), not as G1 lines.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <sstream>
#include <string>
#include <thread>

#include "common/cam/cutter.h"
#include "common/cam/drop_cutter.h"
#include "common/cam/gcode_writer.h"
#include "common/cam/raster.h"
#include "common/cam/rough.h"
#include "common/cam/shapes.h"
#include "common/cam/points_csv.h"
#include "common/cam/stl.h"

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct DropArgs {
  std::string stl, tool, points, out;
  int threads = 0;
};

int run_drop(const DropArgs& a) {
  using namespace cnc::cam;
  const Cutter cutter = parse_cutter(a.tool);
  auto t0 = Clock::now();
  StlInfo info;
  const Mesh mesh = read_stl(a.stl, &info);
  const double load_s = seconds_since(t0);
  std::fprintf(stderr, "cnc-cam drop: %s: %zu triangles (%s, %zu zero-area skipped), %.1f MB read in %.3f s\n",
               a.stl.c_str(), mesh.triangles.size(), info.binary ? "binary" : "ASCII", info.zero_area_skipped,
               static_cast<double>(info.bytes) / 1e6, load_s);
  const PointsCsv pts = read_points_csv(a.points);
  t0 = Clock::now();
  const DropCutter dc(mesh, cutter);
  std::fprintf(stderr, "cnc-cam drop: index built in %.3f s (cell %.3g mm, %zu entries)\n", seconds_since(t0),
               dc.cell_mm(), dc.index_entries());

  const int threads = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::vector<ClPoint> out(pts.points.size());
  std::atomic<std::size_t> done{0};
  t0 = Clock::now();
  Clock::time_point t1;  // the worker's own end: the progress loop below polls only every 50 ms
  std::thread worker([&] {
    dc.drop_batch(pts.points, out, threads, &done);
    t1 = Clock::now();
  });
  double next_report = 1.0;
  while (done.load() < pts.points.size()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const double t = seconds_since(t0);
    if (t >= next_report) {
      const auto n = done.load();
      const double rate = static_cast<double>(n) / t;
      std::fprintf(stderr, "cnc-cam drop: %zu / %zu points, %.0f pts/s, %.1f s left\n", n, pts.points.size(), rate,
                   rate > 0 ? static_cast<double>(pts.points.size() - n) / rate : 0.0);
      next_report += 1.0;
    }
  }
  worker.join();
  const double s = std::chrono::duration<double>(t1 - t0).count();
  write_xyz_csv(a.out, pts, out);
  std::printf("points=%zu seconds=%.6f pts_per_s=%.0f\n", pts.points.size(), s,
              s > 0 ? static_cast<double>(pts.points.size()) / s : 0.0);
  return 0;
}

struct RasterArgs {
  std::string stl, tool, out, origin = "corner";
  double pick = 1, step = 0.1, angle = 0, feed = 1000, plunge = 300, spindle = 10000, safe_z = 2;
  double beta = 0, alpha = 0, min_step = 1e-3, nurbs = 0;
  bool compare_fixed = false;
  int threads = 0;
};

std::size_t cl_point_count(const cnc::cam::RasterPath& p) {
  std::size_t n = 0;
  for (const auto& c : p.cuts) n += c.size();
  return n;
}

int run_raster(const RasterArgs& a) {
  using namespace cnc::cam;
  const Cutter cutter = parse_cutter(a.tool);
  if (a.origin != "corner" && a.origin != "mesh") throw std::invalid_argument("--origin must be corner or mesh");
  const Mesh mesh = read_stl(a.stl);
  const Bounds b = mesh_bounds(mesh);
  const DropCutter dc(mesh, cutter);
  const int threads = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const auto t0 = Clock::now();
  const RasterSpec spec{a.pick, a.step, a.angle};
  RasterPath path = a.beta > 0 ? raster_adaptive(dc, b, spec, AdaptiveSpec{a.beta, a.min_step}, threads)
                               : raster_fixed_step(dc, b, spec, threads);
  const double s = seconds_since(t0);
  const double deviation = path_deviation(dc, path, 32, threads);
  std::fprintf(stderr, "cnc-cam raster: %s: %zu CL points, largest deviation from the CL surface %.3g mm%s\n",
               a.beta > 0 ? "step control" : "fixed step", cl_point_count(path), deviation,
               a.beta > 0 ? (" (beta " + std::to_string(a.beta) + ", alpha + beta " + std::to_string(a.alpha + a.beta) +
                             ")").c_str()
                          : "");
  if (a.compare_fixed && a.beta > 0) {
    for (double st = a.step; st >= a.min_step; st *= 0.5) {
      const RasterPath fixed = raster_fixed_step(dc, b, RasterSpec{a.pick, st, a.angle}, threads);
      const double dev = path_deviation(dc, fixed, 32, threads);
      std::fprintf(stderr, "cnc-cam raster: fixed step %.4g mm: %zu CL points, deviation %.3g mm\n", st,
                   cl_point_count(fixed), dev);
      if (dev <= a.beta) {
        std::fprintf(stderr, "cnc-cam raster: as accurate: fixed step %zu points, step control %zu (%.2fx fewer)\n",
                     cl_point_count(fixed), cl_point_count(path),
                     static_cast<double>(cl_point_count(fixed)) / static_cast<double>(cl_point_count(path)));
        break;
      }
    }
  }
  const Vec3 zero = a.origin == "corner" ? Vec3{b.min.x, b.min.y, b.max.z} : Vec3{0, 0, 0};
  GcodeSetup setup;
  setup.title = "cnc-cam raster " + a.stl + " tool " + a.tool + " pick " + std::to_string(a.pick) + " step " +
                std::to_string(a.step) + " angle " + std::to_string(a.angle) +
                (a.origin == "corner" ? ", zero at the mesh's min x, min y, max z" : ", mesh coordinates");
  setup.cutter = cutter;
  setup.feed_mm_per_min = a.feed;
  setup.plunge_mm_per_min = a.plunge;
  setup.spindle_rpm = a.spindle;
  setup.safe_z_mm = a.safe_z + (a.origin == "mesh" ? b.max.z : 0);
  GcodeWriter w(setup);
  std::size_t cl_points = 0;
  double fit_error = 0;
  std::vector<Vec3> samples;
  for (std::vector<Vec3>& cut : path.cuts) {
    for (Vec3& p : cut) p = {p.x - zero.x, p.y - zero.y, p.z - zero.z};
    cl_points += cut.size();
    if (a.nurbs > 0) {
      fit_error = std::max(fit_error, w.cut_nurbs(cut.data(), cut.size(), a.nurbs, &samples));
    } else {
      w.cut(cut.data(), cut.size());
    }
  }
  if (a.nurbs > 0) {
    // The written curves against the exact CL surface: height differences at 16 points a
    // knot span (where the cutter touches the mesh).
    std::vector<XY> xy(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) xy[i] = {samples[i].x + zero.x, samples[i].y + zero.y};
    std::vector<ClPoint> cl(xy.size());
    dc.drop_batch(xy, cl, threads);
    double dev = 0;
    for (std::size_t i = 0; i < cl.size(); ++i)
      if (cl[i].touched()) dev = std::max(dev, std::fabs(samples[i].z - (cl[i].z - zero.z)));
    std::fprintf(stderr, "cnc-cam raster: NURBS: largest height difference from the CL surface %.3g mm (%zu samples)\n",
                 dev, samples.size());
    std::fprintf(stderr,
                 "cnc-cam raster: NURBS: %zu G6.2 curves, %zu control points for %zu CL points, largest fit error %.3g mm "
                 "(tolerance %g mm, + 8.7e-5 mm for the written digits)\n",
                 w.nurbs_blocks(), w.nurbs_control_points(), cl_points, fit_error, a.nurbs);
  }
  const std::string text = w.finish();
  std::FILE* f = std::fopen(a.out.c_str(), "w");
  if (!f || std::fwrite(text.data(), 1, text.size(), f) != text.size() || std::fclose(f) != 0)
    throw std::runtime_error(a.out + ": cannot write");
  std::fprintf(stderr, "cnc-cam raster: %zu passes, %zu cuts, %zu CL points on the surface, %zu G1 moves, %.1f mm of feed\n",
               path.passes, path.cuts.size(), cl_points, w.feed_moves(), w.feed_length_mm());
  std::printf("points=%zu seconds=%.6f pts_per_s=%.0f\n", path.points_dropped, s,
              s > 0 ? static_cast<double>(path.points_dropped) / s : 0.0);
  return 0;
}


struct RoughArgs {
  std::string stl, stock = "box", tool, out, png, compare, origin = "corner";
  double cusp = 0, stepover = 0.4, max_stepdown = 0, feed = 1000, plunge = 300, rapid = 15000, spindle = 10000,
         safe_z = 2, ramp = 0;
  int threads = 0;
};

std::string fmt_g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::vector<std::string> split_commas(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

int run_rough(const RoughArgs& a) {
  using namespace cnc::cam;
  if (a.origin != "corner" && a.origin != "mesh") throw std::invalid_argument("--origin must be corner or mesh");
  const Mesh mesh = read_stl(a.stl);
  const Bounds b = mesh_bounds(mesh);
  const Stock stock = parse_stock(a.stock, b);
  const TimeModel tm{a.feed, a.plunge, a.rapid};
  const Vec3 zero = a.origin == "corner" ? Vec3{stock.xmin, stock.ymin, stock.zmax} : Vec3{0, 0, 0};
  const double clear = a.safe_z + (a.origin == "mesh" ? stock.zmax : 0);
  auto plan_for = [&](const std::string& tool) {
    RoughSpec spec;
    spec.cutter = parse_cutter(tool);
    spec.cusp_mm = a.cusp;
    spec.stepover_frac = a.stepover;
    spec.max_stepdown_mm = a.max_stepdown;
    spec.threads = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    const auto t0 = Clock::now();
    bool reported = false;
    RoughPlan plan = plan_roughing(mesh, stock, spec, [&](std::size_t done, std::size_t total) {
      const double t = seconds_since(t0);
      if (t >= 1.0 && done < total) {
        const double rate = static_cast<double>(done) / t;
        std::fprintf(stderr, "cnc-cam rough: %s: %zu / %zu levels, %.2f levels/s, %.1f s left\n", tool.c_str(), done,
                     total, rate, static_cast<double>(total - done) / rate);
        reported = true;
      }
    });
    if (reported) std::fprintf(stderr, "cnc-cam rough: %s: planned in %.1f s\n", tool.c_str(), seconds_since(t0));
    return plan;
  };
  auto print_plan = [&](const std::string& tool, const RoughPlan& plan) {
    const PlanTime t = plan_time(plan, clear + zero.z, tm, a.ramp);
    std::string zs;
    for (const Level& l : plan.levels) {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%s%.2f", zs.empty() ? "" : "/", l.z - b.min.z);
      zs += buf;
    }
    std::printf("tool=%s levels=%zu heights=%s path_mm=%.1f contour_mm=%.1f ramp_mm=%.1f plunge_mm=%.1f "
                "rapid_mm=%.1f chains=%zu time_s=%.1f\n",
                tool.c_str(), plan.levels.size(), zs.c_str(), t.feed_mm, plan.contour_mm, t.ramp_mm, t.plunge_mm,
                t.rapid_mm, plan.retracts, t.seconds);
  };
  const RoughPlan plan = plan_for(a.tool);
  for (const Level& l : plan.levels)
    std::fprintf(stderr, "cnc-cam rough: level z=%.3f (%.3f above the base) %s step %.3f smallest slope %.2f deg\n", l.z,
                 l.z - b.min.z, level_kind_name(l.kind), l.step_mm,
                 std::isfinite(l.min_slope_rad) ? l.min_slope_rad * 180 / M_PI : -1.0);
  print_plan(a.tool, plan);
  GcodeSetup setup;
  setup.title = "cnc-cam rough " + a.stl + " tool " + a.tool + " cusp " + fmt_g(a.cusp) + " stock " + a.stock +
                (a.origin == "corner" ? ", zero at the stock's min x, min y, top" : ", mesh coordinates");
  setup.cutter = parse_cutter(a.tool);
  setup.feed_mm_per_min = a.feed;
  setup.plunge_mm_per_min = a.plunge;
  setup.spindle_rpm = a.spindle;
  setup.safe_z_mm = clear;
  const std::string text = rough_gcode(plan, setup, zero, a.ramp);
  std::FILE* f = std::fopen(a.out.c_str(), "w");
  if (!f || std::fwrite(text.data(), 1, text.size(), f) != text.size() || std::fclose(f) != 0)
    throw std::runtime_error(a.out + ": cannot write");
  if (!a.compare.empty()) {
    std::vector<std::pair<std::string, RoughPlan>> plans;
    for (const std::string& tool : split_commas(a.compare)) plans.emplace_back(tool, plan_for(tool));
    std::printf("compare (feed %g, plunge %g, rapid %g mm/min, constant speeds, no acceleration):\n", a.feed, a.plunge,
                a.rapid);
    const double ref = plan_time(plans.front().second, clear + zero.z, tm, a.ramp).feed_mm;
    const double ref_c = plans.front().second.contour_mm;
    for (const auto& [tool, p] : plans) {
      print_plan(tool, p);
      const PlanTime t = plan_time(p, clear + zero.z, tm, a.ramp);
      std::printf("  vs %s: path %+.1f %%, contour %+.1f %%\n", plans.front().first.c_str(),
                  100 * (t.feed_mm / ref - 1), 100 * (p.contour_mm / ref_c - 1));
    }
  }
  if (!a.png.empty()) {
    for (const std::string* arg : {&a.png, &a.tool})
      if (arg->find('\'') != std::string::npos) throw std::invalid_argument("--png: no quote (') in " + *arg + ", please");
    const std::string csv = a.png + ".levels.csv";
    std::FILE* c = std::fopen(csv.c_str(), "w");
    if (!c) throw std::runtime_error(csv + ": cannot write");
    std::fprintf(c, "kind,level,z,chain,x,y\n");
    for (std::size_t i = 0; i < plan.paths.size(); ++i)
      for (std::size_t k = 0; k < plan.paths[i].chains.size(); ++k)
        for (const XY& p : plan.paths[i].chains[k])
          std::fprintf(c, "path,%zu,%.4f,%zu,%.4f,%.4f\n", i, plan.paths[i].z, k, p.x, p.y);
    const SlopeProfile prof = slope_profile(mesh, 0.01, 0.5 * M_PI / 180);
    for (std::size_t i = 0; i < prof.min_slope.size(); ++i)
      if (std::isfinite(prof.min_slope[i]))
        std::fprintf(c, "slope,%zu,%.4f,0,%.4f,0\n", i, prof.z0 + (static_cast<double>(i) + 0.5) * prof.dz,
                     prof.min_slope[i] * 180 / M_PI);
    for (const Level& l : plan.levels) std::fprintf(c, "level,0,%.4f,0,0,0\n", l.z);
    std::fclose(c);
    const std::string cmd = std::string("/usr/bin/python3 '") + CNC_SOURCE_DIR + "/tools/cam/plot_rough.py' '" + csv +
                            "' '" + a.png + "' '" + a.tool + " cusp " + fmt_g(a.cusp) + "'";
    if (std::system(cmd.c_str()) != 0) throw std::runtime_error("plot_rough.py failed for " + a.png);
    std::remove(csv.c_str());
  }
  return 0;
}

struct PartArgs {
  std::string shape, out;
  int cells = 200;
};

int run_part(const PartArgs& a) {
  using namespace cnc::cam;
  Mesh m;
  if (a.shape == "table1-a") m = make_table1_part("a", a.cells);
  else if (a.shape == "table1-b") m = make_table1_part("b", a.cells);
  else if (a.shape == "hemisphere") m = make_hemisphere(20, a.cells / 4, a.cells);
  else if (a.shape == "frustum") m = make_frustum(50, 10, 30);
  else throw std::invalid_argument("--shape must be table1-a, table1-b, hemisphere or frustum, not " + a.shape);
  write_stl_binary(a.out, m);
  std::fprintf(stderr, "cnc-cam part: %s: %zu triangles to %s\n", a.shape.c_str(), m.triangles.size(), a.out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"cnc-cam: offline CAM on triangle meshes (drop-cutter by inverse offset)"};
  app.require_subcommand(1);
  DropArgs drop;
  CLI::App* d = app.add_subcommand("drop", "CL heights of a cutter dropped onto a mesh at given points");
  d->add_option("--stl", drop.stl, "mesh, ASCII or binary STL")->required();
  d->add_option("--tool", drop.tool, "ball:D, flat:D or bull:D:r (mm; optional :L=flute length)")->required();
  d->add_option("--points", drop.points, "CSV with header x,y")->required();
  d->add_option("--out", drop.out, "CSV x,y,z to write")->required();
  d->add_option("--threads", drop.threads, "worker threads (default: all cores)")->check(CLI::Range(1, 256));
  RasterArgs raster;
  CLI::App* r = app.add_subcommand("raster", "parallel finishing passes with a fixed step, as G-code");
  r->add_option("--stl", raster.stl, "mesh, ASCII or binary STL")->required();
  r->add_option("--tool", raster.tool, "ball:D, flat:D or bull:D:r (mm)")->required();
  r->add_option("--pick", raster.pick, "distance between passes, mm")->required()->check(CLI::PositiveNumber);
  r->add_option("--step", raster.step, "largest distance between CL points along a pass, mm")->required()->check(CLI::PositiveNumber);
  r->add_option("--angle", raster.angle, "direction of the passes, degrees from +X");
  r->add_option("--out", raster.out, "G-code file to write")->required();
  r->add_option("--tol-beta", raster.beta, "step control: largest deviation of the path from the CL surface, mm")
      ->check(CLI::PositiveNumber);
  r->add_option("--tol-alpha", raster.alpha, "the mesh's tolerance against the design surface, mm (reported)");
  r->add_option("--min-step", raster.min_step, "smallest step of the step control, mm")->check(CLI::PositiveNumber);
  r->add_flag("--compare-fixed", raster.compare_fixed, "also find the fixed step that is as accurate");
  r->add_option("--nurbs", raster.nurbs, "write each cut as G6.2 cubic NURBS fitted within this tolerance, mm")
      ->check(CLI::PositiveNumber);
  r->add_option("--origin", raster.origin, "corner: zero at the mesh's min x, min y, max z; mesh: as is");
  r->add_option("--feed", raster.feed, "cutting feed, mm/min")->check(CLI::PositiveNumber);
  r->add_option("--plunge", raster.plunge, "plunge feed, mm/min")->check(CLI::PositiveNumber);
  r->add_option("--spindle", raster.spindle, "spindle speed, rpm")->check(CLI::PositiveNumber);
  r->add_option("--safe-z", raster.safe_z, "retract height above the part's top, mm");
  r->add_option("--threads", raster.threads, "worker threads (default: all cores)")->check(CLI::Range(1, 256));
  RoughArgs rough;
  CLI::App* g = app.add_subcommand("rough", "z-level roughing with cusp-limited levels (seed 002), as G-code");
  g->add_option("--stl", rough.stl, "mesh, ASCII or binary STL")->required();
  g->add_option("--stock", rough.stock, "box (the mesh's bounds) or margin[:MM] (grown by MM in x, y and top; 2)");
  g->add_option("--tool", rough.tool, "ball:D, flat:D or bull:D:r (mm)")->required();
  g->add_option("--cusp", rough.cusp, "largest cusp height between levels, normal to the surface, mm")
      ->required()->check(CLI::PositiveNumber);
  g->add_option("--out", rough.out, "G-code file to write")->required();
  g->add_option("--png", rough.png, "picture of the levels to write (matplotlib)");
  g->add_option("--compare", rough.compare, "tools to compare, e.g. flat:10,bull:10:2,ball:10");
  g->add_option("--stepover", rough.stepover, "ring spacing as a fraction of the diameter (default 0.4)")
      ->check(CLI::Range(0.01, 0.9));
  g->add_option("--max-stepdown", rough.max_stepdown, "largest z-step, mm (default: the flute length)")
      ->check(CLI::PositiveNumber);
  g->add_option("--origin", rough.origin, "corner: zero at the stock's min x, min y and top; mesh: as is");
  g->add_option("--feed", rough.feed, "cutting feed, mm/min")->check(CLI::PositiveNumber);
  g->add_option("--plunge", rough.plunge, "plunge feed, mm/min")->check(CLI::PositiveNumber);
  g->add_option("--rapid", rough.rapid, "rapid speed of the time model, mm/min")->check(CLI::PositiveNumber);
  g->add_option("--spindle", rough.spindle, "spindle speed, rpm")->check(CLI::PositiveNumber);
  g->add_option("--safe-z", rough.safe_z, "clearance plane above the stock's top, mm")->check(CLI::NonNegativeNumber);
  g->add_option("--ramp", rough.ramp, "enter each chain down its first ring at this angle, degrees (0: plunge)")
      ->check(CLI::Range(0.0, 90.0));
  g->add_option("--threads", rough.threads, "levels planned side by side (default: all cores)")->check(CLI::Range(1, 256));
  PartArgs part;
  CLI::App* pa = app.add_subcommand("part", "write an analytic test part as binary STL");
  pa->add_option("--shape", part.shape, "table1-a, table1-b, hemisphere or frustum")->required();
  pa->add_option("--out", part.out, "STL file to write")->required();
  pa->add_option("--cells", part.cells, "grid cells per side")->check(CLI::Range(4, 4000));
  CLI11_PARSE(app, argc, argv);
  try {
    if (d->parsed()) return run_drop(drop);
    if (r->parsed()) return run_raster(raster);
    if (g->parsed()) return run_rough(rough);
    if (pa->parsed()) return run_part(part);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-cam: %s\n", e.what());
    return 2;
  }
  return 1;
}
