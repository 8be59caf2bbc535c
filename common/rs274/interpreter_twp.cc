// The tilted work plane (Fanuc's G68.2 feature coordinate system), G53.1 (the tool
// normal to it) and G69. While a frame is active the program's X Y Z, arcs' centres
// and the plane of G17-G19 are the frame's; the interpreter turns them into work
// coordinates, so every canonical call and the block builder see work coordinates as
// ever, and an arc whose plane is tilted becomes the circle it is in space.
#include <stdexcept>

#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

namespace {

using Mat3 = std::array<double, 9>;  // row-major

Mat3 mul(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k)
        c[static_cast<size_t>(3 * i + j)] += a[static_cast<size_t>(3 * i + k)] * b[static_cast<size_t>(3 * k + j)];
  return c;
}

// The right-handed turn by `deg` about axis 1 (X), 2 (Y) or 3 (Z).
Mat3 turn(int axis, double deg) {
  const double t = deg * M_PI / 180.0, c = std::cos(t), s = std::sin(t);
  switch (axis) {
    case 1: return {1, 0, 0, 0, c, -s, 0, s, c};
    case 2: return {c, 0, s, 0, 1, 0, -s, 0, c};
    default: return {c, -s, 0, s, c, 0, 0, 0, 1};
  }
}

// An arc's end off its plane by more than this is a helix.
constexpr double kHelixToleranceMm = 1e-6;
constexpr double kFullCircleRad = 1e-9;

}  // namespace

Pose Interpreter::frame_of(const Pose& work_mm) const {
  Pose f = work_mm;
  const double d[3] = {work_mm[0] - twp_o_[0], work_mm[1] - twp_o_[1], work_mm[2] - twp_o_[2]};
  for (size_t j = 0; j < 3; ++j) f[j] = twp_r_[j] * d[0] + twp_r_[3 + j] * d[1] + twp_r_[6 + j] * d[2];
  return f;
}

Pose Interpreter::work_of(const Pose& frame_mm) const {
  Pose p = frame_mm;
  for (size_t i = 0; i < 3; ++i)
    p[i] = twp_o_[i] + twp_r_[3 * i] * frame_mm[0] + twp_r_[3 * i + 1] * frame_mm[1] + twp_r_[3 * i + 2] * frame_mm[2];
  return p;
}

// G68.2 X Y Z I J K [P Q], G69. P0 (the default): Euler angles I J K turning about the
// axes Q names in turn, each about the frame the turns before made (Q313, Fanuc's
// Z-X-Z, by default; 121 131 212 232 323 the other proper orders). P1: I about X, J
// about Y, K about Z, made in Q's order the same way (Q123 by default; LinuxCNC's
// remap). X Y Z: the frame's origin in the current work coordinates, absolute in G91
// too (0 where omitted).
void Interpreter::g68_2_g69(Words& w) {
  const int col = w.gcol[16];
  if (w.g[16] == 690) {
    twp_ = twp_tool_tilted_ = false;
    return;
  }
  if (twp_) fail(col, "G68.2 while a tilted work plane is active: G69 first");
  if (comp_ != 400) fail(col, "G68.2 with cutter radius compensation on (G40 first)");
  if (rotation_deg_ != 0)
    fail(col, "G68.2 in a coordinate system rotated by G10 L2 R (" + num(rotation_deg_) + " degrees) is not supported");
  if (w.on('R')) fail(w.column('R'), "R word with G68.2 (the frame is turned by I J K only)");
  int p = 0;
  if (w.on('P')) {
    const double v = w['P'];
    p = static_cast<int>(std::lround(v));
    if (std::fabs(v - p) > 1e-4 || p < 0 || p > 4) fail(w.column('P'), "G68.2 P must be 0 to 4");
    if (p >= 2)
      fail(w.column('P'), std::string("G68.2 P") + std::to_string(p) +
                              (p == 2 ? " (three points)" : p == 3 ? " (two vectors)" : " (the tool axis)") +
                              " is not supported: give the frame by Euler angles (P0) or by turns about X Y Z (P1)");
  }
  int q = p == 0 ? 313 : 123;
  if (w.on('Q')) {
    const double v = w['Q'];
    q = static_cast<int>(std::lround(v));
    if (std::fabs(v - q) > 1e-4) q = -1;
  }
  const int d1 = q / 100, d2 = q / 10 % 10, d3 = q % 10;
  const bool digits = q >= 111 && q <= 333 && d1 >= 1 && d1 <= 3 && d2 >= 1 && d2 <= 3 && d3 >= 1 && d3 <= 3;
  const bool proper = digits && d1 == d3 && d1 != d2;                  // Euler: 121 131 212 232 313 323
  const bool tait = digits && d1 != d2 && d2 != d3 && d1 != d3;         // about X Y Z each: 123 132 ...
  if (p == 0 && !proper)
    fail(w.on('Q') ? w.column('Q') : col, "G68.2 Q must name an Euler order (121 131 212 232 313 323)");
  if (p == 1 && !tait)
    fail(w.on('Q') ? w.column('Q') : col, "G68.2 P1 Q must name an order of X Y Z (123 132 213 231 312 321)");
  const double angle[3] = {w.on('I') ? w['I'] : 0, w.on('J') ? w['J'] : 0, w.on('K') ? w['K'] : 0};
  for (const char c : {'I', 'J', 'K'})
    if (w.on(c) && !std::isfinite(w[c])) fail(w.column(c), std::string(1, c) + " of G68.2 is not a finite angle");
  // P0: the first, second and third turns are I, J, K; P1: the turn about axis d is I, J or K by d.
  const double a1 = p == 0 ? angle[0] : angle[d1 - 1];
  const double a2 = p == 0 ? angle[1] : angle[d2 - 1];
  const double a3 = p == 0 ? angle[2] : angle[d3 - 1];
  twp_r_ = mul(mul(turn(d1, a1), turn(d2, a2)), turn(d3, a3));
  const double s = length_scale();
  for (int i = 0; i < 3; ++i) {
    const char c = kAxisLetters[i];
    twp_o_[static_cast<size_t>(i)] = w.on(c) ? w[c] * s : 0.0;
  }
  twp_ = true;
  w.axes &= ~7u;  // the origin's words, not a move
}

// G53.1 [P]: the rotary axes turn (at rapid, alone) so that the tool stands along the
// tilted frame's +Z, through the machine's kinematics. P0 (the default): the solution
// the machine's kinematics.solution picks; P1 the one with the tilt >= 0, P2 <= 0.
void Interpreter::g53_1(const Words& w) {
  const int col = w.gcol[0];
  if (!twp_) fail(col, "G53.1 without a tilted work plane (G68.2 first)");
  if (!setup_.orient_tool) fail(col, "G53.1 needs a machine with five-axis kinematics (kinematics.type)");
  if (w.axes != 0) fail(w.column(kAxisLetters[std::countr_zero(w.axes)]), "G53.1 takes no axis words");
  int choice = 0;
  if (w.on('P')) {
    const double v = w['P'];
    choice = static_cast<int>(std::lround(v));
    if (std::fabs(v - choice) > 1e-4 || choice < 0 || choice > 2) fail(w.column('P'), "G53.1 P must be 0, 1 or 2");
  }
  const std::array<double, 3> direction{twp_r_[2], twp_r_[5], twp_r_[8]};
  // The block builder adds a tool length offset along the part's Z: with the tool
  // turned off it, the tip would be off by the offset's turn.
  const bool tilted = std::fabs(direction[0]) > 1e-12 || std::fabs(direction[1]) > 1e-12;
  if (tilted && (tool_offset_[0] != 0 || tool_offset_[1] != 0 || tool_offset_[2] != 0))
    fail(col, "G53.1 with a tool length offset in effect: it acts along the part's Z, not the turned tool's (G49 first)");
  Pose machine = machine_of(position_, coord_);
  ToolOrientation o;
  try {
    o = setup_.orient_tool(direction, machine, choice);
  } catch (const std::invalid_argument& e) {
    fail(col, std::string("G53.1: ") + e.what());
  }
  for (const int a : {o.tilt_axis, o.rotary_axis})
    if (a < 3 || a > 5 || setup_.axes.find(kAxisLetters[a]) == std::string::npos)
      fail(col, "G53.1: the kinematics named no rotary axis of this machine");
  machine[static_cast<size_t>(o.tilt_axis)] = o.tilt_deg;
  machine[static_cast<size_t>(o.rotary_axis)] = o.rotary_deg;
  const Pose q = program_of(machine, coord_);
  Pose target = position_;
  target[static_cast<size_t>(o.tilt_axis)] = q[static_cast<size_t>(o.tilt_axis)];
  target[static_cast<size_t>(o.rotary_axis)] = q[static_cast<size_t>(o.rotary_axis)];
  twp_tool_tilted_ = tilted;
  if (target == position_) return;
  canon_.straight_traverse(ref(col), program_pose(target));
  position_ = target;
}

// What the frame does not take, as Fanuc refuses it in G68.2 mode: another work
// coordinate system, G52/G92, G28/G30, cutter compensation; and what this
// interpreter does not turn into the frame (splines and NURBS, spindle-synchronised
// motion, probing). Canned cycles are made in the frame, as Fanuc's (drilling along
// the frame's Z in G17).
void Interpreter::refuse_in_tilted_plane(const Words& w) const {
  if (w.g[16] == 690) return;  // cancelled on this line
  const auto refuse = [&](int column, const std::string& what) {
    fail(column, what + " in a tilted work plane (G68.2): G69 first");
  };
  const int g0 = w.g[0];
  if (g0 == 520 || (g0 >= 920 && g0 <= 923)) refuse(w.gcol[0], g_text(g0));
  if (g0 == 280 || g0 == 300) refuse(w.gcol[0], g_text(g0));
  if (g0 == 100 && w.on('L') && (w['L'] == 2 || w['L'] == 20) && w.on('P') &&
      (w['P'] == 0 || static_cast<int>(std::lround(w['P'])) == coord_))
    refuse(w.gcol[0], "G10 L" + std::to_string(static_cast<int>(w['L'])) + " of the active coordinate system");
  if (w.g[12] >= 0) {
    static const int kCs[] = {540, 550, 560, 570, 580, 590, 591, 592, 593};
    if (kCs[coord_ - 1] != w.g[12]) refuse(w.gcol[12], g_text(w.g[12]));
  }
  if (w.g[7] > 400) refuse(w.gcol[7], "cutter radius compensation " + g_text(w.g[7]));
  const int m = motion_to_be(w);
  if (m == 760 || m == 330 || m == 331 || (m >= 382 && m <= 385) || (m >= 50 && m <= 62)) {
    const int column = w.g[1] >= 0 ? w.gcol[1] : w.column(kAxisLetters[std::countr_zero(w.axes)]);
    fail(column, g_text(m) + " in a tilted work plane (G68.2) is not supported");
  }
}

void Interpreter::frame_arc(int col, const std::array<int, 3>& plane_axes, double cen1, double cen2, bool cw, int turns,
                            const Pose& from, const Pose& to, const Pose& end) {
  const size_t a1 = static_cast<size_t>(plane_axes[0]), a2 = static_cast<size_t>(plane_axes[1]),
               a3 = static_cast<size_t>(plane_axes[2]);
  if (std::fabs(to[a3] - from[a3]) > kHelixToleranceMm)
    fail(col, std::string("a helix in a tilted work plane (G68.2) is not supported: the arc's end must keep its ") +
                  kAxisLetters[a3] + " in the frame");
  for (size_t i = 3; i < end.size(); ++i)
    if (end[i] != position_[i]) fail(col, "an arc in a tilted work plane (G68.2) moves X Y Z only");
  const double t0 = std::atan2(from[a2] - cen2, from[a1] - cen1);
  const double t1 = std::atan2(to[a2] - cen2, to[a1] - cen1);
  const double r = std::hypot(from[a1] - cen1, from[a2] - cen2);
  double sweep = cw ? t0 - t1 : t1 - t0;
  // A full circle's end is its start, but for the rounding of the frame's round trip:
  // an angle this small is that, not an arc of its own.
  if (sweep < kFullCircleRad) sweep += 2 * M_PI;
  sweep += 2 * M_PI * (turns - 1);
  // Pieces of at most 90 degrees, each three control points of a rational quadratic
  // (the middle one where the tangents at its ends meet, weighted cos(half angle)).
  const int n = std::max(1, static_cast<int>(std::ceil(sweep / M_PI_2 - 1e-9)));
  const double step = sweep / n, dir = cw ? -1.0 : 1.0;
  const double w_mid = std::cos(step / 2), r_mid = r / w_mid;
  std::vector<NurbsPoint> pts;
  std::vector<double> knots{0, 0, 0};
  const auto put = [&](const Pose& work_mm, double weight) {
    NurbsPoint p;
    p.x = to_program(work_mm[0]);
    p.y = to_program(work_mm[1]);
    p.z = to_program(work_mm[2]);
    p.w = weight;
    p.has_z = true;
    pts.push_back(p);
  };
  const auto on_circle = [&](double angle, double radius) {
    Pose f = from;
    f[a1] = cen1 + radius * std::cos(angle);
    f[a2] = cen2 + radius * std::sin(angle);
    return work_of(f);
  };
  put(position_, 1);
  for (int k = 0; k < n; ++k) {
    put(on_circle(t0 + dir * (k + 0.5) * step, r_mid), w_mid);
    if (k + 1 == n) break;
    put(on_circle(t0 + dir * (k + 1) * step, r), 1);
    knots.push_back(k + 1);
    knots.push_back(k + 1);
  }
  put(end, 1);
  knots.insert(knots.end(), 3, static_cast<double>(n));
  canon_.nurbs_feed(ref(col), 3, pts, knots, program_pose(end));
}

}  // namespace cnc::rs274
