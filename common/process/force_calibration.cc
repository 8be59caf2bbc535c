#include "common/process/force_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

namespace cnc::process {
namespace {
constexpr double kPi = std::numbers::pi;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

struct Fit2 {
  double a = 0, b = 0;  // y = a + b·x
};

// Weighted least squares line.
Fit2 fit_line(const std::vector<double>& x, const std::vector<double>& y, const std::vector<double>& w) {
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    sw += w[i];
    sx += w[i] * x[i];
    sy += w[i] * y[i];
    sxx += w[i] * x[i] * x[i];
    sxy += w[i] * x[i] * y[i];
  }
  const double det = sw * sxx - sx * sx;
  if (!(std::abs(det) > 0.0)) return {};
  return {(sxx * sy - sx * sxy) / det, (sw * sxy - sx * sy) / det};
}

// The calibration discretisation of one cut: elements sit on the angular grid
// φ_b = (b + 1/2)·Δθ; element (disc i, flute k) at sample j is at b = j + k·Nθ/N − i − 1.
struct Grid {
  int steps = 0;
  int discs = 0;
  double dz = 0;
  double dtheta = 0;
  std::vector<int> bin_of;    // grid index -> unknown index or -1
  std::vector<int> unknown_bin;  // unknown index -> grid index
  Eigen::MatrixXd a;          // steps x unknowns: how many elements sit at each position
};

Grid make_grid(const EndMill& tool, const CalibrationCut& cut) {
  Grid g;
  g.steps = cut.steps_per_rev;
  g.dtheta = kTwoPi / g.steps;
  g.discs = calibration_discs(tool, cut.engagement, g.steps);
  g.dz = cut.engagement.axial_depth_mm / g.discs;
  g.bin_of.assign(static_cast<size_t>(g.steps), -1);
  for (int b = 0; b < g.steps; ++b) {
    const double phi = (b + 0.5) * g.dtheta;
    if (phi >= cut.engagement.phi_start && phi <= cut.engagement.phi_exit && std::sin(phi) > 0.0) {
      g.bin_of[static_cast<size_t>(b)] = static_cast<int>(g.unknown_bin.size());
      g.unknown_bin.push_back(b);
    }
  }
  g.a = Eigen::MatrixXd::Zero(g.steps, static_cast<Eigen::Index>(g.unknown_bin.size()));
  const int per_flute = g.steps / tool.flutes;
  for (int j = 0; j < g.steps; ++j) {
    for (int k = 0; k < tool.flutes; ++k) {
      for (int i = 0; i < g.discs; ++i) {
        int b = (j + k * per_flute - i - 1) % g.steps;
        if (b < 0) b += g.steps;
        const int u = g.bin_of[static_cast<size_t>(b)];
        if (u >= 0) g.a(j, u) += 1.0;
      }
    }
  }
  return g;
}

// The measured history averaged per angle of the revolution.
Eigen::MatrixXd average_per_angle(const CalibrationCut& cut) {
  Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(cut.steps_per_rev, 2);
  std::vector<int> count(static_cast<size_t>(cut.steps_per_rev), 0);
  for (size_t s = 0; s < cut.fxy.size(); ++s) {
    const auto j = static_cast<Eigen::Index>(s % static_cast<size_t>(cut.steps_per_rev));
    sum.row(j) += cut.fxy[s].transpose();
    count[static_cast<size_t>(j)]++;
  }
  for (Eigen::Index j = 0; j < sum.rows(); ++j) {
    if (count[static_cast<size_t>(j)] > 0) sum.row(j) /= count[static_cast<size_t>(j)];
  }
  return sum;
}
}  // namespace

int calibration_discs(const EndMill& tool, const Engagement& e, int steps_per_rev) {
  const double tan_h = std::tan(tool.helix_deg * kPi / 180.0);
  if (!(tan_h > 0.0) || steps_per_rev < 1) return 1;
  const double dz = tool.radius() * (kTwoPi / steps_per_rev) / tan_h;  // eq. 11
  return std::max(1, static_cast<int>(std::lround(e.axial_depth_mm / dz)));
}

CalibrationCut synthetic_cut(const EndMill& tool, const Material& mat, ForceModel model, const Engagement& e,
                             int steps_per_rev, int revolutions, double noise_n, unsigned seed) {
  CalibrationCut cut;
  cut.engagement = e;
  cut.steps_per_rev = steps_per_rev;
  const CuttingForceModel m(tool, mat, model, calibration_discs(tool, e, steps_per_rev));
  const ForceHistory rev = m.simulate_revolution(e, steps_per_rev);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_n);
  for (int r = 0; r < revolutions; ++r) {
    for (const Eigen::Vector3d& f : rev.force) cut.fxy.emplace_back(f.x() + noise(rng), f.y() + noise(rng));
  }
  return cut;
}

CalibrationResult calibrate(const EndMill& tool, const std::vector<CalibrationCut>& cuts, double min_sin) {
  CalibrationResult res;
  if (cuts.empty()) {
    res.error = "no cuts";
    return res;
  }
  double sq = 0;
  size_t nsq = 0;
  std::vector<double> lh, lkt, wkt, lkr, wkr, hs, ft, fr, ones;
  for (size_t c = 0; c < cuts.size(); ++c) {
    const CalibrationCut& cut = cuts[c];
    if (cut.steps_per_rev < tool.flutes || cut.steps_per_rev % tool.flutes != 0) {
      res.error = "cut " + std::to_string(c) + ": steps_per_rev must be a multiple of the flute count";
      return res;
    }
    if (cut.fxy.size() < static_cast<size_t>(cut.steps_per_rev)) {
      res.error = "cut " + std::to_string(c) + ": the history is shorter than one revolution";
      return res;
    }
    const Grid g = make_grid(tool, cut);
    if (g.unknown_bin.empty()) {
      res.error = "cut " + std::to_string(c) + ": no angular position is engaged";
      return res;
    }
    const Eigen::MatrixXd f = average_per_angle(cut);
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(g.a);
    if (qr.rank() < g.a.cols()) {
      res.error = "cut " + std::to_string(c) + ": the elemental forces are not identifiable (rank " +
                  std::to_string(qr.rank()) + " of " + std::to_string(g.a.cols()) +
                  "): flutes share the engaged arc; use a smaller radial depth";
      return res;
    }
    const Eigen::MatrixXd d = qr.solve(f);  // eq. 8: unknowns x 2 (dFx_n, dFy_n)
    const Eigen::MatrixXd r = g.a * d - f;
    sq += r.squaredNorm();
    nsq += static_cast<size_t>(r.size());
    const double feed = cut.engagement.feed_per_tooth_mm;
    for (Eigen::Index u = 0; u < d.rows(); ++u) {
      const double phi = (g.unknown_bin[static_cast<size_t>(u)] + 0.5) * g.dtheta;
      const double s = std::sin(phi);
      const double co = std::cos(phi);
      const double dfx = d(u, 0);
      const double dfy = d(u, 1);
      const double dft = -dfx * co + dfy * s;  // eq. 9 inverted
      const double dfr = -dfx * s - dfy * co;
      const double h = feed * s;
      CoefficientSample smp{h, dft / (g.dz * h), dfr / dft, dft / g.dz, dfr / g.dz};  // eq. 10
      res.samples.push_back(smp);
      if (s < min_sin) continue;
      hs.push_back(h);
      ft.push_back(smp.ft_per_mm);
      fr.push_back(smp.fr_per_mm);
      ones.push_back(1.0);
      if (smp.kt > 0 && smp.kr > 0) {
        lh.push_back(std::log(h));
        lkt.push_back(std::log(smp.kt));
        lkr.push_back(std::log(smp.kr));
        // var(ln K) ≈ var(dF)/dF²: weight by the force squared.
        wkt.push_back(dft * dft);
        wkr.push_back(1.0 / (1.0 / (dfr * dfr) + 1.0 / (dft * dft)));
      }
    }
  }
  res.residual_rms_n = nsq ? std::sqrt(sq / static_cast<double>(nsq)) : 0.0;
  if (lh.size() < 2 || hs.size() < 2) {
    res.error = "fewer than two usable angular positions (sin β >= min_sin)";
    return res;
  }
  const Fit2 kt = fit_line(lh, lkt, wkt);
  const Fit2 kr = fit_line(lh, lkr, wkr);
  res.chip_law.kt = {CoefficientLaw::Form::kPower, std::exp(kt.a), kt.b};
  res.chip_law.kr = {CoefficientLaw::Form::kPower, std::exp(kr.a), kr.b};
  const Fit2 lt = fit_line(hs, ft, ones);
  const Fit2 lr = fit_line(hs, fr, ones);
  res.linear.ktc = lt.b;
  res.linear.kte = lt.a;
  res.linear.krc = lr.b;
  res.linear.kre = lr.a;
  return res;
}

}  // namespace cnc::process
