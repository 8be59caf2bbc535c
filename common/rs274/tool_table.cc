#include "common/rs274/tool_table.h"

#include <cstdio>

#include "common/rs274/parameters.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>

namespace cnc::rs274 {

namespace {

int axis_index(char c) {
  static const char kAxes[] = "XYZABCUVW";
  for (int i = 0; i < kNumAxes; ++i)
    if (kAxes[i] == c) return i;
  return -1;
}

}  // namespace

void ToolTable::read(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path, SourceRef{0, 0, 0}, "cannot open the tool table");
  tools_.clear();
  std::string text;
  int32_t line_no = 0;
  while (std::getline(in, text)) {
    ++line_no;
    auto fail = [&](size_t col, const std::string& what) {
      throw Error(path, SourceRef{0, line_no, static_cast<int32_t>(col + 1)}, what);
    };
    Tool t;
    bool has_t = false;
    size_t i = 0;
    while (i < text.size()) {
      const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(text[i])));
      if (c == ';') {
        t.comment = text.substr(i + 1);
        break;
      }
      if (std::isspace(static_cast<unsigned char>(c))) {
        ++i;
        continue;
      }
      const size_t at = i;
      ++i;
      const char* start = text.c_str() + i;
      char* stop = nullptr;
      const double v = std::strtod(start, &stop);
      if (stop == start || !std::isfinite(v)) fail(at, std::string("expected a number after '") + c + "'");
      i += static_cast<size_t>(stop - start);
      const int ax = axis_index(c);
      if (c == 'T') {
        t.number = static_cast<int>(std::lround(v));
        has_t = true;
      } else if (c == 'P') {
        t.pocket = static_cast<int>(std::lround(v));
      } else if (ax >= 0) {
        t.offset[static_cast<size_t>(ax)] = v;
      } else if (c == 'D') {
        t.diameter = v;
      } else if (c == 'I') {
        t.front_angle = v;
      } else if (c == 'J') {
        t.back_angle = v;
      } else if (c == 'Q') {
        t.orientation = static_cast<int>(std::lround(v));
      } else {
        fail(at, std::string("unknown tool table word '") + c + "'");
      }
    }
    if (!has_t) continue;  // blank or comment line
    if (t.number < 0) fail(0, "negative tool number");
    put(t);
  }
}

const Tool* ToolTable::find(int number) const {
  for (const Tool& t : tools_)
    if (t.number == number) return &t;
  return nullptr;
}

Tool* ToolTable::find(int number) {
  for (Tool& t : tools_)
    if (t.number == number) return &t;
  return nullptr;
}

void ToolTable::put(const Tool& t) {
  if (Tool* old = find(t.number)) {
    *old = t;
    return;
  }
  tools_.push_back(t);
}

void write_tool_table(const std::string& path, const std::vector<Tool>& tools) {
  static const char kAxes[] = "XYZABCUVW";
  std::string data;
  // Room for the longest line part: " I%+.6f J%+.6f Q%d" of two doubles near 1e308 (309
  // digits each). 64 bytes cut a diameter of 3.3e101 to 60 characters, silently: the
  // table read back held another number (fuzz_tables).
  char buf[800];
  for (const Tool& t : tools) {
    std::snprintf(buf, sizeof buf, "T%d P%d", t.number, t.pocket);
    data += buf;
    for (int i = 0; i < kNumAxes; ++i) {
      const double v = t.offset[static_cast<size_t>(i)];
      if (v == 0) continue;
      std::snprintf(buf, sizeof buf, " %c%+.6f", kAxes[i], v);
      data += buf;
    }
    std::snprintf(buf, sizeof buf, " D%+.6f", t.diameter);
    data += buf;
    if (t.front_angle != 0 || t.back_angle != 0 || t.orientation != 0) {
      std::snprintf(buf, sizeof buf, " I%+.6f J%+.6f Q%d", t.front_angle, t.back_angle, t.orientation);
      data += buf;
    }
    if (!t.comment.empty()) {
      data.append(" ;");
      data.append(t.comment);
    }
    data += '\n';
  }
  write_file_atomically(path, data);
}

}  // namespace cnc::rs274
