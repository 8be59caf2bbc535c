#include "common/cam/points_csv.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string_view>

namespace cnc::cam {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

double parse_field(std::string_view s, const std::string& where) {
  const char* b = s.data();
  const char* e = b + s.size();
  if (b < e && *b == '+') ++b;
  double v = 0;
  const auto r = std::from_chars(b, e, v);
  if (s.empty() || r.ec != std::errc() || r.ptr != e || !std::isfinite(v))
    throw std::runtime_error(where + ": '" + std::string(s) + "' is not a finite number");
  return v;
}

}  // namespace

PointsCsv parse_points_csv(const std::string& text, const std::string& name) {
  PointsCsv out;
  std::size_t line_no = 0;
  bool header = false;
  for (std::size_t b = 0; b < text.size();) {
    std::size_t e = text.find('\n', b);
    if (e == std::string::npos) e = text.size();
    const std::string_view line = trim(std::string_view(text).substr(b, e - b));
    b = e + 1;
    ++line_no;
    if (line.empty()) continue;
    const std::string where = name + ":" + std::to_string(line_no);
    const std::size_t comma = line.find(',');
    if (comma == std::string_view::npos || line.find(',', comma + 1) != std::string_view::npos)
      throw std::runtime_error(where + ": expected two fields 'x,y', found '" + std::string(line) + "'");
    const std::string_view xs = trim(line.substr(0, comma)), ys = trim(line.substr(comma + 1));
    if (!header) {
      if (xs != "x" || ys != "y") throw std::runtime_error(where + ": expected the header 'x,y'");
      header = true;
      continue;
    }
    out.points.push_back({parse_field(xs, where), parse_field(ys, where)});
    out.x_text.emplace_back(xs);
    out.y_text.emplace_back(ys);
  }
  if (!header) throw std::runtime_error(name + ": empty, expected the header 'x,y'");
  return out;
}

PointsCsv read_points_csv(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
  std::ostringstream s;
  s << f.rdbuf();
  return parse_points_csv(s.str(), path);
}

void write_xyz_csv(const std::string& path, const PointsCsv& in, const std::vector<ClPoint>& out) {
  if (out.size() != in.points.size()) throw std::invalid_argument("write_xyz_csv: sizes differ");
  std::string text = "x,y,z\n";
  text.reserve(in.points.size() * 40 + 8);
  char buf[32];
  for (std::size_t i = 0; i < out.size(); ++i) {
    text += in.x_text[i];
    text += ',';
    text += in.y_text[i];
    text += ',';
    if (out[i].touched()) {
      const auto r = std::to_chars(buf, buf + sizeof buf, out[i].z);
      text.append(buf, r.ptr);
    }
    text += '\n';
  }
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) throw std::runtime_error(path + ": cannot create: " + std::strerror(errno));
  if (std::fwrite(text.data(), 1, text.size(), f.get()) != text.size() || std::fflush(f.get()) != 0)
    throw std::runtime_error(path + ": write error");
}

}  // namespace cnc::cam
