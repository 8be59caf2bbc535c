// ocl_drop: OpenCAMLib's BatchDropCutter on an STL and an XY.csv, for side-by-side
// figures with `cnc-cam drop`. Built by compare_ocl.sh against a separate OpenCAMLib
// build (OpenCAMLib is LGPL and is not part of this project; this file only calls it).
//
//   ocl_drop MESH.stl XY.csv ball:D|flat:D|bull:D:r THREADS REPEATS OUT.csv
//
// Prints "points=N seconds=S pts_per_s=R" for the best of REPEATS runs of run()
// (the kd-tree build in setSTL is excluded, as cnc-cam-bench excludes its index).
// OUT.csv: x,y,z with z empty where OpenCAMLib found no contact.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "ballcutter.hpp"
#include "batchdropcutter.hpp"
#include "bullcutter.hpp"
#include "cylcutter.hpp"
#include "stlreader.hpp"
#include "stlsurf.hpp"

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: ocl_drop MESH.stl XY.csv TOOL THREADS REPEATS OUT.csv\n");
    return 2;
  }
  const std::string stl = argv[1], csv = argv[2], tool = argv[3], out_path = argv[6];
  const int threads = std::atoi(argv[4]), repeats = std::atoi(argv[5]);
  ocl::STLSurf surf;
  ocl::STLReader reader(std::wstring(stl.begin(), stl.end()), surf);
  double zmin = std::numeric_limits<double>::infinity();
  for (const ocl::Triangle& t : surf.tris)
    for (const ocl::Point& p : t.p) zmin = std::min(zmin, p.z);
  const double start_z = zmin - 100;  // every CL point starts far below the mesh

  std::vector<std::pair<std::string, std::string>> text;
  std::vector<std::pair<double, double>> xy;
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);  // header x,y
  while (std::getline(in, line)) {
    const auto comma = line.find(',');
    if (comma == std::string::npos) continue;
    text.emplace_back(line.substr(0, comma), line.substr(comma + 1));
    xy.emplace_back(std::strtod(text.back().first.c_str(), nullptr), std::strtod(text.back().second.c_str(), nullptr));
  }

  const auto c1 = tool.find(':'), c2 = tool.find(':', c1 + 1);
  const std::string kind = tool.substr(0, c1);
  const double d = std::strtod(tool.substr(c1 + 1, c2 - c1 - 1).c_str(), nullptr);
  ocl::MillingCutter* cutter = nullptr;
  if (kind == "ball") cutter = new ocl::BallCutter(d, 4 * d);
  else if (kind == "flat") cutter = new ocl::CylCutter(d, 4 * d);
  else if (kind == "bull") cutter = new ocl::BullCutter(d, std::strtod(tool.substr(c2 + 1).c_str(), nullptr), 4 * d);
  else {
    std::fprintf(stderr, "ocl_drop: unknown tool %s\n", tool.c_str());
    return 2;
  }

  ocl::BatchDropCutter bdc;
  bdc.setThreads(static_cast<unsigned>(threads));
  bdc.setCutter(cutter);
  bdc.setSTL(surf);
  double best = 1e300;
  std::vector<ocl::CLPoint> result;
  for (int k = 0; k < repeats; ++k) {
    bdc.clearCLPoints();
    for (const auto& p : xy) {
      ocl::CLPoint cl(p.first, p.second, start_z);
      bdc.appendPoint(cl);
    }
    const auto t0 = std::chrono::steady_clock::now();
    bdc.run();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (k == 0) result = bdc.getCLPoints();
  }
  std::ofstream out(out_path);
  out << "x,y,z\n";
  char buf[64];
  for (std::size_t i = 0; i < result.size(); ++i) {
    out << text[i].first << ',' << text[i].second << ',';
    if (result[i].z > start_z) {
      std::snprintf(buf, sizeof buf, "%.17g", result[i].z);
      out << buf;
    }
    out << '\n';
  }
  std::printf("points=%zu seconds=%.6f pts_per_s=%.0f\n", xy.size(), best, static_cast<double>(xy.size()) / best);
  return 0;
}
