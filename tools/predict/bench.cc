// cnc-predict-bench: figures of the force model (VMCS 1999) and the Z-map (Choi et al. 2005).
//   cnc-predict-bench force   relative error of the disc simulation's slot means
//                             against the closed form, by disc count
//   cnc-predict-bench zmap    Z-map speed: Choi et al. 2005's case (r 5, f_p = f_t = 0.5 mm,
//                             α 10°, 2 flutes) on a 5×5 mm window at 2 µm, 1 and 2 threads
//                             [--window MM] [--pitch MM] [--alpha DEG]; wall and process CPU
//                             time, and the load average (other work on the machine)
//   cnc-predict-bench zmap-converge  Choi et al. 2005's α_c case (f_t = f_p = 0.5 mm, r 5, 2 flutes, 1×1 mm):
//                             Z-map − model by grid pitch, by the edge's rotation step, and by α
//                             around α_c, by window size, and by the spindle phase between passes (why the
//                             paper's 1.8 µm is not met there)
//   cnc-predict-bench deflection  the wall's largest surface error over the paper's Table 2
//                             ranges (RDC 0.5-2 mm, ADC 2-6 mm, 0.01-0.02 mm/tooth), its Al and S41C
//   cnc-predict-bench calibration  coefficients recovered from synthetic noisy histories
//                             (the unit test's set-up: 6 cuts, 1 % noise, 20 revolutions)
#include <cmath>
#include <ctime>
#include <fstream>
#include <numbers>
#include <vector>
#include <cstdio>
#include <exception>
#include <string>

#include "common/process/cutting_config.h"
#include "common/process/cutting_force.h"
#include "common/process/deflection.h"
#include "common/process/force_calibration.h"
#include "common/process/roughness.h"
#include "common/process/zmap.h"
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
int bench_zmap(const cnc::predict::Args& args) {
  InclinedPlaneCase c;
  c.window_x_mm = c.window_y_mm = args.num("window", 5.0);
  c.pitch_mm = args.num("pitch", 0.002);
  c.alpha_rad = args.num("alpha", 10.0) * 3.14159265358979323846 / 180.0;
  std::printf("zmap: ball r=%g, %d flutes, f_p=%g f_t=%g mm, alpha=%g deg, window %gx%g mm at %g um, step %.2f deg\n",
              c.radius_mm, c.flutes, c.pick_feed_mm, c.feed_per_tooth_mm, args.num("alpha", 10.0), c.window_x_mm,
              c.window_y_mm, c.pitch_mm * 1e3, c.max_step_rad * 180 / 3.14159265358979323846);
  double t1 = 0;
  std::string load;
  std::getline(std::ifstream("/proc/loadavg"), load);
  std::printf("zmap: load average before: %s\n", load.c_str());
  for (int threads : {1, 2}) {
    c.threads = threads;
    const std::clock_t cpu0 = std::clock();
    const InclinedPlaneResult r = simulate_inclined_plane(c);
    const double cpu = static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC;
    if (threads == 1) t1 = r.seconds;
    std::printf("zmap: threads=%d cells=%lld time_s=%.3f cells_per_s=%.3g edge_tests=%lld edge_tests_per_s=%.3g "
                "rmax_um=%.3f speedup=%.2f cpu_s=%.3f\n",
                threads, r.cells, r.seconds, static_cast<double>(r.cells) / r.seconds, r.stats.cells_visited,
                static_cast<double>(r.stats.cells_visited) / r.seconds, r.rmax_mm * 1e3, t1 / r.seconds, cpu);
  }
  return 0;
}
int bench_zmap_converge() {
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  InclinedPlaneCase c;  // r 5, f_p = f_t = 0.5, 2 flutes, 1×1 mm, 2.5 µm, 0.5°
  c.threads = 2;
  const double ac = critical_angle(c.radius_mm, c.feed_per_tooth_mm, c.pick_feed_mm);
  auto diff = [&](const InclinedPlaneCase& k, double* zmap_um) {
    const InclinedPlaneResult r = simulate_inclined_plane(k);
    *zmap_um = r.rmax_mm * 1e3;
    return (r.rmax_mm - rmax_extended(k.radius_mm, k.feed_per_tooth_mm, k.pick_feed_mm, k.alpha_rad)) * 1e3;
  };
  std::printf("zmap-converge: r=%g f_p=%g f_t=%g, %d flutes, window %gx%g mm; alpha_c=%.4f deg (eq. 4)\n", c.radius_mm,
              c.pick_feed_mm, c.feed_per_tooth_mm, c.flutes, c.window_x_mm, c.window_y_mm, ac / kDeg);
  c.alpha_rad = 4.34 * kDeg;  // just below α_c: region I, model 10.695 µm
  for (double pitch_um : {20.0, 10.0, 5.0, 2.5, 1.25, 1.0}) {
    InclinedPlaneCase k = c;
    k.pitch_mm = pitch_um * 1e-3;
    double z = 0;
    const double d = diff(k, &z);
    std::printf("zmap-converge: alpha=4.34 step_deg=0.50 pitch_um=%.2f zmap_um=%.3f diff_um=%.3f\n", pitch_um, z, d);
  }
  for (double step_deg : {2.0, 1.0, 0.5, 0.25, 0.1}) {
    InclinedPlaneCase k = c;
    k.max_step_rad = step_deg * kDeg;
    double z = 0;
    const double d = diff(k, &z);
    std::printf("zmap-converge: alpha=4.34 pitch_um=2.50 step_deg=%.2f zmap_um=%.3f diff_um=%.3f\n", step_deg, z, d);
  }
  for (double window_mm : {0.5, 1.0, 2.0, 3.0}) {  // the window's edges: the cut runs r beyond it anyway
    InclinedPlaneCase k = c;
    k.window_x_mm = k.window_y_mm = window_mm;
    double z = 0;
    const double d = diff(k, &z);
    std::printf("zmap-converge: alpha=4.34 pitch_um=2.50 window_mm=%.1f zmap_um=%.3f diff_um=%.3f\n", window_mm, z, d);
  }
  // The case's definition: the spindle phase from one pass to the next (the paper states none;
  // 0 = every pass starts with the same phase; 180° repeats 0 with two flutes).
  for (double a : {4.34, 10.0}) {
    for (double phase = 0; phase < 180; phase += 15) {
      InclinedPlaneCase k = c;
      k.alpha_rad = a * kDeg;
      k.pass_phase_rad = phase * kDeg;
      double z = 0;
      const double d = diff(k, &z);
      std::printf("zmap-converge: pitch_um=2.50 alpha=%5.2f pass_phase_deg=%5.1f zmap_um=%.3f diff_um=%.3f\n", a, phase, z, d);
    }
  }
  for (double a : {3.0, 3.5, 3.8, 4.0, 4.1, 4.2, 4.3, 4.34, 4.36, 4.4, 4.5, 4.6, 4.8, 5.0, 5.5, 6.0}) {
    InclinedPlaneCase k = c;
    k.alpha_rad = a * kDeg;
    double z = 0;
    const double d = diff(k, &z);
    std::printf("zmap-converge: pitch_um=2.50 alpha=%5.2f (alpha-alpha_c=%+.2f) zmap_um=%.3f model_um=%.3f diff_um=%.3f\n",
                a, a - ac / kDeg, z, z - d, d);
  }
  return 0;
}

int bench_deflection() {
  const std::string cfg = std::string(CNC_SOURCE_DIR) + "/config/";
  const EndMill tool = load_tool(cfg + "tools/hss_flat_4f_d6.yaml");
  std::printf("deflection: %s, overhang %g mm, EI %.4g N mm^2; largest |surface error| over the wall, mm "
              "(+ material left), down / up milling\n",
              tool.name.c_str(), tool.overhang_mm, CantileverTool(tool).ei());
  for (const char* file : {"materials/al_paper004.yaml", "materials/s41c.yaml"}) {
    const Material mat = load_material(cfg + file);
    const CuttingForceModel m(tool, mat, mat.model, 100);
    std::printf("deflection: %-16s %5s %5s %6s %10s %10s %9s\n", mat.name.c_str(), "RDC", "ADC", "feed", "down_mm",
                "up_mm", "Fmax_N");
    for (double ae : {0.5, 1.0, 2.0}) {
      for (double ap : {2.0, 4.0, 6.0}) {
        for (double c : {0.01, 0.02}) {
          double w[2] = {0, 0}, fmax = 0;
          for (int up = 0; up < 2; ++up) {
            const Engagement e = up ? Engagement::up_milling(6.0, ae, ap, c) : Engagement::down_milling(6.0, ae, ap, c);
            for (const WallErrorPoint& p : wall_surface_error(m, e, 30, wall_angle(e))) {
              if (std::abs(p.surface_error_mm) > std::abs(w[up])) w[up] = p.surface_error_mm;
            }
            for (const Eigen::Vector3d& f : m.simulate_revolution(e, 360).force) fmax = std::max(fmax, f.head<2>().norm());
          }
          std::printf("deflection: %-16s %5.1f %5.1f %6.3f %10.4f %10.4f %9.1f\n", "", ae, ap, c, w[0], w[1], fmax);
        }
      }
    }
  }
  return 0;
}

int bench_calibration() {
  constexpr double kPi = std::numbers::pi;
  EndMill tool;
  const int steps = 180;
  const double dz = tool.radius() * (2 * kPi / steps) / std::tan(kPi / 6);
  const double a = 11 * dz;
  const std::string dir = std::string(CNC_SOURCE_DIR) + "/config/materials/";
  for (const char* file : {"al_paper004.yaml", "al7075_t6.yaml"}) {
    const Material mat = load_material(dir + file);
    std::vector<CalibrationCut> cuts;
    unsigned seed = 16;
    for (double c : {0.01, 0.02, 0.03}) {
      for (bool up : {true, false}) {
        const Engagement e = up ? Engagement::up_milling(6.0, 1.0, a, c) : Engagement::down_milling(6.0, 1.0, a, c);
        const CuttingForceModel m(tool, mat, mat.model, calibration_discs(tool, e, steps));
        double peak = 0;
        for (const Eigen::Vector3d& f : m.simulate_revolution(e, steps).force) peak = std::max(peak, f.head<2>().norm());
        cuts.push_back(synthetic_cut(tool, mat, mat.model, e, steps, 20, 0.01 * peak, seed++));
      }
    }
    const CalibrationResult r = calibrate(tool, cuts);
    std::printf("calibration: %s (%s), 6 cuts (up/down, ae 1 mm, a %.3f mm, c 0.01-0.03), noise 1 %% of peak, 20 revs, "
                "%d discs: %s\n",
                mat.name.c_str(), to_string(mat.model), a, calibration_discs(tool, cuts[0].engagement, steps),
                r.error.empty() ? "ok" : r.error.c_str());
    auto line = [](const char* name, double truth, double got) {
      std::printf("calibration:   %-12s true %10.5g recovered %10.5g rel_err %.2e\n", name, truth, got,
                  std::abs(got / truth - 1));
    };
    if (mat.model == ForceModel::kChipThicknessLaw) {
      line("K_T c", mat.chip_law.kt.c, r.chip_law.kt.c);
      line("K_T exp", mat.chip_law.kt.exponent, r.chip_law.kt.exponent);
      line("K_R c", mat.chip_law.kr.c, r.chip_law.kr.c);
      line("K_R exp", mat.chip_law.kr.exponent, r.chip_law.kr.exponent);
    } else {
      line("K_tc", mat.linear.ktc, r.linear.ktc);
      line("K_te", mat.linear.kte, r.linear.kte);
      line("K_rc", mat.linear.krc, r.linear.krc);
      line("K_re", mat.linear.kre, r.linear.kre);
    }
  }
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"figures of the force model (VMCS 1999) and the Z-map (Choi et al. 2005)", "cnc-predict-bench"};
  cnc::util::cli::setup(app);
  std::string what = "all";
  app.add_option("what", what, "force, deflection, calibration, zmap, zmap-converge or all")
      ->check(CLI::IsMember({"all", "force", "deflection", "calibration", "zmap", "zmap-converge"}));
  cnc::predict::Args args;
  args.text(&app, "material", "FILE", "force: the work material (default al7075_t6)")
      .number(&app, "flutes", "N", "force: flutes (default 4)")
      .number(&app, "diameter", "D", "force: tool diameter, mm (default 6)")
      .number(&app, "helix", "DEG", "force: helix angle (default 30)")
      .number(&app, "axial-depth", "A", "force: axial depth, mm (default 3)")
      .number(&app, "feed-per-tooth", "C", "force: feed per tooth, mm (default 0.05)")
      .number(&app, "window", "MM", "zmap: window side, mm (default 5)")
      .number(&app, "pitch", "MM", "zmap: pitch, mm (default 0.002)")
      .number(&app, "alpha", "DEG", "zmap: inclination, degrees (default 10)");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  try {
    if (what == "force" || what == "all") bench_force(args);
    if (what == "deflection" || what == "all") bench_deflection();
    if (what == "calibration" || what == "all") bench_calibration();
    if (what == "zmap" || what == "all") bench_zmap(args);
    if (what == "zmap-converge") bench_zmap_converge();
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-predict-bench: %s\n", e.what());
    return 2;
  }
}
