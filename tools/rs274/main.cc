// cnc-rs274: the project's RS274NGC interpreter, printing its canonical calls in the
// format of LinuxCNC's standalone interpreter rs274, for the conformance harness
// (tools/conformance). Flags as rs274's where they matter:
//   cnc-rs274 [-g] [-i INI] [-t TOOLTABLE] [-v VARFILE] [-b] [--subroutine-path D:D]
//             [--table-units inch|mm] [--axes XYZABCUVW] PROGRAM [OUT]
// Exit status 0 when the program ran to its end, 1 on an interpreter error (the
// message on stderr as "file:line:column: what", then the offending line), 2 on bad
// flags. Like rs274, lengths in the tool table and var file are read as inches unless
// --table-units mm.
#include <cctype>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/rs274/canon_printer.h"
#include "common/rs274/interpreter.h"

namespace {

std::vector<std::string> split_path(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string d;
  while (std::getline(ss, d, ':'))
    if (!d.empty()) out.push_back(d);
  return out;
}

// A key of the [RS274NGC] section of a LinuxCNC INI file (SUBROUTINE_PATH,
// DISABLE_FANUC_STYLE_SUB); empty when absent. As LinuxCNC's IniFile, which reads
// with fgets(line, LINELEN + 1): a line longer than 255 characters is cut there and
// its rest read as a line of its own (so a long SUBROUTINE_PATH loses its tail).
std::string ini_rs274ngc(const std::string& ini, const std::string& wanted, bool* cut = nullptr) {
  constexpr size_t kLineLen = 255;
  std::ifstream in(ini);
  std::string physical, section;
  while (std::getline(in, physical)) {
    for (size_t at = 0; at == 0 || at < physical.size(); at += kLineLen) {
      const std::string line = physical.substr(at, kLineLen);
      const size_t b = line.find_first_not_of(" \t");
      if (b == std::string::npos || line[b] == '#' || line[b] == ';') continue;
      if (line[b] == '[') {
        section = line.substr(b + 1, line.find(']') - b - 1);
        continue;
      }
      const size_t eq = line.find('=');
      if (section != "RS274NGC" || eq == std::string::npos) continue;
      std::string key = line.substr(b, eq - b);
      while (!key.empty() && (key.back() == ' ' || key.back() == '\t')) key.pop_back();
      if (key != wanted) continue;
      std::string v = line.substr(eq + 1);
      v.erase(0, v.find_first_not_of(" \t"));
      while (!v.empty() && (v.back() == ' ' || v.back() == '\t' || v.back() == '\r')) v.pop_back();
      if (cut != nullptr) *cut = physical.size() > kLineLen;
      return v;
    }
  }
  return {};
}

int usage(const char* why) {
  std::fprintf(stderr, "cnc-rs274: %s\nusage: cnc-rs274 [-g] [-i INI] [-t TOOLTABLE] [-v VARFILE] [-b] "
               "[--subroutine-path DIR:DIR] [--table-units inch|mm] [--axes XYZABCUVW] PROGRAM [OUT]\n", why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::rs274::MachineSetup setup;
  setup.axes = "XYZABCUVW";
  setup.machine_units = cnc::rs274::Units::kInch;  // rs274's reading of table and var file
  setup.block_delete = false;                      // rs274's default; -b toggles
  std::string program, out_path, sub_path;
  bool have_ini = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "-g") continue;
      if (a == "-b") setup.block_delete = !setup.block_delete;
      else if (a == "-i") {
        const std::string ini = next();
        bool cut = false;
        sub_path = ini_rs274ngc(ini, "SUBROUTINE_PATH", &cut);
        if (cut)
          std::fprintf(stderr, "cnc-rs274: %s: the SUBROUTINE_PATH line is longer than 255 characters; "
                       "as LinuxCNC, only \"%s\" is read\n", ini.c_str(), sub_path.c_str());
        // LinuxCNC's findBoolV: 1/0, true/false, yes/no, on/off (any case).
        std::string v = ini_rs274ngc(ini, "DISABLE_FANUC_STYLE_SUB");
        for (char& c : v) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        setup.fanuc_subs = !(v == "1" || v == "true" || v == "yes" || v == "on");
        have_ini = true;
      }
      else if (a == "-t") setup.tool_table = next();
      else if (a == "-v") setup.var_file = next();
      else if (a == "--subroutine-path") sub_path = next();
      else if (a == "--axes") setup.axes = next();
      else if (a == "--table-units") {
        const std::string u = next();
        if (u != "inch" && u != "mm") return usage("--table-units takes inch or mm");
        setup.machine_units = u == "mm" ? cnc::rs274::Units::kMm : cnc::rs274::Units::kInch;
      } else if (a == "-n" || a == "-s") {
        if (a == "-n") next();
      } else if (!a.empty() && a[0] == '-') return usage(("unknown flag " + a).c_str());
      else if (program.empty()) program = a;
      else if (out_path.empty()) out_path = a;
      else return usage("too many arguments");
    } catch (const std::exception& e) {
      return usage(e.what());
    }
  }
  if (program.empty()) return usage("no program given");
  setup.subroutine_path = split_path(sub_path);
  std::FILE* out = stdout;
  if (!out_path.empty()) {
    out = std::fopen(out_path.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "cnc-rs274: cannot write %s: %s\n", out_path.c_str(), std::strerror(errno));
      return 1;
    }
  }
  const cnc::rs274::Interpreter* interp_ptr = nullptr;
  static const std::string kEmpty;
  cnc::rs274::CanonPrinter printer(out, [&]() -> const std::string& {
    return interp_ptr ? interp_ptr->current_text() : kEmpty;
  });
  int status = 0;
  {
    cnc::rs274::Interpreter interp(setup, printer);
    interp_ptr = &interp;
    try {
      interp.open(program);
      while (interp.execute_next()) {
      }
    } catch (const cnc::rs274::Error& e) {
      std::fprintf(stderr, "%s\n%s\n", e.what(), interp.current_text().c_str());
      status = 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s\n", e.what());
      status = 1;
    }
    // rs274 resets once when it exits, and once more when it ran without an INI file.
    interp_ptr = nullptr;  // rs274's closing resets carry no block's N word
    const cnc::rs274::SourceRef r{};
    printer.on_reset(r);
    if (!have_ini) printer.on_reset(r);
  }
  if (out != stdout) std::fclose(out);
  return status;
}
