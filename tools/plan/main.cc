// cnc-plan: dry run of a part program through the interpolator core — no LCM, no
// clock. Writes the setpoint stream as CSV and prints the program time. Two runs
// of the same program and config give identical files, byte for byte. On a five-axis
// machine it applies the kinematics: every setpoint (the tool tip in the part, the
// rotary axes) is turned into joints, which the CSV carries and the run checks
// against the joints' travel (refused, naming the joint and the line) and limits.
//
//   cnc-plan --machine M --program P --csv OUT [--override 1.0] [--param-update corrected]
//            [--subroutine-path DIR:DIR] [--tool-table FILE] [--block-delete on|off] [--start X,Y,Z]
//            [--with-kind] [--modes OUT]
//   cnc-plan --machine M --show-setup     (what a program may do here: the program server's setup)
#include <utility>
#include <array>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/kinematics/kinematics.h"
#include "common/motion/feed_override.h"
#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/service/service.h"
#include "common/rs274/modal_text.h"
#include "common/util/signals.h"
#include "services/part_program_server/program_server.h"

namespace {

// --modes OUT: the interpreter's modal state after each line of the main program (a
// row where it changed), interpreted again with the dry run's setup: what the HMI shows
// as the active G-codes, F and S, and the work offset, at the line a program runs.
int write_modes(const cnc::pps::ProgramSetup& setup, const std::string& program, const std::vector<double>& start,
                const std::string& out_path) {
  struct Quiet : cnc::rs274::Canon {
    void straight_traverse(const cnc::rs274::SourceRef&, const cnc::rs274::Pose&) override {}
    void straight_feed(const cnc::rs274::SourceRef&, const cnc::rs274::Pose&) override {}
    void arc_feed(const cnc::rs274::SourceRef&, double, double, double, double, int, double,
                  const cnc::rs274::Pose&) override {}
    void nurbs_feed(const cnc::rs274::SourceRef&, int, const std::vector<cnc::rs274::NurbsPoint>&,
                    const std::vector<double>&, const cnc::rs274::Pose&) override {}
    void dwell(const cnc::rs274::SourceRef&, double) override {}
  } canon;
  cnc::rs274::MachineSetup m = setup.machine;
  m.write_var_file = false;
  // The machine's axes (m.axes, in the config's order) to the interpreter's pose (X Y Z A B C U V W).
  for (size_t a = 0; a < start.size() && a < m.axes.size(); ++a)
    if (const size_t i = std::string("XYZABCUVW").find(m.axes[a]); i != std::string::npos) m.start_position[i] = start[a];
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(out_path.c_str(), "w"), &std::fclose);
  if (!f) {
    std::fprintf(stderr, "cnc-plan: cannot write %s\n", out_path.c_str());
    return 1;
  }
  std::fputs("line,codes,feed,speed,tool,offset_x,offset_y,offset_z\n", f.get());
  cnc::rs274::Interpreter in(m, canon);
  int32_t last_file = -1, last_line = 0;
  std::string last_row;
  auto emit = [&] {
    if (last_file != 0 || last_line <= 0) return;
    const cnc::rs274::ModalState s = in.modal_state();
    const cnc::rs274::Pose off = cnc::rs274::work_offset(s);
    char buf[512];
    std::snprintf(buf, sizeof buf, "%s,%.6g,%.6g,%d,%.6f,%.6f,%.6f", cnc::rs274::active_codes(s).c_str(), s.feed,
                  s.speed, s.tool, off[0], off[1], off[2]);
    if (last_row == buf) return;
    last_row = buf;
    std::fprintf(f.get(), "%d,%s\n", last_line, buf);
  };
  in.set_line_hook([&](int32_t file, int32_t line) {
    emit();
    last_file = file;
    last_line = line;
  });
  try {
    in.open(program);
    for (int64_t n = 0; in.execute_next(); ++n)
      if (n > setup.max_validation_lines) break;
    emit();
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "cnc-plan: --modes: %s\n", ex.what());
    return 1;
  }
  return 0;
}

int run_plan(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  const std::string program_path = args.option("program");
  const std::string csv_path = args.option("csv");
  // The language's files from the command line, over the machine config's.
  cnc::pps::DryRunFiles files;
  const std::string dirs = args.option("subroutine-path");
  for (size_t b = 0; b < dirs.size();) {
    size_t e = dirs.find(':', b);
    if (e == std::string::npos) e = dirs.size();
    if (e > b) files.subroutine_path.push_back(dirs.substr(b, e - b));
    b = e + 1;
  }
  files.tool_table = args.option("tool-table");
  cnc::pps::ProgramSetup setup = cnc::pps::dry_run_setup(cfg, files);
  // The program server's switch as the program was loaded with it (the HMI's preview passes it).
  if (const std::string bd = args.option("block-delete"); !bd.empty()) {
    if (bd != "on" && bd != "off")
      throw cnc::service::FlagError("--block-delete " + bd + ": expected on or off");
    setup.machine.block_delete = bd == "on";
  }
  if (args.flags.count("show-setup") > 0) {
    std::fputs(cnc::pps::describe(setup).c_str(), stdout);
    return 0;
  }
  if (program_path.empty()) {
    std::fprintf(stderr, "cnc-plan: --program FILE is required\n");
    return cnc::service::kExitBadInput;
  }
  // Where the machine stands, as the program server loads a program from there (the
  // HMI's preview passes it); default: the home position.
  const int naxes = static_cast<int>(cfg.axes.size());
  std::vector<double> start;
  if (const std::string text = args.option("start"); !text.empty()) {
    for (size_t b = 0; b <= text.size();) {
      size_t e = text.find(',', b);
      if (e == std::string::npos) e = text.size();
      const std::string one = text.substr(b, e - b);
      char* end = nullptr;
      const double v = std::strtod(one.c_str(), &end);
      if (one.empty() || *end != '\0' || !std::isfinite(v))
        throw cnc::service::FlagError("--start " + text + ": '" + one + "' is not a position");
      start.push_back(v);
      b = e + 1;
    }
    if (static_cast<int>(start.size()) != naxes)
      throw cnc::service::FlagError("--start " + text + ": expected " + std::to_string(naxes) +
                                    " machine positions, one per axis, comma-separated");
  }
  const bool with_kind = args.flags.count("with-kind") > 0;
  const cnc::pps::ProgramSetup modes_setup = setup;
  cnc::pps::ProgramServer server(std::move(setup), cnc::pps::ServerLimits{});
  const cnc::pps::LoadResult loaded = server.load(program_path, 1, start);
  if (!loaded.ok) {
    std::fprintf(stderr, "cnc-plan: program refused: %s\n", loaded.error.c_str());
    return 3;
  }
  if (const std::string modes = args.option("modes"); !modes.empty())
    if (const int rc = write_modes(modes_setup, program_path, start, modes); rc != 0) return rc;
  for (const std::string& w : loaded.warnings) std::fprintf(stderr, "cnc-plan: warning: %s\n", w.c_str());
  // The planner inline: each plan is ready the cycle its block is submitted, as if
  // the planner thread were never late.
  cnc::interp::SyncPlanLink planner(cfg);
  cnc::interp::Interpolator core(cfg, planner);
  const cnc::interp::FeedPolicy feed(cfg);
  core.set_auto_resume_pauses(true);  // M0/M1/M6: a dry run does not wait for an operator
  if (!args.option("param-update").empty())
    core.set_param_update(cnc::interp::param_update_from_string(args.option("param-update")));
  if (!args.option("override").empty()) {
    // At override 0 the path never moves on without an operator's resume: a dry run
    // of it could never end.
    const std::string text = args.option("override");
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(value > 0) || value > cnc::motion::kMaxFeedOverride) {
      std::fprintf(stderr,
                   "cnc-plan: --override %s: expected a feed override in (0, %g]; at override 0 the motion "
                   "stands still until resumed, so the program can never finish\n",
                   text.c_str(), cnc::motion::kMaxFeedOverride);
      return cnc::service::kExitBadInput;
    }
    cnc::interp::Command c{cnc::interp::Command::Kind::kOverride, value};
    core.apply_command(c);
  }
  if (!start.empty()) {
    // The path rests there, as after a RESET that took the drives' positions.
    cnc::interp::Command c{cnc::interp::Command::Kind::kReset, 0.0};
    for (int a = 0; a < naxes; ++a) c.position_mm[static_cast<size_t>(a)] = start[static_cast<size_t>(a)];
    core.apply_command(c);
  }
  core.apply_command(cnc::interp::Command{cnc::interp::Command::Kind::kLoad, 1.0});
  core.apply_command(cnc::interp::Command{cnc::interp::Command::Kind::kStart, 1.0});

  // The joints of a five-axis machine: each setpoint's inverse (tool length 0: the
  // program's G43 is already in Z, along the part's Z).
  const std::unique_ptr<cnc::kinematics::Kinematics> kin = cnc::kinematics::make_kinematics(cfg);
  const bool five_axis = cfg.kinematics.type != "identity";
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv(nullptr, &std::fclose);
  if (!csv_path.empty()) {
    csv.reset(std::fopen(csv_path.c_str(), "w"));
    if (!csv) {
      std::fprintf(stderr, "cnc-plan: cannot write %s\n", csv_path.c_str());
      return 1;
    }
    std::fputs("cycle,t_s,x_mm,y_mm,z_mm,line,u,feed_mm_min,limit", csv.get());
    if (five_axis)
      for (int j = 0; j < kin->joints(); ++j) std::fprintf(csv.get(), ",j_%s", kin->joint_limits()[static_cast<size_t>(j)].name.c_str());
    std::fputs(with_kind ? ",kind\n" : "\n", csv.get());
  }
  const int64_t num_blocks = server.num_blocks();
  // A program that never ends (a loop without exit) must not hold the dry run forever.
  const int64_t max_cycles = static_cast<int64_t>(std::ceil(cfg.program.dry_run_max_time_s / cfg.ipo_period_s));
  double max_feed = 0;
  const auto t0 = std::chrono::steady_clock::now();
  int64_t cycles = 0;
  // Finite differences of the setpoints against each axis's limits (at rest before
  // the first and after the last setpoint).
  const double T = cfg.ipo_period_s;
  std::array<double, cnc::program::kMaxAxes> p_prev = core.last().position_mm, v1{}, v2{};
  std::array<double, cnc::program::kMaxAxes> use_v{}, use_a{}, use_j{};
  cnc::kinematics::Pose joints{}, j_prev{}, jv1{}, jv2{};
  std::array<double, cnc::program::kMaxAxes> juse_v{}, juse_a{}, juse_j{};
  std::string out_of_travel;  // the first joint out of its travel: where and how far
  if (five_axis && !kin->inverse(p_prev, j_prev)) out_of_travel = "the start is no pose of the machine";
  const auto account_joints = [&](const cnc::kinematics::Pose& j, int32_t line) {
    const auto& lim = kin->joint_limits();
    for (int a = 0; a < kin->joints(); ++a) {
      const size_t k = static_cast<size_t>(a);
      const double v = (j[k] - j_prev[k]) / T;
      const double acc = (v - jv1[k]) / T;
      const double jerk = (v - 2 * jv1[k] + jv2[k]) / (T * T);
      juse_v[k] = std::max(juse_v[k], std::fabs(v) / lim[k].max_velocity_mm_s);
      juse_a[k] = std::max(juse_a[k], std::fabs(acc) / lim[k].max_accel_mm_s2);
      juse_j[k] = std::max(juse_j[k], std::fabs(jerk) / lim[k].max_jerk_mm_s3);
      jv2[k] = jv1[k];
      jv1[k] = v;
      if (out_of_travel.empty() && !(j[k] >= lim[k].min_mm && j[k] <= lim[k].max_mm)) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "joint %s at %.3f, outside its travel [%g, %g], at line %d", lim[k].name.c_str(),
                      j[k], lim[k].min_mm, lim[k].max_mm, line);
        out_of_travel = buf;
      }
    }
    j_prev = j;
  };
  auto account = [&](const std::array<double, cnc::program::kMaxAxes>& p) {
    for (int a = 0; a < naxes; ++a) {
      const double v = (p[a] - p_prev[a]) / T;
      const double acc = (v - v1[a]) / T;
      const double jerk = (v - 2 * v1[a] + v2[a]) / (T * T);
      use_v[a] = std::max(use_v[a], std::fabs(v) / cfg.axes[a].max_velocity_mm_s);
      use_a[a] = std::max(use_a[a], std::fabs(acc) / cfg.axes[a].max_accel_mm_s2);
      use_j[a] = std::max(use_j[a], std::fabs(jerk) / cfg.axes[a].max_jerk_mm_s3);
      v2[a] = v1[a];
      v1[a] = v;
    }
    p_prev = p;
  };
  // --with-kind: each submitted block's kind, until the setpoints are past it.
  std::map<int64_t, cnc::program::BlockKind> kinds;
  while (core.state() != cnc::interp::RunState::kDone && cycles < max_cycles) {
    if (cnc::util::stop_requested()) {  // SIGTERM / SIGINT: end here, the CSV holds what was computed
      std::fprintf(stderr, "cnc-plan: stopped by signal %d after %" PRId64 " cycles\n", cnc::util::stop_signal(),
                   cycles);
      return 128 + std::max(0, cnc::util::stop_signal());
    }
    // Keep the look-ahead window full, as the live node does, with its feed policy.
    int64_t missing = -1;
    const bool fed = feed.cycle(
        core,
        [&](int64_t index) -> std::unique_ptr<cnc::program::Block> {
          if (index >= num_blocks) return nullptr;
          const cnc::program::Block* b = server.block(index);
          if (b == nullptr) {
            missing = index;
            return nullptr;
          }
          if (with_kind) kinds[index] = b->kind;
          return std::make_unique<cnc::program::Block>(*b);
        },
        [](int64_t) {}, [](int) {});
    std::string failure = core.take_plan_failure();
    if (!fed || missing >= 0 || !failure.empty()) {
      if (failure.empty()) failure = missing >= 0 ? "not served" : core.last_refusal();
      std::fprintf(stderr, "cnc-plan: block %" PRId64 " refused by the interpolator: %s\n",
                   missing >= 0 ? missing : core.next_block_index(), failure.c_str());
      return 1;
    }
    const cnc::interp::Setpoint& sp = core.step();
    ++cycles;
    max_feed = std::max(max_feed, sp.feed_mm_per_min);
    account(sp.position_mm);
    if (five_axis) {
      if (!kin->inverse(sp.position_mm, joints) && out_of_travel.empty())
        out_of_travel = "no pose of the machine at line " + std::to_string(sp.source_line);
      account_joints(joints, sp.source_line);
    }
    if (csv) {
      std::fprintf(csv.get(), "%" PRId64 ",%.6f,%.9f,%.9f,%.9f,%d,%.9f,%.6f,%s", sp.cycle,
                   static_cast<double>(sp.cycle) * cfg.ipo_period_s, sp.position_mm[0],
                   sp.num_axes > 1 ? sp.position_mm[1] : 0.0, sp.num_axes > 2 ? sp.position_mm[2] : 0.0,
                   sp.source_line, sp.u, sp.feed_mm_per_min, cnc::interp::to_string(sp.limit));
      if (five_axis)
        for (int j = 0; j < kin->joints(); ++j) std::fprintf(csv.get(), ",%.9f", joints[static_cast<size_t>(j)]);
      if (with_kind) {
        const auto k = kinds.find(sp.block_index);
        std::fprintf(csv.get(), ",%s", k == kinds.end() ? "?" : cnc::program::to_string(k->second));
        kinds.erase(kinds.begin(), kinds.lower_bound(sp.block_index));
      }
      std::fputs("\n", csv.get());
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  account(p_prev);
  account(p_prev);
  if (five_axis) {
    account_joints(j_prev, 0);
    account_joints(j_prev, 0);
  }
  if (core.state() != cnc::interp::RunState::kDone) {
    std::fprintf(stderr,
                 "cnc-plan: program did not finish within %.0f s of program time (%" PRId64
                 " cycles); the cap is program.dry_run_max_time_s in the machine file\n",
                 cfg.program.dry_run_max_time_s, max_cycles);
    return 1;
  }
  std::printf("program time %.3f s (%" PRId64 " cycles of %.3f ms), %" PRId64 " blocks, peak feed %.1f mm/min, "
              "%.0f setpoints/s computed\n",
              core.program_time_s(), cycles, cfg.ipo_period_s * 1e3, core.blocks_done(), max_feed,
              static_cast<double>(cycles) / std::max(wall, 1e-9));
  std::printf("peak use of the axis limits (finite differences of the setpoints):");
  for (int a = 0; a < naxes; ++a)
    std::printf(" %s v %.3f a %.3f j %.3f;", cfg.axes[a].name.c_str(), use_v[a], use_a[a], use_j[a]);
  std::printf("\n");
  if (five_axis) {
    // The planner limits the axes; the joints' use is reported, not yet planned for.
    std::printf("peak use of the joint limits (%s, finite differences of the joints):", cfg.kinematics.type.c_str());
    for (int a = 0; a < kin->joints(); ++a)
      std::printf(" %s v %.3f a %.3f j %.3f;", kin->joint_limits()[static_cast<size_t>(a)].name.c_str(),
                  juse_v[static_cast<size_t>(a)], juse_a[static_cast<size_t>(a)], juse_j[static_cast<size_t>(a)]);
    std::printf("\n");
    if (!out_of_travel.empty()) {
      std::fprintf(stderr, "cnc-plan: %s: %s\n", program_path.c_str(), out_of_travel.c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-plan", "dry run of a part program: setpoints to CSV, program time",
                          
                          {{"program", "FILE", "the part program"},
                           {"csv", "OUT", "where the setpoint stream goes (CSV)"},
                           {"override", "F", "feed override factor (default 1.0)", true},
                           {"param-update", "LAW", "the parameter update (first_order, taylor2, corrected)"},
                           {"subroutine-path", "DIR:DIR", "where O-word subroutines are looked for"},
                           {"tool-table", "FILE", "the tool table (default: the config's)"},
                           {"start", "X,Y,Z", "where the machine stands, machine coordinates per axis (default: home)"},
                           {"block-delete", "on|off", "the block delete switch: '/' lines skipped when on (default: "
                                                      "program.block_delete)"},
                           {"modes", "OUT", "the modal state after each main-program line (CSV: line, active codes, "
                                            "F, S, tool, work offset X Y Z)"}},
                          {{"show-setup", "", "print the settings programs are interpreted with, then exit"},
                           {"with-kind", "", "a last CSV column: the kind of the setpoint's block (rapid, line, "
                                             "arc_cw, ...)"}}};
  spec.applies_kinematics = true;
  return cnc::service::run(spec, argc, argv, run_plan);
}
