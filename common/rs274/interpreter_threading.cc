// G76, LinuxCNC's threading cycle: passes along the drive line (Z) at depths in X that
// grow by the degression R, each one synchronised with the spindle, then spring
// passes at the full depth. The canonical calls are LinuxCNC 2.9's, in its order and
// with its arithmetic (convert_threading_cycle and threading_pass), so that rs274
// prints the same numbers.
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

namespace {

// A G76 whose J is tiny against K, the more so with a large R, makes passes without
// end (LinuxCNC runs them all); here the block is refused before its first move.
constexpr int64_t kMaxThreadingPasses = 10000;

}  // namespace

void Interpreter::threading_cycle(Words& w, int col) {
  if (!setup_.spindle_sync)
    fail(col, "G76 needs a spindle whose position the machine measures (spindle.encoder_counts_per_rev)");
  // LinuxCNC's checks, in its order (the words' presence was checked with the block).
  if (w.on('$') && spindle_number(w) != 0) fail(w.column('$'), "Invalid D-number in G76 cycle");
  if (spindle_ == 0) fail(col, "Chosen spindle (0) not turning in G76");
  const Pose end = axis_target(w, false);
  for (size_t i = 3; i < end.size(); ++i)
    if (end[i] != position_[i]) {
      const char c = kAxisLetters[i];
      fail(w.on(c) ? w.column(c) : col, "Cannot move rotary axes with G76");
    }
  // LinuxCNC refuses it only with a compensation radius of 0; with a radius its
  // compensation turns the block into one plain compensated feed to the end, no thread.
  if (comp_ != 400) fail(col, "Cannot use G76 threading cycle with cutter radius compensation on");
  if (w['I'] == 0) fail(w.column('I'), "In G76, I must not be 0");
  if (w['J'] <= 0) fail(w.column('J'), "In G76, J must be greater than 0");
  if (w['K'] <= w['J']) fail(w.column('K'), "In G76, K must be greater than J");
  // LinuxCNC takes any P; a pitch of 0 or less would never advance along Z.
  if (!(w['P'] > 0)) fail(w.column('P'), "P (pitch) must be > 0 with G76");

  // Program units, as LinuxCNC computes (its current point is in them).
  const Pose from = program_pose(position_);
  const Pose to = program_pose(end);
  const double start_x = from[0], start_y = from[1], start_z = from[2], end_z = to[2];
  double i_number = w['I'], j_number = w['J'], k_number = w['K'];
  if (lathe_diameter_) {  // G7: I J K are diameters too
    i_number /= 2;
    j_number /= 2;
    k_number /= 2;
  }
  const bool boring = i_number > 0.0;  // I > 0: the thread is inside, cut outwards
  const double safe_x = start_x;
  const double full_dia_depth = std::fabs(i_number);
  const double start_depth = std::fabs(i_number) + std::fabs(j_number);
  const double cut_increment = std::fabs(j_number);
  const double full_threadheight = std::fabs(k_number);
  const double end_depth = std::fabs(k_number) + std::fabs(i_number);
  const double pitch = w['P'];
  // Q, the compound slide angle: infeed along the flank (Q-1 is LinuxCNC's absent Q).
  double compound_angle = w.on('Q') ? w['Q'] : 0.0;
  if (compound_angle == -1) compound_angle = 0;
  compound_angle = static_cast<double>(compound_angle * (M_PIl / 180.0L));  // LinuxCNC: long double pi
  if (end_z > start_z) compound_angle = -compound_angle;
  // H, the spring passes: an integer >= -1 (collect_words); past the pass limit it is refused below.
  const int spring_cuts = w.on('H') ? static_cast<int>(std::min(w['H'], static_cast<double>(kMaxThreadingPasses))) : 0;
  double degression = w.on('R') ? w['R'] : 1.0;
  if (degression < 1.0) degression = 1.0;
  // E: the length along Z of the tapered entry and exit, cut at the thread's depth
  // over it; L: which ends get it (1 entry, 2 exit, 3 both).
  double taper_dist = w.on('E') ? w['E'] : 0.0;
  if (taper_dist < 0.0) taper_dist = 0.0;
  const double taper_pitch = taper_dist > 0.0 ? pitch * std::hypot(taper_dist, full_threadheight) / taper_dist : pitch;
  if (end_z > start_z) taper_dist = -taper_dist;
  const int taper_flags = w.on('L') ? static_cast<int>(std::fmod(w['L'], 4.0)) : 0;  // an integer >= 0
  const bool entry_taper = (taper_flags & 1) != 0, exit_taper = (taper_flags & 2) != 0;
  const double target_z = end_z + std::fabs(k_number) * std::tan(compound_angle);

  // The depth of each pass after the first: LinuxCNC's formula, counted before the
  // first move so that a refused block makes none.
  const auto depth_of_pass = [&](int pass) { return full_dia_depth + cut_increment * std::pow(pass, 1.0 / degression); };
  std::string too_many = "G76 would make more than ";
  too_many += std::to_string(kMaxThreadingPasses);
  too_many += " passes";
  int64_t passes = static_cast<int64_t>(spring_cuts) + 1;
  if (passes > kMaxThreadingPasses) fail(w.column('H'), too_many + " (H spring passes)");
  for (int pass = 1; start_depth < end_depth && (pass == 1 || depth_of_pass(pass) < end_depth); ++pass)
    if (++passes > kMaxThreadingPasses) fail(w.column('J'), too_many + " (J too small for K, or R too large)");

  comp_filter_->flush();
  const SourceRef r = ref(col);
  Pose p = from;  // A B C U V W stay where they are
  const auto at = [&](double x, double z) -> const Pose& {
    p[0] = x;
    p[1] = start_y;
    p[2] = z;
    return p;
  };
  // One pass (LinuxCNC's threading_pass): X off the thread, in to the depth (along a
  // taper when asked), along Z synchronised with the spindle, out, and the feed
  // override off while synchronised.
  const auto threading_pass = [&](double depth, double zoff) {
    // X at `depth` less `back` from the drive line, on the thread's side (LinuxCNC's
    // expression, evaluated left to right as there).
    const auto x_of = [&](double back) { return boring ? safe_x + depth - back : safe_x - depth + back; };
    canon_.straight_traverse(r, at(x_of(end_depth), start_z - zoff));
    if (taper_dist != 0 && entry_taper) {
      canon_.enable_feed_override(r, false);
      canon_.start_speed_feed_sync(r, taper_pitch, false);
      canon_.straight_feed(r, at(x_of(full_threadheight), start_z - zoff));
      canon_.straight_feed(r, at(x_of(0), start_z - zoff - taper_dist));
      canon_.start_speed_feed_sync(r, pitch, false);
    } else {
      canon_.straight_traverse(r, at(x_of(0), start_z - zoff));
      canon_.enable_feed_override(r, false);
      canon_.start_speed_feed_sync(r, pitch, false);
    }
    if (taper_dist != 0 && exit_taper) {
      canon_.straight_feed(r, at(x_of(0), target_z - zoff + taper_dist));
      canon_.start_speed_feed_sync(r, taper_pitch, false);
      canon_.straight_feed(r, at(x_of(full_threadheight), target_z - zoff));
    } else {
      canon_.straight_feed(r, at(x_of(0), target_z - zoff));
    }
    canon_.stop_speed_feed_sync(r);
    canon_.straight_traverse(r, at(x_of(end_depth), target_z - zoff));
    canon_.enable_feed_override(r, true);
  };

  double depth = start_depth;
  double zoff = (depth - full_dia_depth) * std::tan(compound_angle);
  int pass = 1;
  while (depth < end_depth) {
    threading_pass(depth, zoff);
    depth = depth_of_pass(++pass);
    zoff = (depth - full_dia_depth) * std::tan(compound_angle);
  }
  // The full depth, once and then H times more (H-1: not at all, as in LinuxCNC).
  depth = end_depth;
  zoff = (depth - full_dia_depth) * std::tan(compound_angle);
  for (int i = 0; i < spring_cuts + 1; ++i) threading_pass(depth, zoff);
  canon_.straight_traverse(r, to);
  position_ = end;
}

}  // namespace cnc::rs274
