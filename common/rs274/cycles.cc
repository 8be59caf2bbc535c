// Canned cycles as LinuxCNC 2.9's interpreter runs them; the behaviour (order of the
// checks, the moves of each repeat, the calls around them) was measured on rs274
// 2.9.0~pre1 (see tests/unit/rs274_cycles_test.cc).
#include "common/rs274/cycles.h"

#include <cmath>
#include <string>

namespace cnc::rs274 {
namespace {
// Moves one cycle block may make (repeats × pecks): beyond it the block is refused.
constexpr int kMaxCycleMoves = 100'000;

// Axis indices into a Pose of the plane's first axis, second axis and depth axis.
struct Axes {
  int a, b, c;
};

Axes axes_of(Plane plane) {
  switch (plane) {
    case Plane::kXY: return {0, 1, 2};
    case Plane::kYZ: return {1, 2, 0};
    case Plane::kXZ: return {2, 0, 1};
    case Plane::kUV: return {6, 7, 8};
    case Plane::kVW: return {7, 8, 6};
    case Plane::kUW: return {8, 6, 7};
  }
  return {0, 1, 2};
}

bool uvw_plane(Plane plane) { return plane == Plane::kUV || plane == Plane::kVW || plane == Plane::kUW; }

// LinuxCNC's spelling: lower case for the XYZ planes, upper case for the UVW ones.
const char* plane_text(Plane plane) {
  switch (plane) {
    case Plane::kXY: return "xy";
    case Plane::kYZ: return "yz";
    case Plane::kXZ: return "xz";
    case Plane::kUV: return "UV";
    case Plane::kVW: return "VW";
    case Plane::kUW: return "UW";
  }
  return "xy";
}

char axis_letter(int index, bool upper) {
  static const char kLetters[] = "XYZABCUVW";
  const char c = kLetters[index];
  return upper ? c : static_cast<char>(c - 'A' + 'a');
}

// "G84" / "g84" (LinuxCNC writes both). Appended, not "G" + string: GCC 12 warns
// falsely (-Wrestrict) on a literal plus a temporary string.
std::string gcode_text(int g, char letter = 'G') {
  std::string s(1, letter);
  s.append(std::to_string(g / 10));
  return s;
}

[[noreturn]] void refuse(const std::string& message) { throw Error(0, message); }

class Runner {
 public:
  Runner(const CycleInput& in, const SourceRef& ref, Canon& canon)
      : in_(in), ref_(ref), canon_(canon), ax_(axes_of(in.plane)) {}

  CycleResult run();

 private:
  // A move of the plane point (a, b) and depth c, the other axes where they stand.
  Pose at(double a, double b, double c) const {
    Pose p = in_.start;
    p[static_cast<size_t>(ax_.a)] = a;
    p[static_cast<size_t>(ax_.b)] = b;
    p[static_cast<size_t>(ax_.c)] = c;
    return p;
  }
  void traverse(double a, double b, double c) { canon_.straight_traverse(ref_, at(a, b, c)); }
  void feed(double a, double b, double c) { canon_.straight_feed(ref_, at(a, b, c)); }
  void start_spindle(bool cw) {
    if (cw)
      canon_.start_spindle_clockwise(ref_);
    else
      canon_.start_spindle_counterclockwise(ref_);
  }
  void require_turning() const {
    if (!in_.spindle_turning) refuse("Spindle not turning in " + gcode_text(in_.g, 'g'));
  }

  void peck(double a, double b, double r, double clear, double bottom, double delta, bool full_retract);
  void tap(double a, double b, double clear, double bottom);
  void back_bore(double a, double b, double r, double clear, double bottom);
  void check_input() const;
  void require_words() const;
  void hole(double a, double b, double r, double clear, double bottom);

  const CycleInput& in_;
  const SourceRef& ref_;
  Canon& canon_;
  Axes ax_;
  double p_ = 0, q_ = 0, i_ = 0, j_ = 0, k_ = 0;
};

// G73 (full_retract false: a rapid back by the peck clearance after each peck) and
// G83 (full_retract true: a rapid out to R, then back down to the clearance above
// the last peck). LinuxCNC 2.9's clearance is 0.010 in, or 0.254 mm.
void Runner::peck(double a, double b, double r, double clear, double bottom, double delta, bool full_retract) {
  if (delta <= 0.0) refuse("Negative or zero q value used");
  // Pecks of every repeat: a Q far below the depth made billions of moves in one
  // block (or, below the depth's rounding step, a loop that never ended).
  const double pecks = std::ceil((r - bottom) / delta) * static_cast<double>(in_.repeats);
  if (!(pecks <= static_cast<double>(kMaxCycleMoves)))
    refuse(gcode_text(in_.g) + " with Q" + std::to_string(delta) + " from R" + std::to_string(r) + " to " +
           std::to_string(bottom) + " (L" + std::to_string(in_.repeats) + "): more than " +
           std::to_string(kMaxCycleMoves) + " pecks in one block");
  const double clearance = in_.units == Units::kMm ? 0.010 * 25.4 : 0.010;
  for (double depth = r - delta; depth > bottom; depth = depth - delta) {
    feed(a, b, depth);
    if (full_retract) traverse(a, b, r);
    traverse(a, b, depth + clearance);
  }
  feed(a, b, bottom);
  traverse(a, b, clear);
}

// G84 (right hand) and G74 (left hand): overrides off, feed in, reverse the spindle,
// dwell P, feed out to the clearance level, spindle back to its direction, the
// overrides that were on back on.
void Runner::tap(double a, double b, double clear, double bottom) {
  const bool g84 = in_.g == 840;
  if (!in_.spindle_turning) refuse("Spindle not turning in " + gcode_text(in_.g));
  if (in_.spindle_cw && !g84) refuse("Spindle turning clockwise in G74");
  if (!in_.spindle_cw && g84) refuse("Spindle turning counterclockwise in G84");
  if (uvw_plane(in_.plane))
    refuse(gcode_text(in_.g) + " for plane " + plane_text(in_.plane) + " not implemented");
  // LinuxCNC 2.9 passes the coordinates of these two feeds in the wrong order in
  // G18 and G19 (the tap would move sideways); here they are the plane's analogue
  // of the G17 moves, as LinuxCNC documents the cycle.
  canon_.enable_feed_override(ref_, false);
  canon_.enable_speed_override(ref_, false);
  feed(a, b, bottom);
  canon_.stop_spindle_turning(ref_);
  start_spindle(!g84);
  canon_.dwell(ref_, p_);
  feed(a, b, clear);
  canon_.stop_spindle_turning(ref_);
  start_spindle(g84);
  if (in_.feed_override_enabled) canon_.enable_feed_override(ref_, true);
  if (in_.speed_override_enabled) canon_.enable_speed_override(ref_, true);
}

// G87: to the offset point (I J from the hole) at R, spindle stopped and oriented,
// rapid down beside the hole to the bottom, over to the hole, spindle on, feed up to
// the K level and back down, stop and orient, out the same way, restart.
void Runner::back_bore(double a, double b, double r, double clear, double bottom) {
  require_turning();
  const int direction = in_.spindle_cw ? 2 : 3;
  const double oa = a + i_, ob = b + j_;
  traverse(oa, ob, r);
  canon_.stop_spindle_turning(ref_);
  canon_.orient_spindle(ref_, 0.0, direction);
  traverse(oa, ob, bottom);
  traverse(a, b, bottom);
  start_spindle(in_.spindle_cw);
  feed(a, b, k_);
  feed(a, b, bottom);
  canon_.stop_spindle_turning(ref_);
  canon_.orient_spindle(ref_, 0.0, direction);
  traverse(oa, ob, bottom);
  traverse(oa, ob, clear);
  traverse(a, b, clear);
  start_spindle(in_.spindle_cw);
}

// The refusals that need no position: an unknown cycle, then LinuxCNC's convert_cycle.
void Runner::check_input() const {
  const int g = in_.g;
  const bool known = g == 730 || g == 740 || (g >= 810 && g <= 890 && g % 10 == 0);
  if (!known) {
    std::string s = gcode_text(g);
    if (g % 10 != 0) s.append(".").append(std::to_string(g % 10));
    refuse(s + " is not a canned cycle");
  }

  // LinuxCNC's convert_cycle.
  if (in_.feed_rate == 0.0) refuse("Cannot feed with zero feed rate");
  if (in_.inverse_time) refuse("Cannot use inverse time feed with canned cycles");
  if (in_.cutter_comp) refuse("Cannot use canned cycles with cutter compensation on");
  if (!in_.has_r && !in_.continuing) refuse("R clearance plane unspecified in cycle");
  if (in_.repeats < 0) refuse("Negative l word used");
  if (in_.repeats == 0) refuse("Cannot do zero repeats of cycle");
  // Not LinuxCNC's: one cycle block makes all its moves at once (into the block
  // builder's queue), so their number is bounded (L here, the pecks in peck()).
  if (in_.repeats > kMaxCycleMoves)
    refuse("L" + std::to_string(in_.repeats) + " repeats of " + gcode_text(in_.g) + ": more than " +
           std::to_string(kMaxCycleMoves) + " in one block");
}

// The words each cycle needs (after the mode switch, as in LinuxCNC).
void Runner::require_words() const {
  const int g = in_.g;
  const std::string gname = gcode_text(g, 'g');
  switch (g) {
    case 820: case 860: case 880: case 890:
      if (!in_.continuing && !in_.has_p) refuse("Dwell time p word missing with " + gname);
      break;
    case 730: case 830:
      if (!in_.continuing && !in_.has_q) refuse("Q word missing with " + gname);
      break;
    case 870:
      if (!in_.continuing) {
        // LinuxCNC checks I, then J, then K; i/j/k here are in plane order.
        const bool has_word[3] = {
            ax_.a % 3 == 0 ? in_.has_i : ax_.b % 3 == 0 ? in_.has_j : in_.has_k,
            ax_.a % 3 == 1 ? in_.has_i : ax_.b % 3 == 1 ? in_.has_j : in_.has_k,
            ax_.a % 3 == 2 ? in_.has_i : ax_.b % 3 == 2 ? in_.has_j : in_.has_k,
        };
        if (!has_word[0]) refuse("I word missing with g87");
        if (!has_word[1]) refuse("J word missing with g87");
        if (!has_word[2]) refuse("K word missing with g87");
      }
      break;
    default: break;
  }
}

// One repeat's moves at the hole (a, b), from the clearance level down and back.
void Runner::hole(double a, double b, double r, double clear, double bottom) {
  switch (in_.g) {
    case 810:
      feed(a, b, bottom);
      traverse(a, b, clear);
      break;
    case 820:
      feed(a, b, bottom);
      canon_.dwell(ref_, p_);
      traverse(a, b, clear);
      break;
    case 730:
      peck(a, b, r, clear, bottom, q_, false);
      break;
    case 830:
      peck(a, b, r, clear, bottom, q_, true);
      break;
    case 740: case 840:
      tap(a, b, clear, bottom);
      break;
    case 850:
      feed(a, b, bottom);
      feed(a, b, r);
      traverse(a, b, clear);
      break;
    case 860:
      require_turning();
      feed(a, b, bottom);
      canon_.dwell(ref_, p_);
      canon_.stop_spindle_turning(ref_);
      traverse(a, b, clear);
      start_spindle(in_.spindle_cw);
      break;
    case 870:
      back_bore(a, b, r, clear, bottom);
      break;
    case 880:
      // The operator takes the tool out by hand at the program stop.
      require_turning();
      feed(a, b, bottom);
      canon_.dwell(ref_, p_);
      canon_.stop_spindle_turning(ref_);
      canon_.program_stop(ref_);
      start_spindle(in_.spindle_cw);
      break;
    case 890:
      feed(a, b, bottom);
      canon_.dwell(ref_, p_);
      feed(a, b, clear);
      break;
    default: break;
  }
}

CycleResult Runner::run() {
  check_input();

  // LinuxCNC's convert_cycle_xy (yz, zx, uv, vw, wu).
  // LinuxCNC's letters: "Z value unspecified in xy plane ...", "R less than z in ... xy".
  const bool upper = uvw_plane(in_.plane);
  if (!in_.has_z && !in_.continuing)
    refuse(std::string(1, axis_letter(ax_.c, true)) + " value unspecified in " + plane_text(in_.plane) +
           " plane canned cycle");
  const double current_a = in_.start[static_cast<size_t>(ax_.a)];
  const double current_b = in_.start[static_cast<size_t>(ax_.b)];
  double current_c = in_.start[static_cast<size_t>(ax_.c)];
  double old_c = in_.old_z;

  double a = 0, b = 0, r = 0, bottom = 0, inc_a = 0, inc_b = 0;
  if (!in_.incremental) {
    r = in_.r;
    bottom = in_.z;
    a = in_.has_x ? in_.x : current_a;
    b = in_.has_y ? in_.y : current_b;
  } else {
    if (in_.has_x) inc_a = in_.x;
    if (in_.has_y) inc_b = in_.y;
    r = in_.r + old_c;
    bottom = r + in_.z;
    a = current_a;
    b = current_b;
  }
  if (r < bottom)
    refuse(std::string("R less than ") + axis_letter(ax_.c, upper) + " in cycle in " + plane_text(in_.plane) +
           " plane");

  // Below the R level: straight up to it first (where the tool stands).
  if (old_c < r) {
    Pose up = in_.start;
    up[static_cast<size_t>(ax_.c)] = r;
    canon_.straight_traverse(ref_, up);
    old_c = r;
    current_c = r;
  }
  const double clear = in_.retract_to_r ? r : old_c;

  if (in_.path_mode != PathMode::kExactPath) canon_.set_motion_control_mode(ref_, PathMode::kExactPath, 0);

  require_words();
  p_ = in_.p;
  q_ = in_.q;
  i_ = in_.i;
  j_ = in_.j;
  k_ = in_.incremental ? bottom + in_.k : in_.k;  // G87's level: relative to the bottom in G91

  for (int repeat = in_.repeats; repeat > 0; --repeat) {
    if (in_.next_hole) {
      in_.next_hole(&a, &b);
    } else {
      a += inc_a;
      b += inc_b;
    }
    // The tolerance absorbs the interpreter's mm round trip of an inch position
    // (0.1051 in -> mm -> in), which LinuxCNC, keeping program units, never makes.
    if (repeat == in_.repeats && current_c > r + 1e-9 * std::max(1.0, std::fabs(r))) {
      traverse(a, b, current_c);
      traverse(a, b, r);
    } else {
      traverse(a, b, clear);
      if (clear > r) traverse(a, b, r);
    }
    hole(a, b, r, clear, bottom);
  }

  if (in_.path_mode != PathMode::kExactPath) {
    canon_.set_motion_control_mode(ref_, in_.path_mode, in_.path_tolerance);
    canon_.set_naivecam_tolerance(ref_, in_.naivecam_tolerance);
  }

  CycleResult result;
  result.end = at(a, b, clear);
  result.r_plane = r;
  return result;
}

}  // namespace

CycleResult run_cycle(const CycleInput& in, const SourceRef& ref, Canon& canon) {
  return Runner(in, ref, canon).run();
}

}  // namespace cnc::rs274
