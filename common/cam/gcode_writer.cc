#include "common/cam/gcode_writer.h"

#include <cmath>
#include <cstdio>
#include <vector>

#include "common/geometry/polyline_fit.h"

namespace cnc::cam {
namespace {

// 4 decimals, trailing zeros and a lone "-0" dropped.
std::string number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  std::string s(buf);
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  if (s == "-0") return "0";  // (assigned, GCC 12 under -fsanitize=address warned -Wrestrict: a false positive)
  return s;
}

std::string comment_text(std::string s) {
  for (char& c : s)
    if (c == '(' || c == ')' || c == '\n' || c == '\r') c = ' ';
  return s;
}

}  // namespace

GcodeWriter::GcodeWriter(const GcodeSetup& setup) : setup_(setup) {
  const Cutter& c = setup_.cutter;
  const char* kind = c.is_ball() ? "ball" : c.is_flat() ? "flat" : "bull";
  char buf[256];
  out_ += "%\n";
  if (!setup_.title.empty()) {
    out_ += '(';
    out_ += comment_text(setup_.title);
    out_ += ")\n";
  }
  std::snprintf(buf, sizeof buf, "(T%d: %s end mill D%s r%s, flute length %s mm)\n", setup_.tool_number, kind,
                number(c.diameter_mm).c_str(), number(c.corner_radius_mm).c_str(), number(c.flute_length_mm).c_str());
  out_ += buf;
  out_ += "G21 G17 G90 G54\n";
  std::snprintf(buf, sizeof buf, "T%d M6\n", setup_.tool_number);
  out_ += buf;
  out_ += 'S';
  out_ += number(setup_.spindle_rpm);
  out_ += " M3\nG0 Z";
  out_ += number(setup_.safe_z_mm);
  out_ += '\n';
  modal_g_ = 0;
}

void GcodeWriter::move(int g, const Vec3& p, double feed_mm_per_min) {
  std::string line;
  if (g != modal_g_) line += g == 0 ? "G0" : "G1";
  auto axis = [&](char name, double v, double was) {
    const std::string s = number(v);
    if (known_ && s == number(was)) return;
    if (!line.empty()) line += ' ';
    line += name;
    line += s;
  };
  axis('X', p.x, at_.x);
  axis('Y', p.y, at_.y);
  axis('Z', p.z, at_.z);
  if (line.empty() || line == "G0" || line == "G1") return;  // no motion
  if (g == 1 && feed_mm_per_min != modal_f_) {
    line += " F";
    line += number(feed_mm_per_min);
    modal_f_ = feed_mm_per_min;
  }
  if (g == 1 && known_) {
    ++feed_moves_;
    feed_length_ += std::sqrt((p.x - at_.x) * (p.x - at_.x) + (p.y - at_.y) * (p.y - at_.y) + (p.z - at_.z) * (p.z - at_.z));
  }
  modal_g_ = g;
  out_ += line;
  out_ += '\n';
  at_ = p;
  known_ = true;
}

void GcodeWriter::rapid(const Vec3& p) { move(0, p, 0); }
void GcodeWriter::feed(const Vec3& p, double feed_mm_per_min) { move(1, p, feed_mm_per_min); }

void GcodeWriter::cut(const Vec3* points, std::size_t n) {
  if (n == 0) return;
  if (!known_ || at_.z != setup_.safe_z_mm) {
    if (known_) rapid({at_.x, at_.y, setup_.safe_z_mm});
  }
  rapid({points[0].x, points[0].y, setup_.safe_z_mm});
  feed(points[0], setup_.plunge_mm_per_min);
  for (std::size_t i = 1; i < n; ++i) feed(points[i], setup_.feed_mm_per_min);
  rapid({points[n - 1].x, points[n - 1].y, setup_.safe_z_mm});
}

double GcodeWriter::cut_nurbs(const Vec3* points, std::size_t n, double tol_mm, std::vector<Vec3>* samples) {
  if (n < 3) {
    cut(points, n);
    return 0;
  }
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d p(points[i].x, points[i].y, points[i].z);
    if (pts.empty() || (p - pts.back()).norm() > 0) pts.push_back(p);
  }
  const geometry::CubicFit fit = pts.size() >= 3 ? geometry::fit_cubic(pts, tol_mm) : geometry::CubicFit{};
  if (!fit.ok || fit.max_error > tol_mm) {
    cut(points, n);
    return 0;
  }
  if (known_ && at_.z != setup_.safe_z_mm) rapid({at_.x, at_.y, setup_.safe_z_mm});
  rapid({points[0].x, points[0].y, setup_.safe_z_mm});
  feed(points[0], setup_.plunge_mm_per_min);
  char buf[64];
  auto knot = [&](double k) {
    std::snprintf(buf, sizeof buf, "%.9f", k);
    std::string s(buf);
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.pop_back();
    return s;
  };
  for (geometry::CubicPiece pc : geometry::split_cubic(fit.knots, fit.ctrl, 100)) {
    const double k0 = pc.knots.front();
    pc.ctrl.front() = Eigen::Vector3d(at_.x, at_.y, at_.z);
    for (std::size_t i = 0; i < pc.ctrl.size(); ++i) {
      // The first control point is the tool's position as written before, to the digit.
      const Vec3 c = i == 0 ? at_ : Vec3{pc.ctrl[i][0], pc.ctrl[i][1], pc.ctrl[i][2]};
      if (i == 0) {
        out_ += "G6.2 P4 ";
      }
      out_ += 'K' + knot(pc.knots[i] - k0) + " X" + number(c.x) + " Y" + number(c.y) + " Z" + number(c.z) + " R1";
      if (i == 0) out_ += " F" + number(setup_.feed_mm_per_min);
      out_ += '\n';
    }
    for (std::size_t i = pc.ctrl.size(); i < pc.knots.size(); ++i) out_ += 'K' + knot(pc.knots[i] - k0) + '\n';
    // Length by 16 chords a span, on the curve as written (control points to 4 decimals).
    for (Eigen::Vector3d& c : pc.ctrl)
      for (int k = 0; k < 3; ++k) c[k] = std::stod(number(c[k]));
    Eigen::Vector3d prev = geometry::cubic_point(pc.knots, pc.ctrl, pc.knots.front());
    if (samples) samples->push_back({prev[0], prev[1], prev[2]});
    const std::size_t n_samples = 16 * (pc.ctrl.size() - 3);
    for (std::size_t k = 1; k <= n_samples; ++k) {
      const double u = pc.knots.front() + (pc.knots.back() - pc.knots.front()) * static_cast<double>(k) /
                                              static_cast<double>(n_samples);
      const Eigen::Vector3d q = geometry::cubic_point(pc.knots, pc.ctrl, u);
      feed_length_ += (q - prev).norm();
      prev = q;
      if (samples) samples->push_back({q[0], q[1], q[2]});
    }
    ++nurbs_blocks_;
    nurbs_ctrl_ += pc.ctrl.size();
    at_ = {pc.ctrl.back()[0], pc.ctrl.back()[1], pc.ctrl.back()[2]};
    modal_g_ = -1;  // no motion mode after a G6.2 curve
    modal_f_ = setup_.feed_mm_per_min;
  }
  rapid({at_.x, at_.y, setup_.safe_z_mm});
  return fit.max_error;
}

std::string GcodeWriter::finish() {
  if (known_) rapid({at_.x, at_.y, setup_.safe_z_mm});
  out_ += "M5\nM2\n%\n";
  return std::move(out_);
}

}  // namespace cnc::cam
