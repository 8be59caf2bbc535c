// cnc-predict: offline prediction of the machined surface (seeds 000 and 004).
//
//   cnc-predict slot --material FILE --flutes N --diameter D --helix DEG
//                    --axial-depth A --feed-per-tooth C [--discs M] [--model linear_edge|chip_thickness_law]
//       the disc simulation's per-revolution mean forces of a full slot, one line:
//       fx_mean_N=… fy_mean_N=… fz_mean_N=…
//   cnc-predict wall --tool FILE --material FILE --radial-depth AE --axial-depth A
//                    --feed-per-tooth C [--mode up|down] [--points N] [--discs M] [--model …]
//       the wall's surface error (tool deflection at each height when it is generated)
//   cnc-predict calibrate --tool FILE --csv HISTORY --radial-depth AE --axial-depth A
//                    --feed-per-tooth C [--mode up|down] --steps-per-rev N [--min-sin S]
//       identifies K_T(h), K_R(h) and the linear edge coefficients from a measured
//       force history (CSV columns fx,fy; one sample per rotation step, whole revolutions)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <sstream>
#include <string>

#include "common/process/cutting_config.h"
#include "common/process/cutting_force.h"
#include "common/process/deflection.h"
#include "common/process/force_calibration.h"
#include "tools/predict/args.h"

namespace {
using namespace cnc::process;
using cnc::predict::Args;

constexpr const char* kUsage =
    "usage: cnc-predict slot --material FILE --flutes N --diameter D --helix DEG --axial-depth A "
    "--feed-per-tooth C [--discs M] [--model linear_edge|chip_thickness_law]\n"
    "       cnc-predict wall --tool FILE --material FILE --radial-depth AE --axial-depth A --feed-per-tooth C "
    "[--mode up|down] [--points N]\n"
    "       cnc-predict calibrate --tool FILE --csv HISTORY --radial-depth AE --axial-depth A "
    "--feed-per-tooth C --steps-per-rev N [--mode up|down] [--min-sin S]\n";

int cmd_slot(const Args& a) {
  const Material mat = load_material(a.require("material"));
  const ForceModel model = a.has("model") ? force_model_from_string(a.str("model")) : mat.model;
  const std::string err = mat.validate(model);
  if (!err.empty()) throw std::invalid_argument(err);
  EndMill tool;
  tool.flutes = a.integer("flutes", 0);
  tool.diameter_mm = a.require_num("diameter");
  tool.helix_deg = a.require_num("helix");
  const std::string terr = tool.validate();
  if (!terr.empty()) throw std::invalid_argument(terr);
  const Engagement e = Engagement::slot(a.require_num("axial-depth"), a.require_num("feed-per-tooth"));
  if (!(e.axial_depth_mm > 0) || !(e.feed_per_tooth_mm > 0))
    throw std::invalid_argument("--axial-depth and --feed-per-tooth must be positive");
  const CuttingForceModel m(tool, mat, model, a.integer("discs", 200));
  const Eigen::Vector3d f = m.simulate_revolution(e, m.paper_steps_per_rev(e)).mean();
  std::printf("fx_mean_N=%.4f fy_mean_N=%.4f fz_mean_N=%.4f\n", f.x(), f.y(), f.z());
  return 0;
}

int cmd_wall(const Args& a) {
  const EndMill tool = load_tool(a.require("tool"));
  const Material mat = load_material(a.require("material"));
  const ForceModel model = a.has("model") ? force_model_from_string(a.str("model")) : mat.model;
  const std::string err = mat.validate(model);
  if (!err.empty()) throw std::invalid_argument(err);
  const double ae = a.require_num("radial-depth");
  const double ap = a.require_num("axial-depth");
  const double c = a.require_num("feed-per-tooth");
  const bool down = a.str("mode", "down") == "down";
  const Engagement e = down ? Engagement::down_milling(tool.diameter_mm, ae, ap, c)
                            : Engagement::up_milling(tool.diameter_mm, ae, ap, c);
  const CuttingForceModel m(tool, mat, model, a.integer("discs", 100));
  const auto prof = wall_surface_error(m, e, a.integer("points", 12), wall_angle(e));
  std::printf("# %s milling, %s, %s: RDC %g ADC %g feed %g mm/tooth, EI %.4g N mm^2\n", down ? "down" : "up",
              tool.name.c_str(), mat.name.c_str(), ae, ap, c, CantileverTool(tool).ei());
  std::printf("height_mm,theta_deg,fx_N,fy_N,dx_mm,dy_mm,surface_error_mm\n");
  double worst = 0;
  for (const WallErrorPoint& w : prof) {
    std::printf("%.4f,%.3f,%.3f,%.3f,%.5f,%.5f,%.5f\n", w.height_mm, w.theta * 180 / 3.14159265358979323846,
                w.force.x(), w.force.y(), w.deflection.x(), w.deflection.y(), w.surface_error_mm);
    if (std::abs(w.surface_error_mm) > std::abs(worst)) worst = w.surface_error_mm;
  }
  std::printf("# max_surface_error_mm=%.5f\n", worst);
  return 0;
}

int cmd_calibrate(const Args& a) {
  const EndMill tool = load_tool(a.require("tool"));
  const double ae = a.require_num("radial-depth");
  const double ap = a.require_num("axial-depth");
  const double c = a.require_num("feed-per-tooth");
  const std::string mode = a.str("mode", "up");
  CalibrationCut cut;
  cut.engagement = mode == "down" ? Engagement::down_milling(tool.diameter_mm, ae, ap, c)
                                  : Engagement::up_milling(tool.diameter_mm, ae, ap, c);
  cut.steps_per_rev = a.integer("steps-per-rev", 0);
  std::ifstream in(a.require("csv"));
  if (!in) throw std::invalid_argument("cannot open " + a.str("csv"));
  std::string line;
  while (std::getline(in, line)) {
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream ls(line);
    double fx = 0, fy = 0;
    if (ls >> fx >> fy) cut.fxy.emplace_back(fx, fy);  // a header line does not parse and is skipped
  }
  const CalibrationResult r = calibrate(tool, {cut}, a.num("min-sin", 0.25));
  if (!r.error.empty()) throw std::invalid_argument(r.error);
  std::printf("discs=%d residual_rms_N=%.4g samples=%zu\n", calibration_discs(tool, cut.engagement, cut.steps_per_rev),
              r.residual_rms_n, r.samples.size());
  std::printf("kt: c=%.6g exponent=%.6g  kr: c=%.6g exponent=%.6g\n", r.chip_law.kt.c, r.chip_law.kt.exponent,
              r.chip_law.kr.c, r.chip_law.kr.exponent);
  std::printf("ktc_n_mm2=%.6g kte_n_mm=%.6g krc_n_mm2=%.6g kre_n_mm=%.6g\n", r.linear.ktc, r.linear.kte, r.linear.krc,
              r.linear.kre);
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fputs(kUsage, stderr);
    return 2;
  }
  const std::string cmd = argv[1];
  try {
    const Args a(argc, argv, 2);
    if (cmd == "slot") return cmd_slot(a);
    if (cmd == "calibrate") return cmd_calibrate(a);
    if (cmd == "wall") return cmd_wall(a);
    if (cmd == "--help" || cmd == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    std::fprintf(stderr, "cnc-predict: unknown command '%s'\n%s", cmd.c_str(), kUsage);
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-predict %s: %s\n", cmd.c_str(), e.what());
    return 2;
  }
}
