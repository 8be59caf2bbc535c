// cnc-cam-index-bench: the drop-cutter's spatial index measured against CGAL's AABB
// tree, the same exact contact queries behind both (vertices and facets first, then
// the edges with the best so far as their floor, shared edges solved once).
//
//   cnc-cam-index-bench [--stl FILE ...] [--step 0.2] [--repeats 3]
//
// Per mesh and cutter: build time and one-thread CPU µs per point of each, and the
// largest |dz| between them. The AABB tree is queried with the box of the cutter's
// disc, unbounded in z (all_intersected_primitives: exact box–triangle tests); the grid
// reads one cell sorted by the highest contact each triangle can give there.
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "common/cam/drop_cutter.h"
#include "common/cam/stl.h"
#include "common/cam/terrain.h"
#include "common/util/cli.h"

namespace {

using namespace cnc::cam;
using K = CGAL::Simple_cartesian<double>;
using Tri3 = K::Triangle_3;
using Iterator = std::vector<Tri3>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

double cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

class AabbDropCutter {
 public:
  AabbDropCutter(const Mesh& mesh, const Cutter& cutter) : contacts_(cutter), R_(cutter.radius()) {
    for (const Triangle& t : mesh.triangles) {
      tris_.push_back(prepare(t));
      cgal_.emplace_back(K::Point_3(t.v[0].x, t.v[0].y, t.v[0].z), K::Point_3(t.v[1].x, t.v[1].y, t.v[1].z),
                         K::Point_3(t.v[2].x, t.v[2].y, t.v[2].z));
    }
    share_edges(tris_);
    tree_.insert(cgal_.begin(), cgal_.end());
    tree_.build();
    const Bounds b = mesh_bounds(mesh);
    zlo_ = b.min.z - 1, zhi_ = b.max.z + 1;
  }

  ClPoint drop(double x, double y, std::vector<Iterator>& hits) const {
    hits.clear();
    tree_.all_intersected_primitives(CGAL::Bbox_3(x - R_, y - R_, zlo_, x + R_, y + R_, zhi_), std::back_inserter(hits));
    ClPoint best;
    for (const Iterator& it : hits) contacts_.vertices_and_facet(x, y, tris_[static_cast<std::size_t>(it - cgal_.begin())], best);
    for (const Iterator& it : hits) contacts_.edges(x, y, tris_[static_cast<std::size_t>(it - cgal_.begin())], best);
    return best;
  }

 private:
  CutterContacts contacts_;
  double R_, zlo_ = 0, zhi_ = 0;
  std::vector<PreparedTriangle> tris_;
  std::vector<Tri3> cgal_;
  Tree tree_;
};

void run(const std::string& name, const Mesh& mesh, double step, int repeats) {
  const Bounds b = mesh_bounds(mesh);
  std::vector<XY> pts;
  for (double y = b.min.y; y <= b.max.y; y += step)
    for (double x = b.min.x; x <= b.max.x; x += step) pts.push_back({x, y});
  std::printf("\nmesh %s: %zu triangles, %zu points\n", name.c_str(), mesh.triangles.size(), pts.size());
  for (const char* spec : {"ball:2", "flat:6", "bull:6:1"}) {
    const Cutter cutter = parse_cutter(spec);
    auto t0 = std::chrono::steady_clock::now();
    const DropCutter grid(mesh, cutter);
    const double grid_build = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    t0 = std::chrono::steady_clock::now();
    const AabbDropCutter aabb(mesh, cutter);
    const double aabb_build = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<ClPoint> g(pts.size()), a(pts.size());
    std::vector<Iterator> hits;
    double grid_us = 1e300, aabb_us = 1e300;
    for (int k = 0; k < repeats; ++k) {
      double c0 = cpu_s();
      for (std::size_t i = 0; i < pts.size(); ++i) g[i] = grid.drop(pts[i].x, pts[i].y);
      grid_us = std::min(grid_us, 1e6 * (cpu_s() - c0) / static_cast<double>(pts.size()));
      c0 = cpu_s();
      for (std::size_t i = 0; i < pts.size(); ++i) a[i] = aabb.drop(pts[i].x, pts[i].y, hits);
      aabb_us = std::min(aabb_us, 1e6 * (cpu_s() - c0) / static_cast<double>(pts.size()));
    }
    double max_dz = 0;
    std::size_t mismatch = 0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (g[i].touched() != a[i].touched()) ++mismatch;
      else if (g[i].touched()) max_dz = std::max(max_dz, std::abs(g[i].z - a[i].z));
    }
    std::printf("  %-9s grid: build %.3f s, %.2f us/pt | CGAL AABB: build %.3f s, %.2f us/pt | grid %.1fx faster;"
                " max |dz| %.3g, touch mismatches %zu\n",
                spec, grid_build, grid_us, aabb_build, aabb_us, aabb_us / grid_us, max_dz, mismatch);
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"the drop-cutter's grid index against CGAL's AABB tree", "cnc-cam-index-bench"};
  cnc::util::cli::setup(app);
  std::vector<std::string> stls;
  double step = 0.2;
  int repeats = 3;
  app.add_option("--stl", stls, "more meshes");
  app.add_option("--step", step, "grid step, mm");
  app.add_option("--repeats", repeats, "runs; the best counts")->check(CLI::Range(1, 100));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  TerrainSpec spec;
  spec.cols = 272;
  spec.rows = 269;
  spec.step_mm = 0.25;
  spec.bumps = 60;
  run("terrain146k (doubles, not rounded to float)", make_terrain(spec), step, repeats);
  for (const std::string& p : stls) run(p, read_stl(p), step, repeats);
  return 0;
}
