// The parameters as a program reads and sets them: the predefined named ones that
// show the modal state, and the settings of a line.
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

// ---- parameters ---------------------------------------------------------------------

double Interpreter::named_value(const std::string& name, int column) const {
  double v = 0;
  if (!name.empty() && name[0] == '_') {
    const Pose cur = current_point();
    const Pose shown = twp_ ? frame_of(cur) : cur;  // G68.2: the program's own frame
    const auto axis = [&](int i) { return to_program_axis(i, shown[static_cast<size_t>(i)]); };
    static const char* kPos[] = {"_x", "_y", "_z", "_a", "_b", "_c", "_u", "_v", "_w"};
    for (int i = 0; i < kNumAxes; ++i)
      if (name == kPos[i]) return axis(i);
    static const char* kAbs[] = {"_abs_x", "_abs_y", "_abs_z", "_abs_a", "_abs_b", "_abs_c", "_abs_u", "_abs_v", "_abs_w"};
    for (int i = 0; i < kNumAxes; ++i)
      if (name == kAbs[i]) {
        const size_t k = static_cast<size_t>(i);
        return to_program_axis(i, machine_of(cur, coord_)[k]);
      }
    if (name == "_line") return line_no_;
    if (name == "_motion_mode") return motion_ < 0 ? 800 : motion_;
    if (name == "_plane") return plane_ == Plane::kXY ? 170 : plane_ == Plane::kXZ ? 180 : 190;
    if (name == "_ccomp") return comp_;
    if (name == "_metric") return units_ == Units::kMm;
    if (name == "_imperial") return units_ == Units::kInch;
    if (name == "_absolute") return !incremental_;
    if (name == "_incremental") return incremental_;
    if (name == "_inverse_time") return feed_mode_ == FeedMode::kInverseTime;
    if (name == "_units_per_minute") return feed_mode_ == FeedMode::kUnitsPerMinute;
    if (name == "_units_per_rev") return feed_mode_ == FeedMode::kUnitsPerRev;
    if (name == "_coord_system") {
      static const int kCs[] = {540, 550, 560, 570, 580, 590, 591, 592, 593};
      return kCs[coord_ - 1];
    }
    if (name == "_tool_offset") return tool_length_ != 490;
    if (name == "_retract_r_plane") return retract_r_;
    if (name == "_retract_old_z") return !retract_r_;
    if (name == "_spindle_rpm_mode") return 1;
    if (name == "_spindle_css_mode") return 0;
    if (name == "_ijk_absolute_mode") return !arc_incremental_;
    if (name == "_lathe_diameter_mode") return lathe_diameter_;
    if (name == "_lathe_radius_mode") return !lathe_diameter_;
    if (name == "_spindle_on") return spindle_ != 0;
    if (name == "_spindle_cw") return spindle_ == 1;
    if (name == "_mist") return mist_;
    if (name == "_flood") return flood_;
    if (name == "_speed_override") return speed_override_;
    if (name == "_feed_override") return feed_override_;
    if (name == "_adaptive_feed") return adaptive_feed_;
    if (name == "_feed_hold") return feed_hold_;
    if (name == "_feed") return feed_;
    if (name == "_rpm") return speed_;
    if (name == "_current_tool") return tool_;
    if (name == "_current_pocket") return tool_;
    if (name == "_selected_tool") return selected_tool_;
    if (name == "_selected_pocket") return selected_tool_;
    if (name == "_value") return last_returned_;
    if (name == "_call_level") return static_cast<double>(frames_.size());
    if (name == "_remap_level") return 0;
    if (name == "_task") return 0;  // not milltask: the standalone interpreter
    if (name == "_vmajor") return 2.9;
    if (name == "_vminor") return 0;
  }
  if (params_.find_named(name, &v)) return v;
  (void)column;
  return params_.get_named(name, column);  // throws "not defined"
}

bool Interpreter::named_exists(const std::string& name) const {
  double v = 0;
  if (params_.find_named(name, &v)) return true;
  try {
    (void)named_value(name, 0);
    return true;
  } catch (const Error&) {
    return false;
  }
}

void Interpreter::apply_settings() {
  for (const ParamSetting& s : line_.settings) {
    double v = 0;
    try {
      v = evaluate(line_.arena, s.value_expr, *reader_);
      if (s.index_expr >= 0) {
        const double idx = evaluate(line_.arena, s.index_expr, *reader_);
        params_.set(Parameters::index_of(idx, s.column), v, s.column);
      } else {
        if (!s.name.empty() && s.name[0] == '_') {
          // Predefined names are read-only.
          static const char* kRo[] = {"_x", "_y", "_z", "_a", "_b", "_c", "_u", "_v", "_w", "_line", "_motion_mode",
                                      "_current_tool", "_feed", "_rpm", "_value", "_call_level", "_vmajor", "_vminor"};
          for (const char* r : kRo)
            if (s.name == r) fail(s.column, "#<" + s.name + "> is a read-only predefined parameter");
        }
        params_.set_named(s.name, v);
      }
    } catch (const Error& e) {
      if (!e.file_name().empty()) throw;
      fail(e.column() > 0 ? e.column() : s.column, e.detail());
    }
  }
}

}  // namespace cnc::rs274
