#include "tools/predict/program_predict.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "common/process/cutting_config.h"
#include "common/process/deflection.h"
#include "common/process/engagement.h"
#include "common/process/roughness.h"
#include "common/process/zmap.h"
#include "tools/predict/args.h"

namespace cnc::predict {
namespace {
using namespace cnc::process;
constexpr double kPi = std::numbers::pi;

struct Setpoint {
  double t = 0;
  Eigen::Vector3d p;
  int line = 0;
  double feed = 0;
  bool cutting = true;
};

std::vector<Setpoint> read_setpoints(const std::string& file) {
  std::ifstream in(file);
  if (!in) throw std::invalid_argument("cannot open " + file);
  std::string row;
  std::getline(in, row);
  if (row.rfind("cycle,t_s,x_mm,y_mm,z_mm,line,u,feed_mm_min", 0) != 0)
    throw std::invalid_argument(file + ": not a cnc-plan CSV (header '" + row + "')");
  std::vector<Setpoint> out;
  while (std::getline(in, row)) {
    std::replace(row.begin(), row.end(), ',', ' ');
    std::istringstream ls(row);
    long long cycle = 0;
    Setpoint s;
    double u = 0;
    if (ls >> cycle >> s.t >> s.p.x() >> s.p.y() >> s.p.z() >> s.line >> u >> s.feed) out.push_back(s);
  }
  return out;
}

// Per program line: true where the modal motion is G0 (a rapid), from a plain scan of
// the G words (comments dropped); and the first S word.
struct ProgramScan {
  std::vector<bool> rapid;  // by 1-based line
  std::vector<std::string> text;
  double spindle = 0;
};

ProgramScan scan_program(const std::string& file) {
  ProgramScan scan;
  std::ifstream in(file);
  if (!in) throw std::invalid_argument("cannot open " + file);
  std::string line;
  bool rapid = true;
  scan.rapid.push_back(true);
  scan.text.emplace_back();
  while (std::getline(in, line)) {
    scan.text.push_back(line);
    std::string code;
    int depth = 0;
    for (char ch : line) {
      if (ch == '(') depth++;
      else if (ch == ')') depth = std::max(0, depth - 1);
      else if (ch == ';') break;
      else if (depth == 0) code.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(ch))));
    }
    for (size_t i = 0; i < code.size(); ++i) {
      if (code[i] != 'G' && code[i] != 'S') continue;
      size_t j = i + 1;
      while (j < code.size() && code[j] == ' ') ++j;
      size_t k = j;
      while (k < code.size() && (std::isdigit(static_cast<unsigned char>(code[k])) || code[k] == '.')) ++k;
      if (k == j) continue;
      const double v = std::atof(code.substr(j, k - j).c_str());
      if (code[i] == 'S') {
        if (scan.spindle == 0 && v > 0) scan.spindle = v;
      } else if (v == 0.0) {
        rapid = true;
      } else if (v == 1.0 || v == 2.0 || v == 3.0 || v == 5.2 || v == 6.2 || v == 5.0) {
        rapid = false;
      }
    }
    scan.rapid.push_back(rapid);
  }
  return scan;
}
}  // namespace

int cmd_program(const Args& a) {
  const std::string dir = a.require("out");
  std::vector<Setpoint> sp = read_setpoints(a.require("csv"));
  const EndMill tool = load_tool(a.require("tool"));
  ProgramScan scan;
  if (a.has("program")) scan = scan_program(a.str("program"));
  for (Setpoint& s : sp) {
    s.cutting = s.feed > 0 && !(s.line > 0 && static_cast<size_t>(s.line) < scan.rapid.size() &&
                                scan.rapid[static_cast<size_t>(s.line)]);
  }
  const double rpm = a.num("spindle-rpm", scan.spindle > 0 ? scan.spindle : 10000.0);
  const double r = tool.radius();
  // Stock: the cutting moves' bounding box plus the tool radius and a margin, below
  // the highest cutting move (or --stock-top).
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300, ztop = -1e300, zlow = 1e300;
  for (const Setpoint& s : sp) {
    if (!s.cutting) continue;
    x0 = std::min(x0, s.p.x()), x1 = std::max(x1, s.p.x());
    y0 = std::min(y0, s.p.y()), y1 = std::max(y1, s.p.y());
    ztop = std::max(ztop, s.p.z()), zlow = std::min(zlow, s.p.z());
  }
  if (x0 > x1) throw std::invalid_argument("no cutting move in the setpoints");
  const double margin = r + a.num("margin", 1.0);
  x0 -= margin, x1 += margin, y0 -= margin, y1 += margin;
  if (a.has("window")) {  // X0,Y0,X1,Y1: the Z-map over this window only
    std::string w = a.str("window");
    std::replace(w.begin(), w.end(), ',', ' ');
    std::istringstream ws(w);
    if (!(ws >> x0 >> y0 >> x1 >> y1) || !(x1 > x0) || !(y1 > y0))
      throw std::invalid_argument("--window expects X0,Y0,X1,Y1 with X1 > X0 and Y1 > Y0");
  }
  ztop = a.num("stock-top", ztop);
  const double area = (x1 - x0) * (y1 - y0);
  const double pitch = a.num("pitch", std::max(0.01, std::sqrt(area / a.num("max-cells", 4e6))));
  const int nx = static_cast<int>(std::ceil((x1 - x0) / pitch)), ny = static_cast<int>(std::ceil((y1 - y0) / pitch));
  ZMap stock(x0, y0, pitch, nx, ny, ztop);
  std::fprintf(stderr, "cnc-predict program: %zu setpoints, stock %.1f x %.1f mm top z %.3f, pitch %.1f um (%d x %d), %s, %.0f rpm\n",
               sp.size(), x1 - x0, y1 - y0, ztop, pitch * 1e3, nx, ny, tool.name.c_str(), rpm);

  std::FILE* out = std::fopen((dir + "/predict.csv").c_str(), "w");
  if (!out) throw std::invalid_argument("cannot write " + dir + "/predict.csv");
  std::map<int, double> worst_by_line;
  if (tool.type == "ball") {
    // Choi et al. 2005: the ball's rotating edges over the whole program, R_max per block.
    std::vector<ToolSample> path;
    for (const Setpoint& s : sp) {
      if (s.cutting || !path.empty()) path.push_back({s.t, s.p + Eigen::Vector3d(0, 0, r)});
    }
    ZMapCutOptions opt;
    opt.spindle_rpm = rpm;
    opt.threads = a.integer("threads", 2);
    opt.max_step_rad = a.num("step-deg", 2.0) * kPi / 180;
    const ZMapStats st = stock.cut({r, tool.flutes}, path, opt);
    std::fprintf(out, "t_s,line,x_mm,y_mm,z_mm,feed_mm_min\n");
    for (const Setpoint& s : sp) std::fprintf(out, "%.4f,%d,%.4f,%.4f,%.4f,%.1f\n", s.t, s.line, s.p.x(), s.p.y(), s.p.z(), s.feed);
    std::fprintf(stderr, "cnc-predict program: ball end mill: %lld steps, %lld columns lowered\n", st.steps, st.cells_cut);
    if (a.has("window")) {
      // R_max over the window against the nominal surface: the ball centre path of the
      // pass nearest the window's centre line (in XZ, extruded along Y) offset by r
      // along its normal; deviations along that normal. (A least-squares reference
      // fitted to the cusps and cutting remains would tilt and bend towards them and
      // read several µm high.) Against the extended model at that pass's setpoints in
      // the window.
      const double yc = 0.5 * (y0 + y1);
      double best = 1e300;
      for (const Setpoint& q : sp) {
        if (q.cutting) best = std::min(best, std::abs(q.p.y() - yc));
      }
      std::vector<Eigen::Vector2d> feet;  // (x, z) of the nominal surface
      for (size_t k = 1; k + 1 < sp.size(); ++k) {
        const Setpoint& q = sp[k];
        if (!q.cutting || std::abs(std::abs(q.p.y() - yc) - best) > 1e-6 || q.p.x() < x0 - r || q.p.x() > x1 + r) continue;
        const Eigen::Vector2d t(sp[k + 1].p.x() - sp[k - 1].p.x(), sp[k + 1].p.z() - sp[k - 1].p.z());
        if (t.norm() < 1e-12 || std::abs(sp[k + 1].p.y() - q.p.y()) > 1e-6 || std::abs(sp[k - 1].p.y() - q.p.y()) > 1e-6) continue;
        Eigen::Vector2d nrm(-t.y(), t.x());
        nrm.normalize();
        if (nrm.y() < 0) nrm = -nrm;
        feet.push_back(Eigen::Vector2d(q.p.x(), q.p.z() + r) - r * nrm);
      }
      std::sort(feet.begin(), feet.end(), [](const Eigen::Vector2d& l, const Eigen::Vector2d& m) { return l.x() < m.x(); });
      if (feet.size() < 2) throw std::invalid_argument("--window: no cutting pass crosses the window");
      double lo = 1e300, hi = -1e300;
      size_t seg = 0;
      for (int i = 0; i < nx; ++i) {
        const double x = stock.x(i);
        while (seg + 2 < feet.size() && feet[seg + 1].x() < x) ++seg;
        const Eigen::Vector2d& fa = feet[seg];
        const Eigen::Vector2d& fb = feet[seg + 1];
        const double dxs = fb.x() - fa.x();
        const double slope = dxs > 0 ? (fb.y() - fa.y()) / dxs : 0.0;
        const double znom = fa.y() + slope * (x - fa.x());
        const double cosa = 1.0 / std::sqrt(1 + slope * slope);
        for (int j = 0; j < ny; ++j) {
          const double dn = (stock.z(i, j) - znom) * cosa;
          lo = std::min(lo, dn), hi = std::max(hi, dn);
        }
      }
      double mlo = 1e300, mhi = -1e300, ftlo = 1e300, fthi = -1e300, alo = 1e300, ahi = -1e300;
      const double fp = a.num("pick-feed", 0.5);
      for (size_t k = 1; k < sp.size(); ++k) {
        const Setpoint& q = sp[k];
        if (!q.cutting || std::abs(std::abs(q.p.y() - yc) - best) > 1e-6 || q.p.x() < x0 || q.p.x() > x1) continue;
        const Eigen::Vector3d tan = q.p - sp[k - 1].p;
        if (tan.norm() < 1e-9) continue;
        const double ft = q.feed / (tool.flutes * rpm);
        const double alpha = feed_inclination_angle(tan);
        const double m = rmax_extended(r, ft, fp, alpha);
        mlo = std::min(mlo, m), mhi = std::max(mhi, m);
        ftlo = std::min(ftlo, ft), fthi = std::max(fthi, ft);
        alo = std::min(alo, alpha), ahi = std::max(ahi, alpha);
      }
      std::printf("window %.3f,%.3f..%.3f,%.3f pitch_um=%.2f rmax_um=%.3f model_um=%.3f..%.3f f_t=%.4f..%.4f "
                  "alpha_deg=%.2f..%.2f\n",
                  x0, y0, x1, y1, pitch * 1e3, (hi - lo) * 1e3, mlo * 1e3, mhi * 1e3, ftlo, fthi, alo * 180 / kPi,
                  ahi * 180 / kPi);
    }
  } else {
    const Material mat = load_material(a.require("material"));
    const ForceModel model = a.has("model") ? force_model_from_string(a.str("model")) : mat.model;
    const CuttingForceModel fm(tool, mat, model, 1);
    const CantileverTool beam(tool);
    const double tan_h = std::tan(tool.helix_deg * kPi / 180);
    std::fprintf(out, "t_s,line,x_mm,y_mm,z_mm,feed_mm_min,arc_start_deg,arc_exit_deg,ap_mm,fx_mean_N,fy_mean_N,"
                      "f_peak_N,deflection_peak_mm,wall_deg,surface_error_mm,final_wall\n");
    // The wall points, to find after the cut which walls are final (material still
    // stands two cells beyond them) and which a later pass removed.
    struct WallPoint {
      long row;  // index into `rows`
      Eigen::Vector2d beyond;
      double z;
    };
    std::vector<WallPoint> walls;
    std::vector<std::string> rows;
    std::vector<std::pair<int, double>> row_err;
    Eigen::Vector2d dir_prev(1, 0);
    std::vector<Eigen::Vector3d> discs;
    size_t next_report = sp.size() / 10;
    // Stations: a setpoint at least station_mm of travel after the previous station,
    // or the last of a program line; between stations the tool's envelope is removed
    // along the straight chord (the setpoints are 4 ms apart, far closer than that).
    const double station = a.num("station-mm", 0.05);
    Eigen::Vector3d prev = sp[0].p;
    for (size_t k = 1; k < sp.size(); ++k) {
      const Setpoint& s = sp[k];
      if (k >= next_report && k + 1 < sp.size()) {
        std::fprintf(stderr, "cnc-predict program: %3.0f %%\n", 100.0 * static_cast<double>(k) / static_cast<double>(sp.size()));
        next_report += std::max<size_t>(sp.size() / 10, 1);
      }
      if (!s.cutting) {
        prev = s.p;
        continue;
      }
      const bool last_of_line = k + 1 == sp.size() || sp[k + 1].line != s.line;
      if ((s.p - prev).norm() < station && !last_of_line) continue;
      const Eigen::Vector2d d = (s.p - prev).head<2>();
      if (d.norm() > 1e-9) dir_prev = d.normalized();
      const double c = s.feed / (tool.flutes * rpm);
      const EngagementProfile prof = engagement_from_stock(stock, s.p, dir_prev, r, tool.overhang_mm, 180, c);
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      double fpeak = 0, dpeak = 0, err = 0, wall = -1;
      if (prof.engaged() && c > 0) {
        const int n_theta = 16;
        for (int j = 0; j < n_theta; ++j) {
          const double theta = 2 * kPi / tool.flutes * j / n_theta;
          double dz = 0;
          const Eigen::Vector3d f = force_from_profile(fm, prof, 0.1, theta, &discs, &dz);
          mean += f / n_theta;
          fpeak = std::max(fpeak, f.head<2>().norm());
          std::vector<double> h(discs.size());
          for (size_t i = 0; i < h.size(); ++i) h[i] = (static_cast<double>(i) + 0.5) * dz;
          dpeak = std::max(dpeak, beam.deflection(0.0, h, discs).norm());
        }
        // The wall this step leaves: the engaged arc's end at a side (down milling at
        // φ = π, up milling at φ = 0); its error at five heights from the generation angle.
        const double bin = kPi / 180;
        if (prof.arc_exit() > kPi - 1.5 * bin) wall = kPi;
        else if (prof.arc_start() < 1.5 * bin) wall = 0.0;
        if (wall >= 0) {
          const size_t wb = wall > 0 ? prof.depth.size() - 1 : 0;
          const double ap = prof.depth[wb];
          const Eigen::Vector2d nrm_local(std::sin(wall), std::cos(wall));
          const Eigen::Vector2d fdir = prof.feed_dir, left(-fdir.y(), fdir.x());
          const Eigen::Vector2d nrm = nrm_local.x() * fdir + nrm_local.y() * left;
          walls.push_back({static_cast<long>(rows.size()), s.p.head<2>() + (r + 2 * pitch) * nrm, s.p.z() + 0.5 * ap});
          for (int q = 0; q < 5; ++q) {
            const double sg = (q + 0.5) * ap / 5;
            double dz = 0;
            force_from_profile(fm, prof, 0.1, wall + sg * tan_h / r, &discs, &dz);
            std::vector<double> h(discs.size());
            for (size_t i = 0; i < h.size(); ++i) h[i] = (static_cast<double>(i) + 0.5) * dz;
            const double e = -beam.deflection(sg, h, discs).dot(nrm);
            if (std::abs(e) > std::abs(err)) err = e;
          }
        }
      }
      char buf[400];
      std::snprintf(buf, sizeof buf, "%.4f,%d,%.4f,%.4f,%.4f,%.1f,%.2f,%.2f,%.4f,%.3f,%.3f,%.3f,%.5f,%.0f,%.5f", s.t,
                    s.line, s.p.x(), s.p.y(), s.p.z(), s.feed, prof.engaged() ? prof.arc_start() * 180 / kPi : 0.0,
                    prof.engaged() ? prof.arc_exit() * 180 / kPi : 0.0, prof.max_depth(), mean.x(), mean.y(), fpeak,
                    dpeak, wall >= 0 ? wall * 180 / kPi : -1.0, err);
      rows.emplace_back(buf);
      row_err.emplace_back(s.line, err);
      remove_flat_envelope(stock, prev, s.p, r);
      prev = s.p;
    }
    // (Reported after the loop: the last report inside it came at 10 x (n / 10) of n
    // setpoints, 100 % only where that rounded up, and never where n is a multiple of 10.)
    std::fprintf(stderr, "cnc-predict program: 100 %%\n");
    std::vector<char> final_wall(rows.size(), 0);
    for (const WallPoint& w : walls) {
      const double zs = stock.sample(w.beyond.x(), w.beyond.y());
      final_wall[static_cast<size_t>(w.row)] = std::isnan(zs) || zs > w.z;
    }
    for (size_t i = 0; i < rows.size(); ++i) {
      std::fprintf(out, "%s,%d\n", rows[i].c_str(), final_wall[i]);
      if (!final_wall[i]) continue;
      double& w = worst_by_line[row_err[i].first];
      if (std::abs(row_err[i].second) > std::abs(w)) w = row_err[i].second;
    }
  }
  std::fclose(out);
  // The stock after the cut, downsampled to at most ~--stock-cells columns a side.
  const int every = std::max(1, std::max(nx, ny) / std::max(1, a.integer("stock-cells", 400)));
  std::FILE* sf = std::fopen((dir + "/stock.csv").c_str(), "w");
  if (!sf) throw std::invalid_argument("cannot write " + dir + "/stock.csv");
  std::fprintf(sf, "# z_mm; rows y, columns x; x0=%.6f y0=%.6f pitch_mm=%g\n", stock.x(0), stock.y(0), pitch * every);
  for (int j = 0; j < ny; j += every) {
    for (int i = 0; i < nx; i += every) std::fprintf(sf, i ? ",%.5f" : "%.5f", stock.z(i, j));
    std::fputc('\n', sf);
  }
  std::fclose(sf);
  if (tool.type == "ball") {
    // R_max per block, after removing each block's least-squares plane.
    const int block = std::max(4, static_cast<int>(std::lround(a.num("block", 0.5) / pitch)));
    std::FILE* rf = std::fopen((dir + "/rmax_map.csv").c_str(), "w");
    if (!rf) throw std::invalid_argument("cannot write " + dir + "/rmax_map.csv");
    std::fprintf(rf, "# R_max um per %g mm block (plane removed), rows y, columns x; x0=%.6f y0=%.6f\n", block * pitch,
                 stock.x0(), stock.y0());
    for (int bj = 0; bj + block <= ny; bj += block) {
      for (int bi = 0; bi + block <= nx; bi += block) {
        Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
        Eigen::Vector3d atb = Eigen::Vector3d::Zero();
        for (int j = bj; j < bj + block; ++j) {
          for (int i = bi; i < bi + block; ++i) {
            const Eigen::Vector3d row(1.0, stock.x(i) - stock.x(bi), stock.y(j) - stock.y(bj));
            ata += row * row.transpose();
            atb += row * static_cast<double>(stock.z(i, j));
          }
        }
        const Eigen::Vector3d pl = ata.ldlt().solve(atb);
        double lo = 1e300, hi = -1e300;
        for (int j = bj; j < bj + block; ++j) {
          for (int i = bi; i < bi + block; ++i) {
            const double dv = stock.z(i, j) - (pl[0] + pl[1] * (stock.x(i) - stock.x(bi)) + pl[2] * (stock.y(j) - stock.y(bj)));
            lo = std::min(lo, dv), hi = std::max(hi, dv);
          }
        }
        const bool untouched = hi - lo < 1e-9 && std::abs(pl[0] - ztop) < 1e-9;
        std::fprintf(rf, bi ? ",%.4f" : "%.4f", untouched ? -1.0 : (hi - lo) * 1e3);
      }
      std::fputc('\n', rf);
    }
    std::fclose(rf);
  }
  // The worst places, tied to program lines.
  std::vector<std::pair<int, double>> worst(worst_by_line.begin(), worst_by_line.end());
  std::sort(worst.begin(), worst.end(), [](auto& l, auto& m) { return std::abs(l.second) > std::abs(m.second); });
  std::FILE* wf = std::fopen((dir + "/worst_lines.csv").c_str(), "w");
  if (wf) {
    std::fprintf(wf, "line,surface_error_mm,text\n");  // final walls only
    for (size_t i = 0; i < worst.size() && i < 10; ++i) {
      std::string text = static_cast<size_t>(worst[i].first) < scan.text.size() ? scan.text[static_cast<size_t>(worst[i].first)] : "";
      std::replace(text.begin(), text.end(), ',', ' ');
      std::fprintf(wf, "%d,%.5f,%s\n", worst[i].first, worst[i].second, text.c_str());
    }
    std::fclose(wf);
  }
  if (!worst.empty()) std::printf("worst_surface_error_mm=%.5f line=%d\n", worst[0].second, worst[0].first);
  std::printf("wrote %s/predict.csv %s/stock.csv\n", dir.c_str(), dir.c_str());
  return 0;
}

}  // namespace cnc::predict
