#pragma once
// The look-ahead's reference: every brake check answered again as the plain scan of
// every sample from s_n to the horizon (what Interpolator::safe_scan and the
// gathered checks shortcut), and the answers (and limits missed) that differ counted.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>

#include "common/motion/interpolator.h"

namespace cnc::interp {

class LookaheadReference : public Interpolator::LookaheadCheck {
 public:
  void check(const Interpolator& ip, bool safe, double v_n, double a_n, double s_n, const double* v_target) override {
    double vt = -1;
    const bool r0 = plain(ip, v_n, a_n, s_n, &vt);
    if (r0 != safe ||
        (!safe && v_target != nullptr && std::bit_cast<uint64_t>(vt) != std::bit_cast<uint64_t>(*v_target)))
      ++mismatches;
    ++checks;
  }
  int64_t mismatches = 0;
  int64_t checks = 0;

 private:
  static bool plain(const Interpolator& ip, double v_n, double a_n, double s_n, double* v_target) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    double A = kInf, J = kInf;
    const double T = ip.period_s_;
    double offset = 0;
    double A_h = kInf, J_h = kInf;
    ip.horizon_limits(&A_h, &J_h);
    const double horizon = brake_distance(v_n, a_n, 0.0, A_h, J_h) + v_n * T + 1e-9;
    for (size_t b = 0; b < ip.blocks_.size(); ++b) {
      const Planned& p = ip.blocks_[b];
      const double A_before = b > 0 ? A : p.live_accel, J_before = b > 0 ? J : p.live_jerk;
      A = std::min(A, p.live_accel);
      J = std::min(J, p.live_jerk);
      if (p.stop_block() || (p.live_entry == 0 && offset > 0)) {
        *v_target = 0;
        return brake_distance(v_n, a_n, 0.0, A_before, J_before) + 0.5 * v_n * T <= offset - s_n + 1e-9;
      }
      const bool entry = b > 0 && !p.samples.empty() && offset + p.samples[0].s - s_n >= 0 && ip.own_limit(p, 0);
      for (size_t i = 0; i < p.samples.size(); ++i) {
        const double d = offset + p.samples[i].s - s_n;
        if (d < 0) continue;
        if (d > horizon) return true;
        const double vt = p.v_bw[i];
        if (!ip.own_limit(p, i)) continue;
        if (entry && i > 0 && vt >= p.v_bw[0]) continue;
        if (vt < v_n + a_n * a_n / (2 * J) &&
            Interpolator::brake_misses(v_n, a_n, vt, d, A, J, entry && i == 0, A_before, J_before, T)) {
          *v_target = vt;
          return false;
        }
      }
      offset += p.length;
    }
    return true;
  }
};

}  // namespace cnc::interp
