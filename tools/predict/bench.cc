// cnc-predict-bench: figures of the force model (seed 004) and the Z-map (seed 000).
//   cnc-predict-bench force   relative error of the disc simulation's slot means
//                             against the closed form, by disc count
#include <cmath>
#include <cstdio>
#include <exception>
#include <string>

#include "common/process/cutting_config.h"
#include "common/process/cutting_force.h"
#include "tools/predict/args.h"

namespace {
using namespace cnc::process;

int bench_force(const cnc::predict::Args& args) {
  const Material al = load_material(args.str("material", std::string(CNC_SOURCE_DIR) + "/config/materials/al7075_t6.yaml"));
  EndMill tool;
  tool.flutes = args.integer("flutes", 4);
  tool.diameter_mm = args.num("diameter", 6.0);
  tool.helix_deg = args.num("helix", 30.0);
  const double a = args.num("axial-depth", 3.0);
  const double c = args.num("feed-per-tooth", 0.05);
  const Engagement e = Engagement::slot(a, c);
  const Eigen::Vector3d ref = slot_mean_force_closed_form(al.linear, tool.flutes, a, c);
  std::printf("force: full slot, %s, N=%d D=%g helix=%g a=%g c=%g (angular step = helix lag per disc, eq. 11)\n",
              al.name.c_str(), tool.flutes, tool.diameter_mm, tool.helix_deg, a, c);
  std::printf("force: closed form fx=%.4f fy=%.4f fz=%.4f N\n", ref.x(), ref.y(), ref.z());
  std::printf("force: %6s %8s %12s %12s %12s\n", "discs", "steps", "rel_err_fx", "rel_err_fy", "rel_err_fz");
  for (int discs : {1, 2, 5, 10, 20, 50, 100, 200, 500, 1000}) {
    const CuttingForceModel m(tool, al, ForceModel::kLinearEdge, discs);
    const int steps = m.paper_steps_per_rev(e);
    const Eigen::Vector3d f = m.simulate_revolution(e, steps).mean();
    std::printf("force: %6d %8d %12.3e %12.3e %12.3e\n", discs, steps, std::abs(f.x() / ref.x() - 1),
                std::abs(f.y() / ref.y() - 1), std::abs(f.z() / ref.z() - 1));
  }
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "all";
  try {
    const cnc::predict::Args args(argc, argv, 2);
    if (what == "force" || what == "all") bench_force(args);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-predict-bench: %s\n", e.what());
    return 2;
  }
}
