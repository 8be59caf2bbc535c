// The dry run is the machine (issue 32): on every shipped machine file, the dry run's
// program server (cnc-plan, which the HMI's preview runs: dry_run_setup) and the cell's
// (program_setup, as cnc-program-server builds it) accept and refuse the same programs
// with the same words, and serve the same blocks, byte for byte as they go on the bus;
// for programs that touch what a machine file switches on or off (a probe, inputs and
// outputs, the spindle, tools, parameters, rotary axes, travel, block delete, the
// G64 fit). And the dry run never writes the machine's files: a G10 that the cell
// writes to the tool table and the var file leaves them as they were.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unistd.h>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/program/block_msg.h"
#include "services/part_program_server/program_server.h"

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
};

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
