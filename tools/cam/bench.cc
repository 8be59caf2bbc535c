// cnc-cam-bench: CL points per second of the drop-cutter (grid index, 1..N threads)
// against brute force over all triangles, measured in the same run, and STL load
// speed. Not a test: it prints figures and ratios.
//
//   cnc-cam-bench [--stl FILE ...] [--step 0.2] [--repeats 5] [--threads 2]
//                 [--brute-points 3000] [--load-triangles 1000000] [--out-dir DIR]
//
// Meshes: a generated smooth terrain of 146,336 triangles (272 × 269 cells at
// 0.25 mm, written as binary STL and read back, so it holds what an STL holds) and
// every --stl given. Points: the grid at --step over the mesh's xy bounds. Cutters:
// ball D2, flat D6, bull D6 r1. Rates are best of --repeats; the index build is
// timed apart. Brute force runs on one thread over --brute-points points spread
// evenly over the grid; its z is compared with the index's on those points. One-thread
// figures are also given as CPU µs per point (the thread's CPU clock), which a loaded
// machine does not inflate; the index/brute ratio is given on both clocks.
// --out-dir keeps each mesh's STL and points CSV (for OpenCAMLib side by side).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <string>
#include <vector>

#include "common/cam/cutter.h"
#include "common/cam/drop_cutter.h"
#include "common/cam/points_csv.h"
#include "common/cam/stl.h"
#include "common/cam/terrain.h"
#include "common/util/cli.h"

namespace {

using namespace cnc::cam;
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
// CPU time of the calling thread: on a shared machine the one-thread figures are
// compared by it, as the wall clock also counts the time other processes held the core.
double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

std::vector<XY> grid_points(const Mesh& mesh, double step) {
  const Bounds b = mesh_bounds(mesh);
  const auto nx = static_cast<std::size_t>(std::floor((b.max.x - b.min.x) / step)) + 1;
  const auto ny = static_cast<std::size_t>(std::floor((b.max.y - b.min.y) / step)) + 1;
  std::vector<XY> pts;
  pts.reserve(nx * ny);
  for (std::size_t j = 0; j < ny; ++j)
    for (std::size_t i = 0; i < nx; ++i)
      pts.push_back({b.min.x + static_cast<double>(i) * step, b.min.y + static_cast<double>(j) * step});
  return pts;
}

void write_points(const std::string& path, const std::vector<XY>& pts) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw std::runtime_error(path + ": cannot create");
  std::fprintf(f, "x,y\n");
  for (const XY& p : pts) std::fprintf(f, "%.17g,%.17g\n", p.x, p.y);
  std::fclose(f);
}

void bench_mesh(const std::string& name, const Mesh& mesh, double step, int repeats, int max_threads,
                std::size_t brute_points) {
  const std::vector<XY> pts = grid_points(mesh, step);
  std::printf("\nmesh %s: %zu triangles, %zu points (step %.3g mm)\n", name.c_str(), mesh.triangles.size(), pts.size(),
              step);
  const char* tools[] = {"ball:2", "flat:6", "bull:6:1"};
  for (const char* spec : tools) {
    const Cutter cutter = parse_cutter(spec);
    auto t0 = Clock::now();
    const DropCutter dc(mesh, cutter);
    const double build_s = seconds_since(t0);
    std::vector<ClPoint> out(pts.size());
    std::vector<double> rate(static_cast<std::size_t>(max_threads) + 1, 0);
    double cpu_us = 1e300;  // one thread: CPU µs per point
    for (int th = 1; th <= max_threads; ++th) {
      double best = 1e300;
      for (int k = 0; k < repeats; ++k) {
        const double c0 = thread_cpu_s();
        t0 = Clock::now();
        dc.drop_batch(pts, out, th);
        best = std::min(best, seconds_since(t0));
        if (th == 1) cpu_us = std::min(cpu_us, 1e6 * (thread_cpu_s() - c0) / static_cast<double>(pts.size()));
      }
      rate[static_cast<std::size_t>(th)] = static_cast<double>(pts.size()) / best;
    }
    // Brute force on an even subsample, one thread, best of the same repeats.
    const BruteForceDropCutter bf(mesh, cutter);
    const std::size_t n = std::min(brute_points, pts.size());
    const std::size_t stride = std::max<std::size_t>(1, pts.size() / std::max<std::size_t>(n, 1));
    double bf_best = 1e300, bf_cpu_us = 1e300, max_dz = 0;
    std::size_t bf_count = 0, mismatched_touch = 0;
    for (int k = 0; k < repeats; ++k) {
      bf_count = 0;
      double sink = 0;
      const double c0 = thread_cpu_s();
      t0 = Clock::now();
      for (std::size_t i = 0; i < pts.size() && bf_count < n; i += stride, ++bf_count) {
        const ClPoint c = bf.drop(pts[i].x, pts[i].y);
        sink += c.touched() ? c.z : 0;
        if (k == 0) {
          if (c.touched() != out[i].touched()) ++mismatched_touch;
          else if (c.touched()) max_dz = std::max(max_dz, std::abs(c.z - out[i].z));
        }
      }
      bf_best = std::min(bf_best, seconds_since(t0));
      bf_cpu_us = std::min(bf_cpu_us, 1e6 * (thread_cpu_s() - c0) / static_cast<double>(bf_count));
      if (sink == 12345.678) std::printf(" ");  // keeps the loop from being optimised away
    }
    const double bf_rate = static_cast<double>(bf_count) / bf_best;
    std::printf("  %-9s index %.3f s (cell %.3g mm, %zu entries)\n", spec, build_s, dc.cell_mm(), dc.index_entries());
    std::printf("    index:");
    for (int th = 1; th <= max_threads; ++th)
      std::printf("  %dT %8.0f pts/s", th, rate[static_cast<std::size_t>(th)]);
    std::printf("  (1T CPU %.2f us/pt)\n", cpu_us);
    std::printf("    brute:  1T %8.0f pts/s  (1T CPU %.1f us/pt, %zu pts)  index/brute: %.0fx wall, %.0fx CPU;"
                " max |dz| %.3g mm%s\n",
                bf_rate, bf_cpu_us, bf_count, rate[1] / bf_rate, bf_cpu_us / cpu_us, max_dz,
                mismatched_touch ? (" TOUCH MISMATCH " + std::to_string(mismatched_touch)).c_str() : "");
    std::fflush(stdout);
  }
}

void bench_load(std::size_t triangles, const std::string& dir) {
  // A terrain of at least `triangles` triangles, binary and ASCII.
  const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(triangles) / 2)));
  TerrainSpec spec;
  spec.cols = spec.rows = side;
  spec.step_mm = 0.1;
  const Mesh mesh = make_terrain(spec);
  const std::string bin = dir + "/load_binary.stl", asc = dir + "/load_ascii.stl";
  write_stl_binary(bin, mesh);
  write_stl_ascii(asc, mesh);
  std::printf("\nSTL load (page cache warm, best of 3), %zu triangles:\n", mesh.triangles.size());
  for (const std::string& path : {bin, asc}) {
    double best = 1e300, raw = 1e300;
    StlInfo info;
    std::size_t got = 0;
    for (int k = 0; k < 3; ++k) {
      // Baseline: the file's bytes alone, in one block, as read_stl reads them.
      auto t0 = Clock::now();
      std::FILE* f = std::fopen(path.c_str(), "rb");
      std::string bytes(std::filesystem::file_size(path), '\0');
      const std::size_t n = std::fread(bytes.data(), 1, bytes.size(), f);
      std::fclose(f);
      raw = std::min(raw, seconds_since(t0));
      if (n != bytes.size()) throw std::runtime_error(path + ": short read");
      t0 = Clock::now();
      got = read_stl(path, &info).triangles.size();
      best = std::min(best, seconds_since(t0));
    }
    const double mb = static_cast<double>(info.bytes) / 1e6;
    std::printf("  %-6s %7.1f MB  %.3f s  %6.0f MB/s  %5.2f M triangles/s (%zu read); bytes alone %.3f s, %6.0f MB/s\n",
                info.binary ? "binary" : "ASCII", mb, best, mb / best, static_cast<double>(got) / 1e6 / best, got, raw,
                mb / raw);
  }
  std::filesystem::remove(bin);
  std::filesystem::remove(asc);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"drop-cutter CL points/s against brute force, and STL load speed", "cnc-cam-bench"};
  cnc::util::cli::setup(app);
  std::vector<std::string> stls;
  double step = 0.2;
  int repeats = 5, threads = 2;
  std::size_t brute_points = 3000, load_triangles = 1000000;
  std::string out_dir;
  bool no_terrain = false;
  app.add_option("--stl", stls, "more meshes to bench (e.g. OpenCAMLib's stl/mount_rush.stl)");
  app.add_option("--step", step, "grid step, mm");
  app.add_option("--repeats", repeats, "runs per figure; the best counts")->check(CLI::Range(1, 100));
  app.add_option("--threads", threads, "largest thread count")->check(CLI::Range(1, 64));
  app.add_option("--brute-points", brute_points, "points for brute force");
  app.add_option("--load-triangles", load_triangles, "STL load test size (0: skip)");
  app.add_option("--out-dir", out_dir, "keep each mesh as STL and its points as CSV here");
  app.add_flag("--no-terrain", no_terrain, "skip the generated terrain");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  try {
    const std::string dir = out_dir.empty() ? std::filesystem::temp_directory_path().string() : out_dir;
    if (!out_dir.empty()) std::filesystem::create_directories(out_dir);
    if (!no_terrain) {
      TerrainSpec spec;
      spec.cols = 272;
      spec.rows = 269;
      spec.step_mm = 0.25;
      spec.bumps = 60;
      const std::string path = dir + "/terrain146k.stl";
      write_stl_binary(path, make_terrain(spec));
      const Mesh mesh = read_stl(path);
      if (!out_dir.empty()) write_points(dir + "/terrain146k_xy.csv", grid_points(mesh, step));
      else std::filesystem::remove(path);
      bench_mesh("terrain146k", mesh, step, repeats, threads, brute_points);
    }
    for (const std::string& path : stls) {
      const Mesh mesh = read_stl(path);
      const std::string stem = std::filesystem::path(path).stem().string();
      if (!out_dir.empty()) write_points(dir + "/" + stem + "_xy.csv", grid_points(mesh, step));
      bench_mesh(stem, mesh, step, repeats, threads, brute_points);
    }
    if (load_triangles > 0) bench_load(load_triangles, dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-cam-bench: %s\n", e.what());
    return 2;
  }
  return 0;
}
