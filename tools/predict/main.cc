// cnc-predict: offline prediction of the machined surface (Choi et al. 2005 and VMCS 1999).
//
//   cnc-predict slot --material FILE --flutes N --diameter D --helix DEG
//                    --axial-depth A --feed-per-tooth C [--discs M] [--model linear_edge|chip_thickness_law]
//       the disc simulation's per-revolution mean forces of a full slot, one line:
//       fx_mean_N=… fy_mean_N=… fz_mean_N=…
//   cnc-predict wall --tool FILE --material FILE --radial-depth AE --axial-depth A
//                    --feed-per-tooth C [--mode up|down] [--points N] [--discs M] [--model …]
//       the wall's surface error (tool deflection at each height when it is generated)
//   cnc-predict zmap --alpha DEG --feed-per-tooth C [--pick-feed P] [--radius R] [--flutes N]
//                    [--window MM] [--pitch MM] [--threads N] [--out DIR]
//       Choi et al. 2005's inclined-plane case on a Z-map of the rotating edges: R_max against
//       the extended model; --out writes the surface (deviation from the plane) and its R_max map
//   cnc-predict zmap-check --out DIR [--pitch MM] [--threads N]
//       the digest's cases and an (α, f_t) grid: rmax_cases.csv, rmax_grid.csv, two surfaces;
//       tools/predict/plot_zmap.py DIR plots them
//   cnc-predict program --csv SETPOINTS --tool FILE [--material FILE] --out DIR [--program NGC]
//                    [--spindle-rpm S] [--pitch MM] [--stock-top Z] [--margin MM]
//       along a dry run's setpoints (cnc-plan --csv) through a Z-map stock: a flat end
//       mill's engagement, forces, deflection and wall error per setpoint; a ball end
//       mill's surface and R_max map (./cnc predict PROGRAM … runs the dry run first);
//       --window X0,Y0,X1,Y1 [--pick-feed P]: a ball's Z-map over that window only, its
//       R_max against the nominal surface and the extended model (the Fig. 11-like check,
//       tools/predict/fig11_passes.py writes the program)
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
#include "common/process/roughness.h"
#include "common/process/zmap.h"
#include "tools/predict/args.h"
#include "tools/predict/program_predict.h"

namespace {
using namespace cnc::process;
using cnc::predict::Args;

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

constexpr double kDeg = 3.14159265358979323846 / 180.0;

InclinedPlaneCase zmap_case(const Args& a) {
  InclinedPlaneCase c;
  c.radius_mm = a.num("radius", 5.0);
  c.flutes = a.integer("flutes", 2);
  c.pick_feed_mm = a.num("pick-feed", 0.5);
  c.feed_per_tooth_mm = a.num("feed-per-tooth", 0.5);
  c.alpha_rad = a.num("alpha", 0.0) * kDeg;
  c.window_x_mm = c.window_y_mm = a.num("window", 1.0);
  c.pitch_mm = a.num("pitch", 0.0025);
  c.max_step_rad = a.num("step-deg", 0.5) * kDeg;
  c.pass_phase_rad = a.num("pass-phase-deg", 0.0) * kDeg;  // spindle phase added from one pass to the next
  c.threads = a.integer("threads", 2);
  if (!(c.radius_mm > 0) || c.flutes < 1 || !(c.pick_feed_mm > 0) || !(c.feed_per_tooth_mm > 0) || !(c.pitch_mm > 0) ||
      !(c.window_x_mm > 0))
    throw std::invalid_argument("radius, flutes, pick-feed, feed-per-tooth, pitch and window must be positive");
  return c;
}

// The surface's deviation from the nominal plane (µm), every `every`-th cell, as CSV rows.
void write_surface(const std::string& file, const ZMap& m, double alpha, int every) {
  std::FILE* f = std::fopen(file.c_str(), "w");
  if (!f) throw std::invalid_argument("cannot write " + file);
  const double sa = std::sin(alpha), ca = std::cos(alpha);
  std::fprintf(f, "# deviation from the nominal plane, um; rows y, columns x; pitch_mm=%g\n", m.pitch() * every);
  for (int j = 0; j < m.ny(); j += every) {
    for (int i = 0; i < m.nx(); i += every) {
      std::fprintf(f, i ? ",%.4f" : "%.4f", (-m.x(i) * sa + m.z(i, j) * ca) * 1e3);
    }
    std::fputc('\n', f);
  }
  std::fclose(f);
}

int cmd_zmap(const Args& a) {
  const InclinedPlaneCase c = zmap_case(a);
  ZMap m(0, 0, 1, 1, 1, 0);
  const InclinedPlaneResult r = simulate_inclined_plane(c, &m);
  const double model = rmax_extended(c.radius_mm, c.feed_per_tooth_mm, c.pick_feed_mm, c.alpha_rad);
  std::printf("rmax_um=%.3f model_um=%.3f diff_um=%.3f alpha_c_deg=%.3f cells=%lld time_s=%.3f cells_per_s=%.3g\n",
              r.rmax_mm * 1e3, model * 1e3, (r.rmax_mm - model) * 1e3,
              critical_angle(c.radius_mm, c.feed_per_tooth_mm, c.pick_feed_mm) / kDeg, r.cells, r.seconds,
              static_cast<double>(r.cells) / r.seconds);
  if (a.has("out")) {
    const std::string dir = a.str("out");
    write_surface(dir + "/zmap_surface.csv", m, c.alpha_rad, std::max(1, m.nx() / 400));
    const double sa = std::sin(c.alpha_rad), ca = std::cos(c.alpha_rad);
    const int block = std::max(1, static_cast<int>(std::lround(a.num("block", 0.25) / c.pitch_mm)));
    const RmaxMap map = zmap_rmax_map(m, [&](double x, double, double z) { return -x * sa + z * ca; }, block, block);
    std::FILE* f = std::fopen((dir + "/rmax_map.csv").c_str(), "w");
    if (!f) throw std::invalid_argument("cannot write " + dir + "/rmax_map.csv");
    std::fprintf(f, "# R_max per %g mm block, um; rows y, columns x\n", block * c.pitch_mm);
    for (int b = 0; b < map.nby; ++b) {
      for (int i = 0; i < map.nbx; ++i) std::fprintf(f, i ? ",%.4f" : "%.4f", map.rmax[static_cast<size_t>(b * map.nbx + i)] * 1e3);
      std::fputc('\n', f);
    }
    std::fclose(f);
  }
  return 0;
}

int cmd_zmap_check(const Args& a) {
  const std::string dir = a.require("out");
  InclinedPlaneCase base = zmap_case(a);
  const double r = base.radius_mm, fp = base.pick_feed_mm;
  std::FILE* cases = std::fopen((dir + "/rmax_cases.csv").c_str(), "w");
  std::FILE* grid = std::fopen((dir + "/rmax_grid.csv").c_str(), "w");
  if (!cases || !grid) throw std::invalid_argument("cannot write into " + dir);
  std::fprintf(cases, "case,alpha_deg,ft_mm,zmap_um,model_um,diff_um\n");
  std::fprintf(grid, "alpha_deg,ft_mm,zmap_um,model_um,diff_um\n");
  double worst_case = 0, worst_grid = 0;
  auto run = [&](double alpha_deg, double ft, ZMap* keep) {
    InclinedPlaneCase c = base;
    c.alpha_rad = alpha_deg * kDeg;
    c.feed_per_tooth_mm = ft;
    const InclinedPlaneResult res = simulate_inclined_plane(c, keep);
    return std::pair<double, double>(res.rmax_mm * 1e3, rmax_extended(r, ft, fp, c.alpha_rad) * 1e3);
  };
  struct Case { const char* name; double alpha; double ft; };
  const double ac = critical_angle(r, fp, fp) / kDeg;
  const Case list[] = {{"fig4_alpha10_ft=fp", 10.0, fp},
                       {"fig5_alpha0_ft=fp", 0.0, fp},
                       {"alpha_c_ft=fp", ac, fp},
                       {"alpha0_ft=0.653fp", 0.0, 0.653 * fp},
                       {"alpha0_ft=0.319", 0.0, 0.319 * fp / 0.5}};
  for (const Case& k : list) {
    ZMap m(0, 0, 1, 1, 1, 0);
    const auto [z, model] = run(k.alpha, k.ft, &m);
    std::fprintf(cases, "%s,%.3f,%.4f,%.3f,%.3f,%.3f\n", k.name, k.alpha, k.ft, z, model, z - model);
    std::printf("case %-20s alpha=%6.3f ft=%.4f zmap_um=%7.3f model_um=%7.3f diff_um=%6.3f\n", k.name, k.alpha, k.ft, z,
                model, z - model);
    if (std::abs(z - model) > std::abs(worst_case)) worst_case = z - model;
    if (k.alpha == 0.0 && k.ft == fp) write_surface(dir + "/surface_alpha0.csv", m, 0.0, std::max(1, m.nx() / 400));
    if (k.alpha == 10.0) write_surface(dir + "/surface_alpha10.csv", m, k.alpha * kDeg, std::max(1, m.nx() / 400));
    if (k.alpha == ac) write_surface(dir + "/surface_alphac.csv", m, k.alpha * kDeg, std::max(1, m.nx() / 400));
  }
  const double amax = a.num("grid-alpha-max", 20.0), astep = a.num("grid-alpha-step", 1.0);
  for (double al = 0.0; al <= amax + 1e-9; al += astep) {
    for (double ratio = 0.55; ratio <= 1.0001; ratio += 0.05) {
      const auto [z, model] = run(al, ratio * fp, nullptr);
      std::fprintf(grid, "%.3f,%.4f,%.3f,%.3f,%.3f\n", al, ratio * fp, z, model, z - model);
      if (std::abs(z - model) > std::abs(worst_grid)) worst_grid = z - model;
    }
    std::fprintf(stderr, "zmap-check: alpha %.1f done\n", al);
  }
  std::fclose(cases);
  std::fclose(grid);
  std::printf("max_diff_cases_um=%.3f max_diff_grid_um=%.3f\n", worst_case, worst_grid);
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
  CLI::App app{"offline prediction of cutting force, tool deflection and the machined surface", "cnc-predict"};
  cnc::util::cli::setup(app);
  app.require_subcommand(1, 1);
  Args a;
  const bool req = true;
  const auto model = [&](CLI::App* c) {
    a.text(c, "model", "linear_edge|chip_thickness_law", "the force model (default: the material's)");
  };
  CLI::App* slot = app.add_subcommand("slot", "the disc simulation's per-revolution mean forces of a full slot");
  a.text(slot, "material", "FILE", "the work material (config/materials/*.yaml)", req)
      .number(slot, "flutes", "N", "flutes", req)
      .number(slot, "diameter", "D", "tool diameter, mm", req)
      .number(slot, "helix", "DEG", "helix angle, degrees", req)
      .number(slot, "axial-depth", "A", "axial depth of cut, mm", req)
      .number(slot, "feed-per-tooth", "C", "feed per tooth, mm", req)
      .number(slot, "discs", "M", "discs along the flutes (default 200)");
  model(slot);
  CLI::App* wall = app.add_subcommand("wall", "the wall's surface error (tool deflection when it is generated)");
  a.text(wall, "tool", "FILE", "the end mill (config/tools/*.yaml)", req)
      .text(wall, "material", "FILE", "the work material", req)
      .number(wall, "radial-depth", "AE", "radial depth of cut, mm", req)
      .number(wall, "axial-depth", "A", "axial depth of cut, mm", req)
      .number(wall, "feed-per-tooth", "C", "feed per tooth, mm", req)
      .text(wall, "mode", "up|down", "up or down milling (default down)")
      .number(wall, "points", "N", "heights along the wall (default 12)")
      .number(wall, "discs", "M", "discs along the flutes (default 100)");
  model(wall);
  const auto zmap_case = [&](CLI::App* c) {
    a.number(c, "alpha", "DEG", "the plane's inclination, degrees (default 0)")
        .number(c, "feed-per-tooth", "C", "feed per tooth, mm (default 0.5)")
        .number(c, "pick-feed", "P", "pick feed, mm (default 0.5)")
        .number(c, "radius", "R", "ball radius, mm (default 5)")
        .number(c, "flutes", "N", "flutes (default 2)")
        .number(c, "window", "MM", "the map's window side, mm (default 1)")
        .number(c, "pitch", "MM", "the map's pitch, mm (default 0.0025)")
        .number(c, "step-deg", "DEG", "the edge's largest rotation step, degrees (default 0.5)")
        .number(c, "pass-phase-deg", "DEG", "spindle phase added from one pass to the next, degrees (default 0)")
        .number(c, "threads", "N", "threads (default 2)");
  };
  CLI::App* zmap = app.add_subcommand("zmap", "Choi et al. 2005's inclined-plane case on a Z-map: R_max against the model");
  zmap_case(zmap);
  a.text(zmap, "out", "DIR", "write the surface and its R_max map into DIR")
      .number(zmap, "block", "MM", "the R_max map's block, mm (default 0.25)");
  CLI::App* check = app.add_subcommand("zmap-check", "the digest's cases and an (alpha, f_t) grid into DIR");
  a.text(check, "out", "DIR", "where rmax_cases.csv, rmax_grid.csv and the surfaces go", req)
      .number(check, "grid-alpha-max", "DEG", "the grid's largest alpha, degrees (default 20)")
      .number(check, "grid-alpha-step", "DEG", "the grid's alpha step, degrees (default 1)");
  zmap_case(check);
  CLI::App* program = app.add_subcommand("program", "force, deflection and surface along a dry run's setpoints");
  a.text(program, "csv", "SETPOINTS", "the dry run's setpoints (cnc-plan --csv)", req)
      .text(program, "tool", "FILE", "the end mill", req)
      .text(program, "out", "DIR", "where predict.csv and the maps go", req)
      .text(program, "material", "FILE", "the work material (flat end mills)")
      .text(program, "program", "NGC", "the program (its rapid moves and spindle speed)")
      .number(program, "spindle-rpm", "S", "spindle speed (default: the program's, else 10000)")
      .number(program, "pitch", "MM", "the stock's Z-map pitch, mm (default: from --max-cells)")
      .number(program, "max-cells", "N", "the Z-map's largest cell count (default 4e6)")
      .number(program, "stock-top", "Z", "the stock's top (default: the highest cutting move)")
      .number(program, "margin", "MM", "stock beyond the tool's envelope, mm (default 1)")
      .text(program, "window", "X0,Y0,X1,Y1", "a ball's Z-map over this window only, R_max against the model")
      .number(program, "pick-feed", "P", "the passes' pick feed of --window, mm (default 0.5)")
      .number(program, "block", "MM", "the R_max map's block, mm (default 0.5)")
      .number(program, "stock-cells", "N", "stock.csv's most columns a side, downsampled beyond (default 400)")
      .number(program, "station-mm", "MM", "travel between force stations, mm (default 0.05)")
      .number(program, "step-deg", "DEG", "the edge's largest rotation step, degrees (default 2)")
      .number(program, "threads", "N", "threads (default 2)");
  model(program);
  CLI::App* calib = app.add_subcommand("calibrate", "K_T(h), K_R(h) and the linear edge coefficients from a force history");
  a.text(calib, "tool", "FILE", "the end mill", req)
      .text(calib, "csv", "HISTORY", "measured forces: columns fx,fy, one sample per rotation step", req)
      .number(calib, "radial-depth", "AE", "radial depth of cut, mm", req)
      .number(calib, "axial-depth", "A", "axial depth of cut, mm", req)
      .number(calib, "feed-per-tooth", "C", "feed per tooth, mm", req)
      .number(calib, "steps-per-rev", "N", "samples per revolution", req)
      .text(calib, "mode", "up|down", "up or down milling (default up)")
      .number(calib, "min-sin", "S", "samples with a smaller sine of the immersion are left out (default 0.25)");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  const std::string cmd = app.get_subcommands().front()->get_name();
  try {
    if (cmd == "slot") return cmd_slot(a);
    if (cmd == "calibrate") return cmd_calibrate(a);
    if (cmd == "wall") return cmd_wall(a);
    if (cmd == "zmap") return cmd_zmap(a);
    if (cmd == "zmap-check") return cmd_zmap_check(a);
    return cnc::predict::cmd_program(a);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-predict %s: %s\n", cmd.c_str(), e.what());
    return 2;
  }
}
