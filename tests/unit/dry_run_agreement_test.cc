// The dry run is the machine (issue 32): on every shipped machine file, the dry run's
// program server (cnc-plan, which the HMI's preview runs: dry_run_setup) and the cell's
// (program_setup, as cnc-program-server builds it) accept and refuse the same programs
// with the same words, and serve the same blocks, byte for byte as they go on the bus;
// for programs that touch what a machine file switches on or off (a probe, inputs and
// outputs, the spindle, tools, parameters, rotary axes, travel, block delete, the
// G64 fit). The setups themselves compared field by field (describe(): a field added
// to a setup struct does not build until it is described), each program.* setting
// shown to reach the setup, and the settings no shipped file uses (a tool table, a var
// file, subroutines, M6 remapped, the switches off) checked on a variant of sim3. And
// the dry run never writes the machine's files: a G10 that the cell writes to the tool
// table and the var file leaves them as they were.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <set>
#include <sstream>
#include <unistd.h>
#include <string>
#include <vector>

#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/program/block_msg.h"
#include "services/part_program_server/program_server.h"
#include "services/part_program_server/program_server_node.h"

namespace {
namespace fs = std::filesystem;
using cnc::pps::LoadResult;
using cnc::pps::ProgramServer;

struct Program {
  const char* name;
  const char* text;
};

// Each touches one thing a machine file decides.
const Program kPrograms[] = {
    {"lines_arcs", "G21 G90 G17\nG0 X10 Y10 Z5\nG1 X20 F600\nG2 X30 Y20 R10\nG3 X20 Y30 I-10 J0\nM2\n"},
    {"probe", "G21 G90\nG0 Z5\nG38.2 Z-5 F100\nG0 Z5\nG38.3 X5 F200\nM2\n"},
    {"inputs", "G21 G90\nM66 P0 L3 Q1\nG0 X1\nM66 E0 L0\nM2\n"},
    {"outputs", "G21 G90\nM62 P0\nG1 X5 F300\nM65 P0\nM67 E0 Q2.5\nM68 E0 Q0\nM2\n"},
    {"spindle_coolant", "G21 G90\nM3 S5000\nM8\nG1 X5 F300\nM7\nM9\nM4 S2000\nM5\nM2\n"},
    {"tools", "G21 G90\nT1 M6\nG43 H1\nG0 Z10\nG10 L1 P1 Z5\nG49\nM2\n"},
    {"parameters", "G21 G90\n#1 = [#5220 + 1]\n#<_shift> = 2\nG10 L2 P1 X1\nG54 G0 X#<_shift>\nG92 Y1\nG92.1\nM2\n"},
    {"travel", "G21 G90\nG0 X100000\nM2\n"},
    {"rotary", "G21 G90\nG0 A90\nG1 A180 F3600\nM2\n"},
    {"block_delete_optional_stop", "G21 G90\n/G0 X1\nM1\nG0 X2\nM0\nM2\n"},
    {"subroutine", "G21 G90\no<no_such_sub> call\nM2\n"},
    {"fit", "G21 G90 G64 P0.01\nG1 X1 Y0.01 F1000\nG1 X2 Y0.03\nG1 X3 Y0.02\nG1 X4 Y0.05\nG1 X5 Y0\nM2\n"},
    {"feed_modes", "G21 G90\nG93 G1 X10 F2\nG94 G1 X0 F500\nM3 S1000\nG95 G1 X5 F0.1\nM5\nM2\n"},
    {"thread", "G21 G90\nM3 S300\nG0 X10 Z5\nG33 Z-10 K1.5\nG0 X20\nM5\nM2\n"},
    {"orient", "G21 G90\nM3 S500\nG0 X5\nM19 R45\nM5\nM2\n"},
};

// Who must accept what: a program that needs a setting is accepted where the machine
// file gives it and refused where it does not (so the comparison above is not vacuous).
struct Expectation {
  const char* program;
  const char* machine;
  bool accepted;
};
const Expectation kExpected[] = {
    {"probe", "sim3_probe.yaml", true},       {"probe", "sim3_machine.yaml", true},
    {"probe", "sim3.yaml", false},            {"probe", "sim3_io.yaml", false},
    {"inputs", "sim3_io.yaml", true},         {"inputs", "sim3_guarded.yaml", true},
    {"inputs", "sim3.yaml", false},           {"thread", "sim3_servo_spindle.yaml", true},
    {"thread", "sim3.yaml", false},           {"thread", "sim3_spindle.yaml", false},
    {"orient", "sim3_servo_spindle.yaml", true}, {"orient", "sim3_huanyang.yaml", false},
    {"rotary", "sim4_rotary.yaml", true},     {"rotary", "sim3.yaml", false},
    {"travel", "sim3.yaml", false},           {"lines_arcs", "sim3.yaml", true},
};

// describe()'s lines as key -> value.
std::map<std::string, std::string> fields(const std::string& description) {
  std::map<std::string, std::string> out;
  std::istringstream in(description);
  for (std::string line; std::getline(in, line);) {
    const size_t eq = line.find(" = ");
    if (eq != std::string::npos) out[line.substr(0, eq)] = line.substr(eq + 3);
  }
  return out;
}

std::string encoded(const cnc::program::Block& b) {
  cnc::lcmt_program_block m = cnc::program::to_msg(b, 1);
  std::string bytes(static_cast<size_t>(m.getEncodedSize()), '\0');
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

class DryRunAgreement : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("cnc-dry-run-agreement." + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

TEST_F(DryRunAgreement, EveryShippedMachineFileAcceptsRefusesAndServesAlike) {
  int files = 0, accepted = 0, refused = 0;
  int64_t blocks = 0;
  std::map<std::pair<std::string, std::string>, bool> outcome;  // (program, machine file) -> accepted
  for (const auto& e : fs::directory_iterator(fs::path(CNC_SOURCE_DIR) / "config" / "machines")) {
    if (e.path().extension() != ".yaml") continue;
    const cnc::config::MachineConfig cfg = cnc::config::load_machine_config(e.path().string());
    ++files;
    for (const Program& p : kPrograms) {
      const std::string what = e.path().filename().string() + ", " + p.name;
      const fs::path file = write(std::string(p.name) + ".ngc", p.text);
      ProgramServer cell(cnc::pps::program_setup(cfg), {});
      ProgramServer dry(cnc::pps::dry_run_setup(cfg), {});
      const LoadResult a = cell.load(file.string(), 1);
      const LoadResult b = dry.load(file.string(), 1);
      ASSERT_EQ(a.ok, b.ok) << what << ": the cell says '" << a.error << "', the dry run '" << b.error << "'";
      EXPECT_EQ(a.error, b.error) << what;
      EXPECT_EQ(a.warnings, b.warnings) << what;
      outcome[{p.name, e.path().filename().string()}] = a.ok;
      if (!a.ok) {
        ++refused;
        continue;
      }
      ++accepted;
      ASSERT_EQ(cell.num_blocks(), dry.num_blocks()) << what;
      for (int64_t i = 0; i < cell.num_blocks(); ++i) {
        const cnc::program::Block* x = cell.block(i);
        ASSERT_NE(x, nullptr) << what << ": block " << i << ": " << cell.serving_error();
        const std::string ex = encoded(*x);
        const cnc::program::Block* y = dry.block(i);
        ASSERT_NE(y, nullptr) << what << ": block " << i << ": " << dry.serving_error();
        EXPECT_EQ(ex, encoded(*y)) << what << ": block " << i << " differs";
        ++blocks;
      }
    }
  }
  std::printf("[ figures  ] %d machine files x %zu programs: %d accepted alike, %d refused alike, %lld blocks "
              "identical\n", files, std::size(kPrograms), accepted, refused, static_cast<long long>(blocks));
  EXPECT_GE(files, 10);
  EXPECT_GT(accepted, 0);
  EXPECT_GT(refused, 0);
  for (const Expectation& x : kExpected) {
    const auto it = outcome.find({x.program, x.machine});
    ASSERT_NE(it, outcome.end()) << x.program << " on " << x.machine << " was not run";
    EXPECT_EQ(it->second, x.accepted) << x.program << " on " << x.machine;
  }
}

// The setup the program server builds (the node, as cnc-program-server runs it) and
// the dry run's, field by field: they differ only in that the dry run never writes the
// machine's files.
TEST_F(DryRunAgreement, TheCellsSetupIsTheDryRunsFieldByField) {
  int files = 0;
  size_t compared = 0;
  for (const auto& e : fs::directory_iterator(fs::path(CNC_SOURCE_DIR) / "config" / "machines")) {
    if (e.path().extension() != ".yaml") continue;
    const cnc::config::MachineConfig cfg = cnc::config::load_machine_config(e.path().string());
    ++files;
    cnc::bus::Bus bus("memq://", 77);
    const cnc::pps::ProgramServerNode node(cfg, bus);
    const auto cell = fields(cnc::pps::describe(node.setup()));
    const auto dry = fields(cnc::pps::describe(cnc::pps::dry_run_setup(cfg)));
    ASSERT_EQ(cell.size(), dry.size()) << e.path();
    for (const auto& [key, value] : cell) {
      const auto it = dry.find(key);
      ASSERT_NE(it, dry.end()) << e.path() << ": " << key;
      if (key == "machine.write_var_file") {
        EXPECT_EQ(value, "true") << e.path();
        EXPECT_EQ(it->second, "false") << e.path();
      } else {
        EXPECT_EQ(value, it->second) << e.path().filename() << ": " << key << ": the cell's " << value
                                     << ", the dry run's " << it->second;
      }
      ++compared;
    }
  }
  std::printf("[ figures  ] %d machine files: %zu fields compared, the cell's and the dry run's alike but "
              "machine.write_var_file\n", files, compared);
  EXPECT_GE(files, 10);
}

// Every program.* setting reaches the interpreter's setup (or is named here as one that
// is not the language's): a setting changed from its value in sim3.yaml changes the
// setup's description, the dry run's and the cell's.
TEST_F(DryRunAgreement, EveryProgramSettingReachesTheSetup) {
  const cnc::config::MachineConfig base =
      cnc::config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  const std::string before = cnc::pps::describe(cnc::pps::dry_run_setup(base));
  using Change = std::function<void(cnc::config::MachineConfig&)>;
  std::vector<std::pair<const char*, Change>> changes;
  // Every field of ProgramConfig by name: a new one does not build until it has its
  // change below, or its reason here for having none. dry_run_max_time_s is the dry
  // run's cap on program time, the planner's; optional_stop the interpolator's switch
  // (every M1 is an event, held at when the switch is on).
  [[maybe_unused]] const auto& [subroutine_path, m6_remap, tool_table, var_file, probe, digital_inputs, analog_inputs,
                                digital_outputs, analog_outputs, block_delete, optional_stop, max_validation_lines,
                                dry_run_max_time_s, g64_fit, g64_fit_max_segment_mm, g64_fit_max_segment_per_p,
                                g64_fit_max_turn_deg,
                                default_path_tolerance_mm] = base.program;
  changes.emplace_back("subroutine_path", [](auto& c) { c.program.subroutine_path = {"/nowhere"}; });
  changes.emplace_back("m6_remap", [](auto& c) { c.program.m6_remap = "change"; });
  changes.emplace_back("tool_table", [](auto& c) { c.program.tool_table = "/nowhere.tbl"; });
  changes.emplace_back("var_file", [](auto& c) { c.program.var_file = "/nowhere.var"; });
  changes.emplace_back("probe", [](auto& c) { c.program.probe = !c.program.probe; });
  changes.emplace_back("digital_inputs", [](auto& c) { ++c.program.digital_inputs; });
  changes.emplace_back("analog_inputs", [](auto& c) { ++c.program.analog_inputs; });
  changes.emplace_back("digital_outputs", [](auto& c) { ++c.program.digital_outputs; });
  changes.emplace_back("analog_outputs", [](auto& c) { ++c.program.analog_outputs; });
  changes.emplace_back("block_delete", [](auto& c) { c.program.block_delete = !c.program.block_delete; });
  changes.emplace_back("max_validation_lines", [](auto& c) { c.program.max_validation_lines += 1000; });
  changes.emplace_back("g64_fit", [](auto& c) { c.program.g64_fit = !c.program.g64_fit; });
  changes.emplace_back("g64_fit_max_segment_mm", [](auto& c) { c.program.g64_fit_max_segment_mm += 1; });
  changes.emplace_back("g64_fit_max_segment_per_p", [](auto& c) { c.program.g64_fit_max_segment_per_p += 1; });
  changes.emplace_back("g64_fit_max_turn_deg", [](auto& c) { c.program.g64_fit_max_turn_deg += 1; });
  changes.emplace_back("default_path_tolerance_mm", [](auto& c) { c.program.default_path_tolerance_mm += 0.01; });
  // And the machine's other settings a program meets.
  changes.emplace_back("spindle.encoder_counts_per_rev", [](auto& c) {
    c.spindle.enabled = true;
    c.spindle.encoder_counts_per_rev = 4096;
  });
  changes.emplace_back("axes[0].rotary", [](auto& c) { c.axes[0].rotary = true; });
  changes.emplace_back("axes[0].wrapped", [](auto& c) { c.axes[0].rotary = c.axes[0].wrapped = true; });
  changes.emplace_back("axes[0].max_mm", [](auto& c) { c.axes[0].max_mm += 1; });
  changes.emplace_back("axes[0].home_mm", [](auto& c) { c.axes[0].home_mm += 1; });
  changes.emplace_back("process.spindle_rpm", [](auto& c) { c.process.spindle_rpm += 1; });
  changes.emplace_back("timing.ipo_period_s", [](auto& c) { c.ipo_period_s *= 2; });
  changes.emplace_back("motion.chord_tolerance_mm", [](auto& c) { c.chord_tolerance_mm *= 2; });
  for (const auto& [key, change] : changes) {
    cnc::config::MachineConfig c = base;
    change(c);
    EXPECT_NE(cnc::pps::describe(cnc::pps::dry_run_setup(c)), before) << key << " does not reach the setup";
    cnc::bus::Bus bus("memq://", 77);
    const cnc::pps::ProgramServerNode node(c, bus);
    EXPECT_NE(cnc::pps::describe(node.setup()), before) << key << " does not reach the cell's setup";
  }
  std::printf("[ figures  ] %zu settings each change the setup of both\n", changes.size());
}

// The settings no shipped file uses, on a variant of sim3.yaml: a tool table, a var
// file, a subroutine folder, M6 remapped, block delete off. Each program is accepted
// and served alike by both, and differently from sim3.yaml's (the setting matters).
TEST_F(DryRunAgreement, TheFilesAndSwitchesOfAVariantAgree) {
  const std::string sim3 = slurp(fs::path(CNC_SOURCE_DIR) / "config" / "machines" / "sim3.yaml");
  fs::create_directories(dir_ / "subs");
  write("subs/change.ngc", "o<change> sub\nG53 G0 Z0\nM6\no<change> endsub\nM2\n");
  write("subs/pocket.ngc", "o<pocket> sub\nG1 X[#1 + 5] F500\no<pocket> endsub\nM2\n");
  write("tool.tbl", "T1 P1 Z+10.000000 D+6.000000 ;end mill\n");
  write("params.var", "5221\t7.000000\n");
  std::string variant = sim3;
  // Relative paths: beside the machine file, as the config reads them.
  variant += "\nprogram:\n  tool_table: tool.tbl\n  var_file: params.var\n  subroutine_path: subs\n"
             "  m6_remap: change\n  block_delete: false\n";
  const fs::path variant_file = write("variant.yaml", variant);
  const fs::path sim3_file = write("sim3_copy.yaml", sim3);
  const Program programs[] = {
      {"tool_length", "G21 G90\nT1 M6\nG43 H1\nG0 X1 Z-50\nM2\n"},
      {"work_offset", "G21 G90\nG54 G0 X1 Y1\nM2\n"},
      {"subroutine", "G21 G90\no<pocket> call [10]\nM2\n"},
      {"remapped_m6", "G21 G90\nG0 Z-20\nT1 M6\nG0 X3\nM2\n"},
      {"block_delete_off", "G21 G90\n/G0 X9\nG0 Y2\nM2\n"},
  };
  const auto serve = [](ProgramServer& s, const fs::path& file, std::vector<std::string>* blocks) {
    const LoadResult r = s.load(file.string(), 1);
    for (int64_t i = 0; r.ok && i < s.num_blocks(); ++i) {
      const cnc::program::Block* b = s.block(i);
      if (b == nullptr) {
        LoadResult failed;
        failed.error = "block " + std::to_string(i) + ": " + s.serving_error();
        return failed;
      }
      blocks->push_back(encoded(*b));
    }
    return r;
  };
  for (const Program& p : programs) {
    const fs::path file = write(std::string(p.name) + ".ngc", p.text);
    const cnc::config::MachineConfig cfg = cnc::config::load_machine_config(variant_file.string());
    std::vector<std::string> dry_blocks, cell_blocks, plain_blocks;
    // The dry run first: the cell's run writes the var file and the tool table.
    ProgramServer dry(cnc::pps::dry_run_setup(cfg), {});
    const LoadResult b = serve(dry, file, &dry_blocks);
    cnc::bus::Bus bus("memq://", 77);
    const cnc::pps::ProgramServerNode node(cfg, bus);
    ProgramServer cell(node.setup(), {});
    const LoadResult a = serve(cell, file, &cell_blocks);
    ASSERT_TRUE(a.ok) << p.name << ": " << a.error;
    ASSERT_TRUE(b.ok) << p.name << ": " << b.error;
    EXPECT_EQ(cell_blocks, dry_blocks) << p.name;
    ProgramServer plain(cnc::pps::dry_run_setup(cnc::config::load_machine_config(sim3_file.string())), {});
    const LoadResult c = serve(plain, file, &plain_blocks);
    EXPECT_TRUE(!c.ok || plain_blocks != dry_blocks) << p.name << ": sim3.yaml serves it alike: the setting did nothing";
    std::printf("[ figures  ] %s: %zu blocks alike; on sim3.yaml %s\n", p.name, dry_blocks.size(),
                c.ok ? "other blocks" : ("refused: " + c.error).c_str());
  }
}

TEST_F(DryRunAgreement, TheDryRunNeverWritesTheMachinesFiles) {
  cnc::config::MachineConfig cfg =
      cnc::config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  const fs::path table = write("tool.tbl", "T1 P1 Z+10.000000 D+6.000000 ;end mill\n");
  const fs::path vars = write("params.var", "5220\t1.000000\n5221\t0.000000\n");
  cfg.program.tool_table = table.string();
  cfg.program.var_file = vars.string();
  const fs::path prog = write("touch_off.ngc", "G21 G90\nG10 L1 P1 Z25\nG10 L2 P1 X7\nM2\n");
  const std::string table_before = slurp(table), vars_before = slurp(vars);
  {
    ProgramServer dry(cnc::pps::dry_run_setup(cfg), {});
    ASSERT_TRUE(dry.load(prog.string(), 1).ok);
    for (int64_t i = 0; i < dry.num_blocks(); ++i) ASSERT_NE(dry.block(i), nullptr);
  }
  EXPECT_EQ(slurp(table), table_before);
  EXPECT_EQ(slurp(vars), vars_before);
  // The cell's writes them (so the check above can tell).
  {
    ProgramServer cell(cnc::pps::program_setup(cfg), {});
    ASSERT_TRUE(cell.load(prog.string(), 1).ok);
    for (int64_t i = 0; i < cell.num_blocks(); ++i) ASSERT_NE(cell.block(i), nullptr);
  }
  EXPECT_NE(slurp(table), table_before);
  EXPECT_NE(slurp(vars), vars_before);
}

}  // namespace
