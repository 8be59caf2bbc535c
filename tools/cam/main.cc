// cnc-cam: offline CAM on triangle meshes (Shin et al. and Hwang).
//
//   cnc-cam drop --stl MESH --tool ball:D|flat:D|bull:D:r --points XY.csv --out XYZ.csv [--threads N]
//                [--png FILE]
//   cnc-cam rough --stl MESH --stock box|margin[:MM] --tool SPEC --cusp H --out rough.ngc
//                 [--png FILE] [--compare SPEC,SPEC,...] [--stepover F] [--max-stepdown MM]
//                 [--origin corner|mesh] [--feed F] [--plunge F] [--rapid F] [--spindle S] [--safe-z Z]
//                 [--ramp DEG] [--threads N]
//   cnc-cam part --shape table1-a|table1-b|hemisphere|frustum --out MESH.stl [--cells N]
//   cnc-cam raster --stl MESH --tool SPEC --pick P --step S [--angle A] --out part.ngc
//                  [--tol-beta B [--tol-alpha A] [--min-step M] [--compare-fixed] [--no-corner-search]]
//                  [--origin corner|mesh] [--feed F] [--plunge F] [--spindle S] [--safe-z Z] [--threads N]
//                  [--nurbs TOL] [--png FILE [--png-cells N]]
//
// Every command reports progress on stderr when it runs over a second (what is done,
// the rate, the time left; every half second), never on stdout, whose figures lines
// stay parseable. --png runs a matplotlib script of tools/cam with Debian's
// /usr/bin/python3 (run_plot; its own output goes to stderr too).
//
// drop: the drop-cutter's CL height for each point of XY.csv, in order, into XYZ.csv
// (x and y echoed as written, z empty where nothing is touched); prints
// "points=N seconds=S pts_per_s=R" on stdout (S: the queries only), and on stderr
// the mesh's load and the index's build. --png: the CL surface (tools/cam/plot_cam.py;
// a shaded height map when the points form a grid, coloured dots otherwise).
//
// rough: Shin et al.'s z-level roughing (common/cam/rough.h): levels bottom-up from the
// smallest slope on each contour and the cusp limit, plus flat areas; per level the
// tool-offset contour (Clipper) and rings stepping in from the stock by --stepover
// (a fraction of D, default 0.4), linked at the level or via the clearance plane;
// G-code through the common writer. Prints one line per level and the totals; with
// --compare, the same plan for each listed tool: levels, path length and the time of
// a constant-speed model (feed, plunge, rapid; no acceleration). --png draws the levels
// (tools/cam/plot_rough.py).
//
// part: writes an analytic test part as binary STL (common/cam/shapes.h).
//
// raster: parallel passes written as G-code (common/cam/gcode_writer.h), with a fixed
// step, or with --tol-beta Hwang's step control up to --step (common/cam/raster.h),
// concave corners found by its bisection unless --no-corner-search;
// then the path's measured deviation from the exact CL surface (32 CL points inside
// every segment) is printed, and with --compare-fixed the point count of the largest
// fixed step (--step halved until it holds) that is as accurate. --tol-alpha is the
// mesh's own tolerance against the design surface, which the mesh does not tell: it is
// only reported with the budget α + β. --origin corner (default) puts the program's zero at
// the mesh's lowest x and y and its highest z (the part's top), so cuts are at Z <= 0;
// --origin mesh keeps the mesh's coordinates. --nurbs TOL writes each cut as G6.2 cubic
// NURBS fitted to its CL points within TOL (GcodeWriter::cut_nurbs), not as G1 lines.
// --png: the CL surface on a grid of --png-cells (200) over the mesh's bounds as a
// shaded height map with the cuts and their CL points, in the mesh's coordinates.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/cam/cutter.h"
#include "common/cam/drop_cutter.h"
#include "common/cam/gcode_writer.h"
#include "common/cam/raster.h"
#include "common/cam/rough.h"
#include "common/cam/shapes.h"
#include "common/cam/points_csv.h"
#include "common/cam/stl.h"
#include "common/util/cli.h"
#include "common/util/install.h"

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Progress on stderr for runs over a second: a thread of its own reads the counters
// the work updates (`poll`) one second after the start and every half second after,
// and prints what is done, the rate and the time left; stdout is left alone. Stops and
// joins when destroyed.
struct ProgressCounts {
  std::size_t done = 0, total = 0;  // in `unit`s; total 0: not known yet
  std::size_t points = 0;           // CL points computed, if the unit is not points
};
class Progress {
 public:
  Progress(std::string label, std::string unit, std::function<ProgressCounts()> poll)
      : label_(std::move(label)), unit_(std::move(unit)), poll_(std::move(poll)), t0_(Clock::now()),
        thread_([this] { loop(); }) {}
  ~Progress() {
    {
      std::lock_guard<std::mutex> lk(m_);
      stop_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  bool reported() const { return reported_.load(); }

 private:
  void loop() {
    std::unique_lock<std::mutex> lk(m_);
    auto next = t0_ + std::chrono::seconds(1);
    while (!cv_.wait_until(lk, next, [this] { return stop_; })) {
      const ProgressCounts c = poll_();
      const double t = seconds_since(t0_);
      const double rate = static_cast<double>(c.done) / t;
      char left[48] = "";
      if (c.total > 0 && c.done > 0 && c.done <= c.total)
        std::snprintf(left, sizeof left, ", %.1f s left", static_cast<double>(c.total - c.done) / rate);
      if (c.points > 0) {
        std::fprintf(stderr, "%s: %zu / %zu %s, %zu CL points, %.0f pts/s%s\n", label_.c_str(), c.done, c.total,
                     unit_.c_str(), c.points, static_cast<double>(c.points) / t, left);
      } else {
        std::fprintf(stderr, "%s: %zu / %zu %s, %.*f %s/s%s\n", label_.c_str(), c.done, c.total, unit_.c_str(),
                     rate < 10 ? 2 : 0, rate, unit_.c_str(), left);
      }
      reported_ = true;
      next += std::chrono::milliseconds(500);
    }
  }
  std::string label_, unit_;
  std::function<ProgressCounts()> poll_;
  Clock::time_point t0_;
  std::mutex m_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::atomic<bool> reported_{false};
  std::thread thread_;  // last: starts once the members above exist
};

std::string fmt_g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// One of tools/cam's matplotlib scripts on Debian's python3 (which has matplotlib),
// with its arguments passed as they are (no shell); an error if it fails.
void run_plot(const std::string& script, const std::vector<std::string>& args) {
  const std::string path = cnc::util::resource_path("tools/cam/" + script);  // installed: /usr/share/cnc/tools/cam
  std::vector<std::string> all{"/usr/bin/python3", path};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : all) argv.push_back(s.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error(script + ": cannot start /usr/bin/python3");
  if (pid == 0) {
    dup2(STDERR_FILENO, STDOUT_FILENO);  // the script's words on stderr: stdout stays the tool's figures
    execv(argv[0], argv.data());
    std::fprintf(stderr, "cnc-cam: cannot run /usr/bin/python3 %s\n", path.c_str());
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw std::runtime_error(path + " failed (Debian's python3-matplotlib is needed for --png)");
}

struct DropArgs {
  std::string stl, tool, points, out, png;
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
  double s = 0;
  {
    const Progress progress("cnc-cam drop", "points", [&] { return ProgressCounts{done.load(), pts.points.size(), 0}; });
    t0 = Clock::now();
    dc.drop_batch(pts.points, out, threads, &done);
    s = seconds_since(t0);
  }
  write_xyz_csv(a.out, pts, out);
  std::printf("points=%zu seconds=%.6f pts_per_s=%.0f\n", pts.points.size(), s,
              s > 0 ? static_cast<double>(pts.points.size()) / s : 0.0);
  if (!a.png.empty())
    run_plot("plot_cam.py", {"--xyz", a.out, "--out", a.png, "--title", a.stl + ", " + a.tool + ": CL surface (drop)"});
  return 0;
}

struct RasterArgs {
  std::string stl, tool, out, origin = "corner", png;
  double pick = 1, step = 0.1, angle = 0, feed = 1000, plunge = 300, spindle = 10000, safe_z = 2;
  double beta = 0, alpha = 0, min_step = 1e-3, nurbs = 0;
  bool compare_fixed = false, no_corner_search = false;
  int threads = 0, png_cells = 200;
};

std::size_t cl_point_count(const cnc::cam::RasterPath& p) {
  std::size_t n = 0;
  for (const auto& c : p.cuts) n += c.size();
  return n;
}

// raster --png: the CL surface on a grid of --png-cells over the mesh's bounds (drop-
// cutter, the same tool) as a shaded height map, with the cuts drawn over it, in the
// mesh's coordinates (tools/cam/plot_cam.py).
void write_raster_png(const RasterArgs& a, const cnc::cam::DropCutter& dc, const cnc::cam::Bounds& b,
                      const cnc::cam::RasterPath& path, int threads) {
  using namespace cnc::cam;
  const double w = b.max.x - b.min.x, h = b.max.y - b.min.y;
  const double cell = std::max(w, h) / a.png_cells;
  const auto nx = static_cast<std::size_t>(std::ceil(w / cell)) + 1, ny = static_cast<std::size_t>(std::ceil(h / cell)) + 1;
  PointsCsv grid;
  for (std::size_t j = 0; j < ny; ++j)
    for (std::size_t i = 0; i < nx; ++i) {
      const double x = std::min(b.max.x, b.min.x + static_cast<double>(i) * cell);
      const double y = std::min(b.max.y, b.min.y + static_cast<double>(j) * cell);
      char bx[32], by[32];
      std::snprintf(bx, sizeof bx, "%.6f", x);
      std::snprintf(by, sizeof by, "%.6f", y);
      grid.points.push_back({x, y});
      grid.x_text.emplace_back(bx);
      grid.y_text.emplace_back(by);
    }
  std::vector<ClPoint> z(grid.points.size());
  {
    std::atomic<std::size_t> done{0};
    const Progress progress("cnc-cam raster: picture's CL surface", "points",
                            [&] { return ProgressCounts{done.load(), grid.points.size(), 0}; });
    dc.drop_batch(grid.points, z, threads, &done);
  }
  const std::string xyz = a.png + ".cl.csv", cuts = a.png + ".cuts.csv";
  write_xyz_csv(xyz, grid, z);
  std::FILE* f = std::fopen(cuts.c_str(), "w");
  if (!f) throw std::runtime_error(cuts + ": cannot write");
  std::fprintf(f, "cut,x,y,z\n");
  for (std::size_t k = 0; k < path.cuts.size(); ++k)
    for (const Vec3& p : path.cuts[k]) std::fprintf(f, "%zu,%.6f,%.6f,%.6f\n", k, p.x, p.y, p.z);
  if (std::fclose(f) != 0) throw std::runtime_error(cuts + ": cannot write");
  std::size_t n = 0;
  for (const auto& c : path.cuts) n += c.size();
  char title[256];
  std::snprintf(title, sizeof title, "%s, %s, pick %g, %s: %zu CL points in %zu cuts", a.stl.c_str(), a.tool.c_str(),
                a.pick, a.beta > 0 ? ("beta " + fmt_g(a.beta) + " mm").c_str() : ("step " + fmt_g(a.step) + " mm").c_str(),
                n, path.cuts.size());
  run_plot("plot_cam.py", {"--xyz", xyz, "--paths", cuts, "--out", a.png, "--title", title});
  std::remove(xyz.c_str());
  std::remove(cuts.c_str());
}

int run_raster(const RasterArgs& a) {
  using namespace cnc::cam;
  const Cutter cutter = parse_cutter(a.tool);
  if (a.origin != "corner" && a.origin != "mesh") throw std::invalid_argument("--origin must be corner or mesh");
  const Mesh mesh = read_stl(a.stl);
  const Bounds b = mesh_bounds(mesh);
  const DropCutter dc(mesh, cutter);
  const int threads = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const RasterSpec spec{a.pick, a.step, a.angle};
  const std::size_t n_passes = raster_passes(b, spec).size();
  AdaptiveSpec ad{a.beta, a.min_step};
  ad.corner_search = !a.no_corner_search;
  RasterProgress rp;
  double s = 0;
  RasterPath path;
  {
    const Progress progress(a.beta > 0 ? "cnc-cam raster: step control" : "cnc-cam raster: fixed step", "passes",
                            [&] { return ProgressCounts{rp.passes.load(), n_passes, rp.points.load()}; });
    const auto t0 = Clock::now();
    path = a.beta > 0 ? raster_adaptive(dc, b, spec, ad, threads, &rp) : raster_fixed_step(dc, b, spec, threads, &rp);
    s = seconds_since(t0);
  }
  // The deviation, measured at 32 CL points inside every segment (`n` segments).
  auto deviation_of = [&](const RasterPath& p, const char* what) {
    std::size_t segments = 0;
    for (const auto& c : p.cuts) segments += c.empty() ? 0 : c.size() - 1;
    RasterProgress dp;
    const Progress progress(std::string("cnc-cam raster: deviation of the ") + what, "CL points",
                            [&] { return ProgressCounts{dp.points.load(), 32 * segments, 0}; });
    return path_deviation(dc, p, 32, threads, &dp);
  };
  const double deviation = deviation_of(path, a.beta > 0 ? "step control" : "fixed step");
  std::fprintf(stderr, "cnc-cam raster: %s: %zu CL points, largest deviation from the CL surface %.3g mm%s\n",
               a.beta > 0 ? "step control" : "fixed step", cl_point_count(path), deviation,
               a.beta > 0 ? (" (beta " + std::to_string(a.beta) + ", alpha + beta " + std::to_string(a.alpha + a.beta) +
                             ", " + std::to_string(path.corners) + " concave corners found" +
                             (ad.corner_search ? "" : ": search off") + ")")
                                .c_str()
                          : "");
  if (a.compare_fixed && a.beta > 0) {
    for (double st = a.step; st >= a.min_step; st *= 0.5) {
      RasterPath fixed;
      {
        RasterProgress fp;
        const std::size_t total = [&] {
          std::size_t n = 0;
          for (const auto& p : raster_passes(b, RasterSpec{a.pick, st, a.angle})) n += p.size();
          return n;
        }();
        const Progress progress("cnc-cam raster: fixed step " + fmt_g(st) + " mm", "CL points",
                                [&] { return ProgressCounts{fp.points.load(), total, 0}; });
        fixed = raster_fixed_step(dc, b, RasterSpec{a.pick, st, a.angle}, threads, &fp);
      }
      const double dev = deviation_of(fixed, "fixed step");
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
  if (!a.png.empty()) write_raster_png(a, dc, b, path, threads);
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
    std::atomic<std::size_t> done{0}, total{0};
    const auto t0 = Clock::now();
    bool reported = false;
    RoughPlan plan;
    {
      const Progress progress("cnc-cam rough: " + tool, "levels", [&] { return ProgressCounts{done.load(), total.load(), 0}; });
      plan = plan_roughing(mesh, stock, spec, [&](std::size_t d, std::size_t n) {
        total = n;
        done = d;
      });
      reported = progress.reported();
    }
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
    run_plot("plot_rough.py", {csv, a.png, a.tool + " cusp " + fmt_g(a.cusp)});
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
  CLI::App app{"offline CAM on triangle meshes (drop-cutter by inverse offset)", "cnc-cam"};
  cnc::util::cli::setup(app);
  app.require_subcommand(1);
  DropArgs drop;
  CLI::App* d = app.add_subcommand("drop", "CL heights of a cutter dropped onto a mesh at given points");
  d->add_option("--stl", drop.stl, "mesh, ASCII or binary STL")->required();
  d->add_option("--tool", drop.tool, "ball:D, flat:D or bull:D:r (mm; optional :L=flute length)")->required();
  d->add_option("--points", drop.points, "CSV with header x,y")->required();
  d->add_option("--out", drop.out, "CSV x,y,z to write")->required();
  d->add_option("--threads", drop.threads, "worker threads (default: all cores)")->check(CLI::Range(1, 256));
  d->add_option("--png", drop.png, "picture of the CL surface to write (matplotlib; a grid of points: shaded height map)");
  RasterArgs raster;
  CLI::App* r = app.add_subcommand("raster", "parallel finishing passes with a fixed step, as G-code");
  r->add_option("--stl", raster.stl, "mesh, ASCII or binary STL")->required();
  r->add_option("--tool", raster.tool, "ball:D, flat:D or bull:D:r (mm)")->required();
  r->add_option("--pick", raster.pick, "distance between passes, mm")->required()->check(cnc::util::cli::positive());
  r->add_option("--step", raster.step, "largest distance between CL points along a pass, mm")->required()->check(cnc::util::cli::positive());
  r->add_option("--angle", raster.angle, "direction of the passes, degrees from +X");
  r->add_option("--out", raster.out, "G-code file to write")->required();
  r->add_option("--tol-beta", raster.beta, "step control: largest deviation of the path from the CL surface, mm")
      ->check(cnc::util::cli::positive());
  r->add_option("--tol-alpha", raster.alpha, "the mesh's tolerance against the design surface, mm (reported)");
  r->add_option("--min-step", raster.min_step, "smallest step of the step control, mm")->check(cnc::util::cli::positive());
  r->add_flag("--compare-fixed", raster.compare_fixed, "also find the fixed step that is as accurate");
  r->add_flag("--no-corner-search", raster.no_corner_search,
              "step control without Hwang's concave corner search (the halving alone closes in on corners)");
  r->add_option("--png", raster.png, "picture of the CL surface and the cuts to write (matplotlib)");
  r->add_option("--png-cells", raster.png_cells, "the picture's CL grid: cells along the longer side")
      ->check(CLI::Range(10, 2000));
  r->add_option("--nurbs", raster.nurbs, "write each cut as G6.2 cubic NURBS fitted within this tolerance, mm")
      ->check(cnc::util::cli::positive());
  r->add_option("--origin", raster.origin, "corner: zero at the mesh's min x, min y, max z; mesh: as is");
  r->add_option("--feed", raster.feed, "cutting feed, mm/min")->check(cnc::util::cli::positive());
  r->add_option("--plunge", raster.plunge, "plunge feed, mm/min")->check(cnc::util::cli::positive());
  r->add_option("--spindle", raster.spindle, "spindle speed, rpm")->check(cnc::util::cli::positive());
  r->add_option("--safe-z", raster.safe_z, "retract height above the part's top, mm");
  r->add_option("--threads", raster.threads, "worker threads (default: all cores)")->check(CLI::Range(1, 256));
  RoughArgs rough;
  CLI::App* g = app.add_subcommand("rough", "z-level roughing with cusp-limited levels (Shin et al.), as G-code");
  g->add_option("--stl", rough.stl, "mesh, ASCII or binary STL")->required();
  g->add_option("--stock", rough.stock, "box (the mesh's bounds) or margin[:MM] (grown by MM in x, y and top; 2)");
  g->add_option("--tool", rough.tool, "ball:D, flat:D or bull:D:r (mm)")->required();
  g->add_option("--cusp", rough.cusp, "largest cusp height between levels, normal to the surface, mm")
      ->required()->check(cnc::util::cli::positive());
  g->add_option("--out", rough.out, "G-code file to write")->required();
  g->add_option("--png", rough.png, "picture of the levels to write (matplotlib)");
  g->add_option("--compare", rough.compare, "tools to compare, e.g. flat:10,bull:10:2,ball:10");
  g->add_option("--stepover", rough.stepover, "ring spacing as a fraction of the diameter (default 0.4)")
      ->check(CLI::Range(0.01, 0.9));
  g->add_option("--max-stepdown", rough.max_stepdown, "largest z-step, mm (default: the flute length)")
      ->check(cnc::util::cli::positive());
  g->add_option("--origin", rough.origin, "corner: zero at the stock's min x, min y and top; mesh: as is");
  g->add_option("--feed", rough.feed, "cutting feed, mm/min")->check(cnc::util::cli::positive());
  g->add_option("--plunge", rough.plunge, "plunge feed, mm/min")->check(cnc::util::cli::positive());
  g->add_option("--rapid", rough.rapid, "rapid speed of the time model, mm/min")->check(cnc::util::cli::positive());
  g->add_option("--spindle", rough.spindle, "spindle speed, rpm")->check(cnc::util::cli::positive());
  g->add_option("--safe-z", rough.safe_z, "clearance plane above the stock's top, mm")->check(cnc::util::cli::non_negative());
  g->add_option("--ramp", rough.ramp, "enter each chain down its first ring at this angle, degrees (0: plunge)")
      ->check(CLI::Range(0.0, 90.0));
  g->add_option("--threads", rough.threads, "levels planned side by side (default: all cores)")->check(CLI::Range(1, 256));
  PartArgs part;
  CLI::App* pa = app.add_subcommand("part", "write an analytic test part as binary STL");
  pa->add_option("--shape", part.shape, "table1-a, table1-b, hemisphere or frustum")->required();
  pa->add_option("--out", part.out, "STL file to write")->required();
  pa->add_option("--cells", part.cells, "grid cells per side")->check(CLI::Range(4, 4000));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
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
