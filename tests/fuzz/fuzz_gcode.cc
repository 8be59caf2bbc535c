// libFuzzer target: a G-code program through the RS274NGC interpreter (lexer,
// expressions, O-words, canned cycles, cutter compensation) and the block builder,
// as tests/unit/program_test_util.h runs one (the server's path without its chunks).
// Bad programs must end in rs274::Error (file:line:column); anything else escaping,
// or a sanitizer report, is a finding.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

#include "common/program/block.h"
#include "common/rs274/block_builder.h"
#include "common/rs274/interpreter.h"

namespace {
// Bounds that keep one input fast (a WHILE loop or M98 L1000000 never ends otherwise).
constexpr int64_t kMaxLines = 20000;
constexpr int64_t kMaxBlocks = 20000;

const std::string& program_path() {
  static const std::string p = "/tmp/cnc_fuzz_gcode_" + std::to_string(::getpid()) + ".ngc";
  return p;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace cnc;
  const std::string& path = program_path();
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) return 0;
    if (size > 0) std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  rs274::BuilderSetup bs;
  bs.axis_names = {"X", "Y", "Z"};
  bs.start_position_mm = {0, 0, 0};
  rs274::MachineSetup m;
  m.axes = "XYZ";
  std::unique_ptr<rs274::Interpreter> interp;
  rs274::BlockBuilder builder(
      bs, [&interp](int32_t f) -> const std::string& { return interp->file_names()[static_cast<size_t>(f)]; });
  try {
    interp = std::make_unique<rs274::Interpreter>(m, builder);
    interp->open(path);
    int64_t blocks = 0;
    for (;;) {
      const bool more = interp->execute_next();
      blocks += static_cast<int64_t>(builder.blocks().size());
      builder.blocks().clear();
      if (!more || interp->lines_executed() > kMaxLines || blocks > kMaxBlocks) break;
    }
  } catch (const rs274::Error&) {
    // A refused program: the error names file, line and column.
  }
  return 0;
}
