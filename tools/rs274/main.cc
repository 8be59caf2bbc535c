// cnc-rs274: the project's RS274NGC interpreter, printing its canonical calls in the
// format of LinuxCNC's standalone interpreter rs274, for the conformance harness
// (tools/conformance). Flags as rs274's where they matter:
//   cnc-rs274 [-g] [-i INI] [-t TOOLTABLE] [-v VARFILE] [-b] [--subroutine-path D:D]
//             [--table-units inch|mm] [--axes XYZABCUVW] [--machine M] PROGRAM [OUT]
// Exit status 0 when the program ran to its end, 1 on an interpreter error (the
// message on stderr as "file:line:column: what", then the offending line), 2 on bad
// flags (util/cli.h). --machine: a machine file whose kinematics G53.1 turns the tool
// with (the tilted work plane's 3+2 programs). --subroutine-path overrides the INI file's SUBROUTINE_PATH. Like rs274, lengths in the tool table and var file are read as inches unless
// --table-units mm.
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/rs274/canon_printer.h"
#include "common/rs274/interpreter.h"
#include "common/util/cli.h"
#include "services/part_program_server/program_server.h"

namespace {

std::vector<std::string> split_path(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string d;
  while (std::getline(ss, d, ':'))
    if (!d.empty()) out.push_back(d);
  return out;
}

// A key of a section of a LinuxCNC INI file ([RS274NGC] SUBROUTINE_PATH,
// DISABLE_FANUC_STYLE_SUB; [AXIS_A] WRAPPED_ROTARY); empty when absent. As LinuxCNC's IniFile, which reads
// with fgets(line, LINELEN + 1): a line longer than 255 characters is cut there and
// its rest read as a line of its own (so a long SUBROUTINE_PATH loses its tail).
std::string ini_value(const std::string& ini, const std::string& wanted_section, const std::string& wanted,
                      bool* cut = nullptr) {
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
      if (section != wanted_section || eq == std::string::npos) continue;
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

}  // namespace

int main(int argc, char** argv) {
  cnc::rs274::MachineSetup setup;
  setup.axes = "XYZABCUVW";
  setup.machine_units = cnc::rs274::Units::kInch;  // rs274's reading of table and var file
  setup.block_delete = false;                      // rs274's default; -b toggles
  std::string program, out_path, sub_path, ini, table_units = "inch", ignored;
  int block_delete = 0, ignored_flags = 0;
  CLI::App app{"the project's RS274NGC interpreter, printing rs274's canonical calls", "cnc-rs274"};
  cnc::util::cli::setup(app);
  app.add_flag("-g", ignored_flags, "ignored (rs274's graphical mode)");
  app.add_option("-i", ini,
                 "LinuxCNC INI file: [RS274NGC] SUBROUTINE_PATH, DISABLE_FANUC_STYLE_SUB, REMAP=M6 ngc=, ORIENT_OFFSET, "
                 "[AXIS_A/B/C] WRAPPED_ROTARY")
      ->type_name("INI");
  app.add_option("-t", setup.tool_table, "tool table")->type_name("TOOLTABLE");
  app.add_option("-v", setup.var_file, "parameter (var) file")->type_name("VARFILE");
  app.add_flag("-b", block_delete, "toggle block delete (off by default; each -b toggles)");
  app.add_option("-n", ignored, "ignored (rs274's tool-change mode)");
  app.add_flag("-s", ignored_flags, "ignored (rs274's silent mode)");
  app.add_option("--subroutine-path", sub_path, "where O-word subroutines are looked for (overrides the INI's)")
      ->type_name("DIR:DIR");
  app.add_option("--table-units", table_units, "lengths of the tool table and var file")
      ->check(CLI::IsMember({"inch", "mm"}));
  app.add_option("--axes", setup.axes, "the machine's axes");
  app.add_flag("--probe", setup.has_probe, "G38.x accepted: the probe at each move's end, not tripped (as rs274)");
  app.add_flag("--spindle-sync", setup.spindle_sync, "G33, G33.1, G76 and M19 accepted (a spindle with an encoder)");
  // rs274's simulated machine answers every M66 (WAIT never fails there); 64 is the
  // most LinuxCNC's motion module has (EMCMOT_MAX_DIO, EMCMOT_MAX_AIO).
  setup.digital_inputs = setup.analog_inputs = 64;
  app.add_option("--inputs", setup.digital_inputs, "M66 P inputs (default 64; #5399 as rs274 reads it)");
  app.add_option("--analog-inputs", setup.analog_inputs, "M66 E inputs (default 64)");
  std::string machine_file;
  app.add_option("--machine", machine_file, "a machine file: G53.1 orients the tool through its kinematics")
      ->type_name("M");
  app.add_option("program", program, "the RS274NGC program")->required()->type_name("PROGRAM");
  app.add_option("out", out_path, "where the canonical calls go (default: stdout)")->type_name("OUT");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  if (block_delete % 2 == 1) setup.block_delete = !setup.block_delete;
  setup.machine_units = table_units == "mm" ? cnc::rs274::Units::kMm : cnc::rs274::Units::kInch;
  const bool have_ini = !ini.empty();
  if (have_ini) {
    bool cut = false;
    const std::string ini_path = ini_value(ini, "RS274NGC", "SUBROUTINE_PATH", &cut);
    if (cut)
      std::fprintf(stderr, "cnc-rs274: %s: the SUBROUTINE_PATH line is longer than 255 characters; "
                   "as LinuxCNC, only \"%s\" is read\n", ini.c_str(), ini_path.c_str());
    if (sub_path.empty()) sub_path = ini_path;
    // LinuxCNC's findBoolV: 1/0, true/false, yes/no, on/off (any case).
    auto yes = [&](const std::string& section, const std::string& key) {
      std::string v = ini_value(ini, section, key);
      for (char& c : v) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      return v == "1" || v == "true" || v == "yes" || v == "on";
    };
    setup.fanuc_subs = !yes("RS274NGC", "DISABLE_FANUC_STYLE_SUB");
    if (const std::string v = ini_value(ini, "RS274NGC", "ORIENT_OFFSET"); !v.empty())
      setup.orient_offset_deg = std::strtod(v.c_str(), nullptr);
    // REMAP=M6 ... ngc=NAME (an ngc body; a Python prolog or epilog is not read).
    const std::string remap = ini_value(ini, "RS274NGC", "REMAP");
    if (remap.rfind("M6 ", 0) == 0 || remap.rfind("m6 ", 0) == 0) {
      const size_t at = remap.find("ngc=");
      if (at != std::string::npos) setup.m6_remap = remap.substr(at + 4, remap.find_first_of(" \t", at) - at - 4);
    }
    for (const char* a : {"A", "B", "C"})
      if (yes(std::string("AXIS_") + a, "WRAPPED_ROTARY")) setup.wrapped += a;
  }
  setup.subroutine_path = split_path(sub_path);
  if (!machine_file.empty()) {
    try {
      setup.orient_tool = cnc::pps::program_setup(cnc::config::load_machine_config(machine_file)).machine.orient_tool;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "cnc-rs274: %s\n", e.what());
      return 2;
    }
  }
  std::FILE* out = stdout;
  if (!out_path.empty()) {
    out = std::fopen(out_path.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "cnc-rs274: cannot write %s: %s\n", out_path.c_str(), std::strerror(errno));
      return 1;
    }
    // 1 MiB writes, not stdio's 4 KiB: a 10-million-line program's canon is 1 GB.
    std::setvbuf(out, nullptr, _IOFBF, 1 << 20);
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
