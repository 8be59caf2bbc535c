#include "common/rs274/modal_text.h"

#include <cstdio>

namespace cnc::rs274 {

namespace {

// A G or M code kept in tenths (10 = G1, 591 = G59.1).
std::string code(char letter, int tenths) {
  char buf[16];
  if (tenths % 10 == 0)
    std::snprintf(buf, sizeof buf, "%c%d", letter, tenths / 10);
  else
    std::snprintf(buf, sizeof buf, "%c%d.%d", letter, tenths / 10, tenths % 10);
  return buf;
}

}  // namespace

std::string active_codes(const ModalState& s) {
  std::string out;
  out.reserve(128);
  auto add = [&](const std::string& c) {
    if (!out.empty()) out.push_back(' ');
    out.append(c);
  };
  if (s.motion >= 0) add(code('G', s.motion));
  static const char* const kPlanes[] = {"G17", "G19", "G18", "G17.1", "G19.1", "G18.1"};
  add(s.plane >= 0 && s.plane < 6 ? kPlanes[s.plane] : "G17");
  add(s.units == static_cast<int>(Units::kInch) ? "G20" : "G21");
  add(code('G', s.comp));
  add(code('G', s.tool_length));
  static const char* const kCoords[] = {"G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"};
  add(s.coord >= 1 && s.coord <= 9 ? kCoords[s.coord - 1] : "G54");
  static const char* const kPaths[] = {"G61", "G61.1", "G64"};
  add(s.path >= 0 && s.path < 3 ? kPaths[s.path] : "G64");
  add(s.incremental ? "G91" : "G90");
  add(s.arc_incremental ? "G91.1" : "G90.1");
  static const char* const kFeeds[] = {"G94", "G93", "G95"};
  add(s.feed_mode >= 0 && s.feed_mode < 3 ? kFeeds[s.feed_mode] : "G94");
  add(s.retract_r ? "G99" : "G98");
  if (s.g92_active) add("G92");
  add(s.spindle > 0 ? "M3" : s.spindle < 0 ? "M4" : "M5");
  if (s.mist) add("M7");
  if (s.flood) add("M8");
  if (!s.mist && !s.flood) add("M9");
  add(s.feed_override && s.speed_override ? "M48" : "M49");
  char tool[24];
  std::snprintf(tool, sizeof tool, "T%d", s.tool);
  add(tool);
  return out;
}

Pose work_offset(const ModalState& s) {
  Pose off{};
  // #5201 + 20 n + axis: system n's offsets (5221.. for G54); offsets[] starts at #5161.
  const int coord = s.coord >= 1 && s.coord <= 9 ? s.coord : 1;
  for (size_t a = 0; a < off.size(); ++a) {
    off[a] = s.offsets[static_cast<size_t>(5201 + 20 * coord - 5161) + a] + s.tool_offset[a];
    if (s.g92_active) off[a] += s.g92[a];
  }
  return off;
}

}  // namespace cnc::rs274
