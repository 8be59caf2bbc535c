// cnc-cam: offline CAM on triangle meshes (seeds 002, 003).
//
//   cnc-cam drop --stl MESH --tool ball:D|flat:D|bull:D:r --points XY.csv --out XYZ.csv [--threads N]
//
// drop: the drop-cutter's CL height for each point of XY.csv, in order, into XYZ.csv
// (x and y echoed as written, z empty where nothing is touched); prints
// "points=N seconds=S pts_per_s=R" on stdout (S: the queries only), and on stderr
// the mesh's load and the index's build, and progress for runs over a second.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <exception>
#include <string>
#include <thread>

#include "common/cam/cutter.h"
#include "common/cam/drop_cutter.h"
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
  std::thread worker([&] { dc.drop_batch(pts.points, out, threads, &done); });
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
  const double s = seconds_since(t0);
  write_xyz_csv(a.out, pts, out);
  std::printf("points=%zu seconds=%.6f pts_per_s=%.0f\n", pts.points.size(), s,
              s > 0 ? static_cast<double>(pts.points.size()) / s : 0.0);
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
  CLI11_PARSE(app, argc, argv);
  try {
    if (d->parsed()) return run_drop(drop);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-cam: %s\n", e.what());
    return 2;
  }
  return 1;
}
