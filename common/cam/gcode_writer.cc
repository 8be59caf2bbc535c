#include "common/cam/gcode_writer.h"

#include <cmath>
#include <cstdio>

namespace cnc::cam {
namespace {

// 4 decimals, trailing zeros and a lone "-0" dropped.
std::string number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  std::string s(buf);
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  if (s == "-0") s = "0";
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

std::string GcodeWriter::finish() {
  if (known_) rapid({at_.x, at_.y, setup_.safe_z_mm});
  out_ += "M5\nM2\n%\n";
  return std::move(out_);
}

}  // namespace cnc::cam
