// Operator motion of the interpolator node: jogging and homing. See
// interpolator_node.h. Each move is a line block and an END block made here and
// fed to the core through the same window, planner and recorded inputs as a
// program's blocks; its jerk-limited start, cruise and brake are the core's.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "cnc/lcmt_alarm.hpp"
#include "common/program/block_msg.h"
#include "common/service/open_limit.h"
#include "common/util/clock.h"
#include "services/interpolator/interpolator_node.h"

namespace cnc::interp {

namespace {
// A homing search that ended without a latch waits this long for one still on its
// way over the bus before it says there is no switch.
constexpr double kLatchGraceS = 0.5;
}  // namespace

namespace {
using PC = cnc::lcmt_program_command;
constexpr double kStatusFresh_s = 0.5;
bool active(RunState s) { return s == RunState::kRunning || s == RunState::kHeld || s == RunState::kStarved; }

std::string mm(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  return buf;
}
}  // namespace

bool InterpolatorNode::limits_apply(int axis) const {
  // Soft limits (the axis's travel) apply once the axis is homed, or always to an
  // axis that needs no homing; an axis not yet homed may be jogged anywhere.
  const auto& a = cfg_.axes[static_cast<size_t>(axis)];
  return a.home.method == "none" || core_.homed(axis);
}

int InterpolatorNode::joint_of(int axis) const {
  const auto n = static_cast<size_t>(joint_status_.num_joints);
  if (joint_status_.axis.size() != n || joint_status_.home_latch_count.size() != n) return -1;
  for (size_t k = 0; k < n; ++k)
    if (joint_status_.axis[k] == axis) return static_cast<int>(k);
  return -1;
}

std::string InterpolatorNode::unhomed() const {
  if (!cfg_.operator_.homing_required) return "";
  for (size_t a = 0; a < cfg_.axes.size(); ++a)
    if (cfg_.axes[a].home.method != "none" && !core_.homed(static_cast<int>(a)))
      return "axis " + cfg_.axes[a].name + " is not homed";
  return "";
}

std::string InterpolatorNode::manual_refusal() const {
  if (fault_) return "the cell is in FAULT (" + fault_cause_ + "): RESET first";
  if (active(core_.state()))
    return manual_ != Manual::kNone ? manual_text_ + " runs: STOP it first" : "a program is running: STOP it first";
  if (peers_.lost(0)) return std::string("the drive bridge is lost: ") + peers_.last_lost_text();
  if (util::monotonic_s() - axis_status_s_ > kStatusFresh_s) return "no AXIS_STATUS from the drive bridge";
  for (size_t i = 0; i < cfg_.axes.size(); ++i)
    if (axis_status_.drive_state[i] != cnc::lcmt_axis_status::ENABLED)
      return "axis " + cfg_.axes[i].name + " is not enabled: enable the drives first";
  return "";
}

void InterpolatorNode::manual_refuse(const char* what, const std::string& why) {
  spdlog::warn("{} refused: {}", what, why);
  alarm(cnc::lcmt_alarm::WARNING, std::string(what) + "_refused", std::string(what) + " refused: " + why);
}

void InterpolatorNode::start_move(int axis, double target_mm, double feed_mm_per_min, const std::string& label) {
  const int n = static_cast<int>(cfg_.axes.size());
  // Nothing to move (already there): no move; the caller sees the path standing.
  if (!(std::fabs(target_mm - core_.machine_position(axis)) > 1e-9)) return;
  program::Block line;
  line.index = 0;
  line.kind = program::BlockKind::kLine;
  line.source_file = label;
  line.start.resize(static_cast<size_t>(n));
  for (int a = 0; a < n; ++a) line.start[static_cast<size_t>(a)] = core_.machine_position(a);
  line.end = line.start;
  line.end[static_cast<size_t>(axis)] = target_mm;
  line.feed_mm_per_min = feed_mm_per_min;
  program::Block end;
  end.index = 1;
  end.kind = program::BlockKind::kEnd;
  end.event.number = program::kEndOfOperatorLine;
  end.source_file = label;
  end.start = line.end;
  end.end = line.end;
  token_ = --local_token_;
  num_blocks_ = 2;
  program_path_ = label;
  reorder_.clear();
  reorder_.emplace(0, program::to_msg(line, token_));
  reorder_.emplace(1, program::to_msg(end, token_));
  cnc::lcmt_program_command load{};
  load.command = PC::LOAD;
  load.program_path = label;
  apply_command(Command{Command::Kind::kLoad, 1.0, {}}, load);
  cnc::lcmt_program_command start{};
  start.command = PC::START;
  apply_command(Command{Command::Kind::kStart, 1.0, {}}, start);
  last_request_first_ = -1;
}

void InterpolatorNode::manual_stop(const std::string& why) {
  if (active(core_.state())) {
    cnc::lcmt_program_command stop{};
    stop.command = PC::STOP;
    apply_command(Command{Command::Kind::kStop, 1.0, {}}, stop);
  }
  if (manual_ == Manual::kHome) {
    spdlog::warn("homing aborted: {}", why);
    alarm(cnc::lcmt_alarm::WARNING, "home_aborted", "homing aborted: " + why);
    home_ = Homing{};
    manual_text_ = "homing (aborting)";
    // The move brakes; manual_ ends when the path stands (manual_cycle).
    manual_ = Manual::kJog;
    jog_continuous_ = false;
  }
}

void InterpolatorNode::on_manual_command(const cnc::lcmt_program_command& m) {
  const int n = static_cast<int>(cfg_.axes.size());
  if (m.command == PC::JOG_KEEPALIVE) {
    if (manual_ == Manual::kJog && jog_continuous_ && m.axis == jog_axis_) {
      jog_keepalive_s_ = util::monotonic_s();
      jog_keepalive_mm_ = core_.machine_position(jog_axis_);
      jog_keepalive_v_ = core_.last().feed_mm_per_min / 60.0;
    }
    return;
  }
  if (m.command == PC::JOG && manual_ == Manual::kJog && jog_continuous_ && m.jog_continuous == 1 &&
      m.axis == jog_axis_ && (m.value > 0) == (jog_dir_ > 0)) {
    jog_keepalive_s_ = util::monotonic_s();  // the same jog again: it goes on
    return;
  }
  const char* what = m.command == PC::HOME ? "home" : "jog";
  if (const std::string why = manual_refusal(); !why.empty()) return manual_refuse(what, why);
  if (m.command == PC::HOME) {
    Homing h;
    if (m.axis >= n || m.axis < -1) return manual_refuse(what, "no axis " + std::to_string(m.axis));
    if (m.axis >= 0) {
      if (cfg_.axes[static_cast<size_t>(m.axis)].home.method == "none")
        return manual_refuse(what, "axis " + cfg_.axes[static_cast<size_t>(m.axis)].name +
                                       " has no home method (axes[].home.method)");
      h.axes.push_back(m.axis);
    } else {
      for (int a = 0; a < n; ++a)
        if (cfg_.axes[static_cast<size_t>(a)].home.method != "none") h.axes.push_back(a);
      std::stable_sort(h.axes.begin(), h.axes.end(), [&](int a, int b) {
        return cfg_.axes[static_cast<size_t>(a)].home.order < cfg_.axes[static_cast<size_t>(b)].home.order;
      });
      if (h.axes.empty()) return manual_refuse(what, "no axis has a home method (axes[].home.method)");
    }
    for (int a : h.axes) {
      const auto i = static_cast<size_t>(a);
      if (cfg_.axes[i].home.method == "switch" &&
          (axis_status_.num_latches != n || axis_status_.home_latch_count[i] < 0))
        return manual_refuse(what, "axis " + cfg_.axes[i].name +
                                       ": its drive reports no home switch latch (drive profile home_latch_*)");
      if (cfg_.axes[i].home.method == "switch" && cfg_.axes[i].gantry.enabled) {
        const int k = joint_of(a);
        if (k < 0) return manual_refuse(what, "axis " + cfg_.axes[i].name + ": no JOINT_STATUS of its gantry joint " +
                                                  cfg_.axes[i].gantry.name + " from the drive bridge");
        if (joint_status_.home_latch_count[static_cast<size_t>(k)] < 0)
          return manual_refuse(what, "axis " + cfg_.axes[i].gantry.name +
                                         ": its drive reports no home switch latch (drive profile home_latch_*)");
      }
    }
    home_ = h;
    manual_ = Manual::kHome;
    spdlog::info("homing {} axis(es)", home_.axes.size());
    home_next_axis();
    return;
  }
  // JOG
  if (m.axis < 0 || m.axis >= n) return manual_refuse(what, "no axis " + std::to_string(m.axis));
  const auto i = static_cast<size_t>(m.axis);
  const auto& ax = cfg_.axes[i];
  const double here = core_.machine_position(m.axis);
  const double dir = m.value > 0 ? 1.0 : -1.0;
  double target = m.jog_continuous == 1 ? here + dir * (ax.max_mm - ax.min_mm) : here + m.value;
  if (limits_apply(m.axis)) {
    // The travel, in machine coordinates; and the drive bridge checks it on the
    // setpoints (the drive's coordinates, which a homed axis's offset shifts): the
    // jog stays within both.
    double lo = 0, hi = 0;
    drive_travel(m.axis, &lo, &hi);
    lo = std::max(lo, ax.min_mm);
    hi = std::min(hi, ax.max_mm);
    target = std::clamp(target, lo, hi);
    if (std::fabs(target - here) < 1e-6)
      return manual_refuse(what, "axis " + ax.name + " stands at its soft limit " + mm(dir > 0 ? hi : lo) + " mm");
  }
  if (cfg_.io.enabled && util::monotonic_s() - io_status_s_ < 1.0) {
    const service::OpenLimit o = service::open_limit(cfg_, io_status_);
    if (o.axis == m.axis && o.side == (dir > 0 ? 1 : -1))
      return manual_refuse(what, "jog towards the limit switch " + o.name + ", which is open: jog the axis away from it");
  }
  const double vmax = ax.max_velocity_mm_s * 60.0;
  const double feed = m.feed_mm_per_min > 0 ? std::min(m.feed_mm_per_min, vmax) : ax.jog_velocity_mm_s * 60.0;
  manual_ = Manual::kJog;
  jog_continuous_ = m.jog_continuous == 1;
  jog_axis_ = m.axis;
  jog_dir_ = dir;
  jog_keepalive_s_ = util::monotonic_s();
  jog_keepalive_mm_ = here;
  jog_keepalive_v_ = 0;
  manual_text_ = "jog " + ax.name + (dir > 0 ? "+" : "-") +
                 (jog_continuous_ ? std::string(" continuous") : " " + mm(m.value) + " mm");
  spdlog::info("{} at {} mm/min: {} -> {} mm", manual_text_, feed, mm(here), mm(target));
  start_move(m.axis, target, feed, manual_text_);
}

void InterpolatorNode::drive_travel(int axis, double* lo, double* hi) const {
  const auto& ax = cfg_.axes[static_cast<size_t>(axis)];
  const double off = core_.drive_offset(axis);
  *lo = ax.min_mm - off;
  *hi = ax.max_mm - off;
}

double InterpolatorNode::backoff_target(int axis, double latch_drive_mm) const {
  const auto& h = cfg_.axes[static_cast<size_t>(axis)].home;
  return latch_drive_mm - core_.drive_offset(axis) - h.direction * h.backoff_mm;
}

void InterpolatorNode::start_search() {
  // Search: towards the switch, at most the travel and a half.
  const int a = home_.axis;
  const auto i = static_cast<size_t>(a);
  const auto& h = cfg_.axes[i].home;
  const int n = static_cast<int>(cfg_.axes.size());
  home_.phase = 0;
  home_.count0 = axis_status_.num_latches == n ? axis_status_.home_latch_count[i] : 0;
  home_.search_end_s = 0;
  home_.gantry = cfg_.axes[i].gantry.enabled;
  if (home_.gantry) {
    const int k = joint_of(a);
    home_.count0_2 = k >= 0 ? joint_status_.home_latch_count[static_cast<size_t>(k)] : 0;
    home_.got1 = home_.got2 = false;
  }
  manual_text_ = "home " + cfg_.axes[i].name + ": search";
  const auto& ax = cfg_.axes[i];
  // At most the travel and a half, and never past the travel the drive bridge checks
  // on the setpoints (the drive's coordinates, as a jog's clamp): the latch reaches
  // the interpolator over the bus, tens of ms after the switch closed, and the stop
  // follows. A 10 mm/s search ran 1.04 mm past a switch 1 mm inside the travel on a
  // loaded machine (a travel fault, integration.operator in 1 of 10 suite runs); now
  // it stands at the travel's end at worst, and the homing goes on from the latch.
  double lo = 0, hi = 0;
  drive_travel(a, &lo, &hi);
  const double span = 1.5 * (ax.max_mm - ax.min_mm);
  const double target = std::clamp(core_.machine_position(a) + h.direction * span, lo, hi);
  start_move(a, target, h.search_velocity_mm_s * 60.0, manual_text_);
}

void InterpolatorNode::home_next_axis() {
  const int n = static_cast<int>(cfg_.axes.size());
  while (home_.next < home_.axes.size()) {
    const int a = home_.axes[home_.next++];
    const auto i = static_cast<size_t>(a);
    const auto& h = cfg_.axes[i].home;
    home_.axis = a;
    if (h.method == "absolute") {
      // The drive's absolute position is the machine's.
      cnc::lcmt_program_command homed{};
      homed.command = PC::HOMED;
      homed.axis = a;
      homed.value = 0.0;
      Command c;
      c.kind = Command::Kind::kHomed;
      c.axis = a;
      c.value = 0.0;
      apply_command(c, homed);
      spdlog::info("axis {} homed (absolute)", cfg_.axes[i].name);
      alarm(cnc::lcmt_alarm::INFO, "homed", "axis " + cfg_.axes[i].name + " homed (absolute position)");
      continue;
    }
    // An axis standing on or past the point where its switch last closed (a homing
    // stopped there, by STOP or a fault) has the switch closed: the search would see
    // no closing edge and run on to the end of the travel (integration.operator: Y
    // to -5.04 mm, a travel fault, in 1 of 12 suite runs). It backs off first, as
    // LinuxCNC does from a tripped home switch.
    const bool latched = axis_status_.num_latches == n && axis_status_.home_latch_count[i] > 0;
    // The back-off's target (the further back of the sides that stand on their switch), if any.
    bool on_switch = false;
    double backoff_to = 0;
    if (latched) {
      const double latch_drive = axis_status_.home_latch_mm[i];
      const double drive_pos = core_.machine_position(a) + core_.drive_offset(a);
      if (h.direction * (drive_pos - latch_drive) > -h.backoff_mm) {
        on_switch = true;
        backoff_to = backoff_target(a, latch_drive);
        spdlog::info("home {}: off the switch: the switch closed at {} mm (drive) and the axis stands at {} mm: "
                     "backing off first",
                     cfg_.axes[i].name, mm(latch_drive), mm(drive_pos));
      }
    }
    // A gantry's second side on its own switch: the same, in the first drive's coordinates.
    if (const int k = cfg_.axes[i].gantry.enabled ? joint_of(a) : -1; k >= 0) {
      const auto kk = static_cast<size_t>(k);
      if (joint_status_.home_latch_count[kk] > 0) {
        const double squaring = joint_status_.squaring_mm[kk];
        const double latch_drive = joint_status_.home_latch_mm[kk] - squaring;
        const double drive_pos = joint_status_.actual_mm[kk] - squaring;
        if (h.direction * (drive_pos - latch_drive) > -h.backoff_mm) {
          const double to = backoff_target(a, latch_drive);
          backoff_to = on_switch && h.direction * (backoff_to - to) > 0 ? to : (on_switch ? backoff_to : to);
          on_switch = true;
          spdlog::info("home {}: off the switch: {}'s switch closed at {} mm and it stands at {} mm (the first "
                       "drive's coordinates): backing off first",
                       cfg_.axes[i].name, cfg_.axes[i].gantry.name, mm(latch_drive), mm(drive_pos));
        }
      }
    }
    if (on_switch) {
      home_.phase = 6;
      manual_text_ = "home " + cfg_.axes[i].name + ": off the switch";
      start_move(a, backoff_to, h.search_velocity_mm_s * 60.0, manual_text_);
      return;
    }
    start_search();
    return;
  }
  spdlog::info("homing done");
  alarm(cnc::lcmt_alarm::INFO, "home_done", "homing done");
  manual_ = Manual::kNone;
  manual_text_.clear();
  home_ = Homing{};
  token_ = 0;
  num_blocks_ = 0;
}

bool InterpolatorNode::gantry_latches(const char* phase) {
  const int a = home_.axis;
  const auto i = static_cast<size_t>(a);
  const auto& ax = cfg_.axes[i];
  const int n = static_cast<int>(cfg_.axes.size());
  const int k = joint_of(a);
  if (axis_status_.num_latches != n || k < 0) return false;
  const auto kk = static_cast<size_t>(k);
  if (!home_.got1 && axis_status_.home_latch_count[i] != home_.count0) {
    home_.got1 = true;
    home_.at1_mm = axis_status_.home_latch_mm[i];
    if (!home_.got2) home_.first_machine_mm = core_.machine_position(a);
  }
  if (!home_.got2 && joint_status_.home_latch_count[kk] != home_.count0_2) {
    home_.got2 = true;
    home_.at2_mm = joint_status_.home_latch_mm[kk];
    if (!home_.got1) home_.first_machine_mm = core_.machine_position(a);
  }
  if (home_.got1 && home_.got2) return true;
  // One side latched: the other's switch must follow within home_max_difference_mm.
  if ((home_.got1 || home_.got2) &&
      std::fabs(core_.machine_position(a) - home_.first_machine_mm) > ax.gantry.home_max_difference_mm)
    manual_stop("axis " + ax.name + " (" + phase + "): " + (home_.got1 ? ax.name : ax.gantry.name) +
                "'s switch closed, " + (home_.got1 ? ax.gantry.name : ax.name) + "'s not within " +
                mm(ax.gantry.home_max_difference_mm) + " mm (axes[].gantry.home_max_difference_mm)");
  return false;
}

void InterpolatorNode::manual_cycle() {
  if (manual_ == Manual::kNone) return;
  const bool moving = active(core_.state());
  if (manual_ == Manual::kJog) {
    if (moving && jog_continuous_ && util::monotonic_s() - jog_keepalive_s_ > cfg_.operator_.jog_keepalive_timeout_s) {
      const std::string text = manual_text_ + ": no keepalive from the jogging client for " +
                               mm(util::monotonic_s() - jog_keepalive_s_) + " s: stopped (at the last keepalive " +
                               cfg_.axes[static_cast<size_t>(jog_axis_)].name + " " + mm(jog_keepalive_mm_) +
                               " mm at " + mm(jog_keepalive_v_) + " mm/s)";
      spdlog::warn("{}", text);
      alarm(cnc::lcmt_alarm::WARNING, "jog_keepalive_lost", text);
      cnc::lcmt_program_command stop{};
      stop.command = PC::STOP;
      apply_command(Command{Command::Kind::kStop, 1.0, {}}, stop);
      jog_continuous_ = false;
    }
    if (!moving) {
      manual_ = Manual::kNone;
      manual_text_.clear();
      token_ = 0;
      num_blocks_ = 0;
    }
    return;
  }
  // Homing.
  const int a = home_.axis;
  const auto i = static_cast<size_t>(a);
  const auto& ax = cfg_.axes[i];
  const auto& h = ax.home;
  const int n = static_cast<int>(cfg_.axes.size());
  const bool have_latch = axis_status_.num_latches == n;
  const int32_t count = have_latch ? axis_status_.home_latch_count[i] : 0;
  auto stop = [&] {
    cnc::lcmt_program_command m{};
    m.command = PC::STOP;
    apply_command(Command{Command::Kind::kStop, 1.0, {}}, m);
  };
  // A gantry: both sides move together; each latches its own switch.
  if (home_.gantry && (home_.phase == 0 || home_.phase == 3)) {
    const bool search = home_.phase == 0;
    if (gantry_latches(search ? "search" : "latch")) {
      stop();
      if (search) {
        // Off both switches: back from the one the search met first.
        const int k = joint_of(a);
        const double squaring = k >= 0 ? joint_status_.squaring_mm[static_cast<size_t>(k)] : 0.0;
        const double second = home_.at2_mm - squaring;  // in the first drive's coordinates
        home_.seen_mm = h.direction * (home_.at1_mm - second) < 0 ? home_.at1_mm : second;
        home_.phase = 1;
      } else {
        home_.latch_mm = home_.at1_mm;
        home_.phase = 4;
      }
      return;
    }
    if (manual_ != Manual::kHome) return;  // stopped
    if (!moving && !(search && !home_.got1 && !home_.got2)) {
      manual_stop("axis " + ax.name + ": " + (home_.got1 ? ax.gantry.name : ax.name) + "'s switch did not close" +
                  (search ? " up to the end of the search" : " within " + mm(2 * h.backoff_mm) + " mm of the back-off"));
      return;
    }
    if (!search || home_.got1 || home_.got2) return;
  }
  switch (home_.phase) {
    case 0:  // search
      if (count != home_.count0) {
        home_.seen_mm = axis_status_.home_latch_mm[i];
        stop();
        home_.phase = 1;
      } else if (!moving) {
        // At the end of the search: a latch may still be on its way (AXIS_STATUS).
        const double now = util::monotonic_s();
        if (home_.search_end_s == 0) home_.search_end_s = now;
        if (now - home_.search_end_s > kLatchGraceS)
          manual_stop("axis " + ax.name + ": no home switch up to the end of its travel (" +
                      mm(core_.machine_position(a)) + " mm)");
      }
      break;
    case 1:  // braking on the switch; then off it, from where it closed
      if (moving) break;
      home_.phase = 2;
      manual_text_ = "home " + ax.name + ": back off";
      start_move(a, backoff_target(a, home_.seen_mm), h.search_velocity_mm_s * 60.0, manual_text_);
      break;
    case 2:  // backed off; the slow approach, up to twice the back-off
      if (moving) break;
      home_.phase = 3;
      home_.count0 = count;
      if (home_.gantry) {
        const int k = joint_of(a);
        home_.count0_2 = k >= 0 ? joint_status_.home_latch_count[static_cast<size_t>(k)] : 0;
        home_.got1 = home_.got2 = false;
      }
      manual_text_ = "home " + ax.name + ": latch";
      start_move(a, core_.machine_position(a) + h.direction * 2 * h.backoff_mm, h.latch_velocity_mm_s * 60.0,
                 manual_text_);
      break;
    case 3:  // latch
      if (count != home_.count0) {
        home_.latch_mm = axis_status_.home_latch_mm[i];
        stop();
        home_.phase = 4;
      } else if (!moving) {
        manual_stop("axis " + ax.name + ": the switch did not close again within " + mm(2 * h.backoff_mm) +
                    " mm of the back-off");
      }
      break;
    case 4: {  // at rest past the latch: the latch is switch_position_mm; then to the home position
      if (moving) break;
      const double offset = home_.latch_mm - h.switch_position_mm;
      cnc::lcmt_program_command homed{};
      homed.command = PC::HOMED;
      homed.axis = a;
      homed.value = offset;
      if (home_.gantry) {
        // The second side's offset, for the drive bridge (the core plans the axis alone):
        // it moves that side by the difference, which squares the axis.
        const double offset2 = home_.at2_mm - ax.gantry.switch_position_mm;
        homed.num_axes = 1;
        homed.position_mm.assign(1, offset2);
        spdlog::info("gantry {}: {} latched at {} mm, {} at {} mm (each drive's); offsets {} and {} mm: squaring {} mm",
                     ax.name, ax.name, mm(home_.at1_mm), ax.gantry.name, mm(home_.at2_mm), mm(offset), mm(offset2),
                     mm(offset2 - offset));
        alarm(cnc::lcmt_alarm::INFO, "gantry_squared",
              "gantry " + ax.name + ": " + ax.gantry.name + " squared to " + ax.name + ": squaring " +
                  mm(offset2 - offset) + " mm (switches latched at " + mm(home_.at1_mm) + " and " + mm(home_.at2_mm) +
                  " mm, each drive's)");
      }
      Command c;
      c.kind = Command::Kind::kHomed;
      c.axis = a;
      c.value = offset;
      apply_command(c, homed);
      spdlog::info("axis {} homed: latched at {} mm (drive), drive offset {} mm", ax.name, mm(home_.latch_mm),
                   mm(offset));
      alarm(cnc::lcmt_alarm::INFO, "homed",
            "axis " + ax.name + " homed: switch latched at " + mm(home_.latch_mm) + " mm (drive), offset " +
                mm(offset) + " mm");
      home_.phase = 5;
      manual_text_ = "home " + ax.name + ": to home";
      start_move(a, h.position_mm, h.search_velocity_mm_s * 60.0, manual_text_);
      break;
    }
    case 5:
      if (moving) break;
      home_next_axis();
      break;
    case 6:  // off the switch (it was closed at the start); then the search
      if (moving) break;
      start_search();
      break;
    default: break;
  }
}

}  // namespace cnc::interp
