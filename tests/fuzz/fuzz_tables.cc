// libFuzzer target: the files the program server reads at start and writes back, in
// LinuxCNC's formats, the tool table (common/rs274/tool_table.h) and the var file of
// persistent parameters (common/rs274/parameters.h). Byte 0 chooses the file; the
// rest is its text. Either the reader refuses it with an Error that names the file and
// the line ("path:line:column: ..."), or every value it took is finite and writing
// the table back, reading that and writing again gives the same text (a table written
// once stays as it is through restarts).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>

#include "common/rs274/lexer.h"
#include "common/rs274/parameters.h"
#include "common/rs274/tool_table.h"

namespace {
using namespace cnc::rs274;

const std::string& dir() {
  static const std::string d = [] {
    const char* t = std::getenv("TMPDIR");
    return std::string(t != nullptr && *t != '\0' ? t : "/tmp") + "/fuzz_tables." + std::to_string(::getpid());
  }();
  return d;
}

void put(const std::string& path, const uint8_t* p, size_t n) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n));
  if (!out) std::abort();
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A refusal names the file and a line number.
void check_refusal(const Error& e, const std::string& path) {
  const std::string what = e.what();
  if (what.compare(0, path.size() + 1, path + ":") != 0 || e.where().line < 1) {
    std::fprintf(stderr, "refusal without the place: %s\n", what.c_str());
    std::abort();
  }
}

void tool_table(const std::string& in, const uint8_t* p, size_t n) {
  put(in, p, n);
  ToolTable t;
  try {
    t.read(in);
  } catch (const Error& e) {
    check_refusal(e, in);
    return;
  }
  for (const Tool& tool : t.tools()) {
    bool finite = std::isfinite(tool.diameter) && std::isfinite(tool.front_angle) && std::isfinite(tool.back_angle);
    for (double v : tool.offset) finite = finite && std::isfinite(v);
    if (!finite) {
      std::fprintf(stderr, "tool %d read with a value that is not finite\n", tool.number);
      std::abort();
    }
  }
  const std::string a = in + ".a", b = in + ".b";
  write_tool_table(a, t.tools());
  ToolTable again;
  again.read(a);  // what we wrote we read: a throw here is a find
  if (again.tools().size() != t.tools().size()) std::abort();
  write_tool_table(b, again.tools());
  if (slurp(a) != slurp(b)) {
    std::fprintf(stderr, "the tool table changed between two writes:\n%s---\n%s", slurp(a).c_str(), slurp(b).c_str());
    std::abort();
  }
}

void var_file(const std::string& in, const uint8_t* p, size_t n) {
  put(in, p, n);
  Parameters params;
  try {
    params.read_var_file(in);
  } catch (const Error& e) {
    check_refusal(e, in);
    return;
  }
  const std::string a = in + ".a", b = in + ".b";
  params.write_var_file(a);
  Parameters again;
  again.read_var_file(a);
  for (int i = 1; i <= kMaxParameter; ++i) {
    if (params.persistent(i) != again.persistent(i)) std::abort();
    const double v = params.get(i);
    if (!std::isfinite(v)) std::abort();
    if (params.persistent(i) && again.get(i) != v) {
      std::fprintf(stderr, "#%d read back as %.17g, written %.17g\n", i, again.get(i), v);
      std::abort();
    }
  }
  again.write_var_file(b);
  if (slurp(a) != slurp(b)) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static const bool made = [] {
    const bool ok = ::mkdir(dir().c_str(), 0700) == 0 || errno == EEXIST;
    // The folder goes with the process (the suite's replay runs it at every test run).
    std::atexit([] {
      for (const char* f : {"/tbl", "/tbl.a", "/tbl.b", "/var", "/var.a", "/var.b"}) std::remove((dir() + f).c_str());
      ::rmdir(dir().c_str());
    });
    return ok;
  }();
  if (!made) std::abort();
  if (data[0] & 1) {
    var_file(dir() + "/var", data + 1, size - 1);
  } else {
    tool_table(dir() + "/tbl", data + 1, size - 1);
  }
  return 0;
}
