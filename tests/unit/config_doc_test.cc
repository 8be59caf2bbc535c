// docs/config.md against the readers' tables of known keys: every key the machine
// config reader and the drive profile reader accept is documented, and every
// documented key exists. A key's row in docs/config.md is a table row whose first
// cell is the key's dotted path in backticks; `<!-- config-keys: machine -->` and
// `<!-- config-keys: drive-profile -->` say which reader the rows after it belong to.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "common/config/machine_config.h"
#include "common/drive/drive_profile.h"

namespace cnc {
namespace {

const std::string kDoc = std::string(CNC_SOURCE_DIR) + "/docs/config.md";

// Documented keys per reader ("machine", "drive-profile"), each with its line.
std::map<std::string, std::map<std::string, int>> documented_keys() {
  std::ifstream in(kDoc);
  EXPECT_TRUE(in.good()) << "cannot open " << kDoc;
  const std::regex marker(R"(<!--\s*config-keys:\s*([a-z-]+)\s*-->)");
  const std::regex row(R"(^\|\s*`([^`]+)`\s*\|)");
  std::map<std::string, std::map<std::string, int>> keys;
  std::string reader;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    std::smatch m;
    if (std::regex_search(line, m, marker)) {
      reader = m[1];
    } else if (!reader.empty() && std::regex_search(line, m, row)) {
      EXPECT_TRUE(keys[reader].emplace(m[1], n).second) << kDoc << ":" << n << ": " << m[1] << " documented twice";
    }
  }
  return keys;
}

// The machine config's leaf keys: every key of every table that is not itself a mapping.
std::set<std::string> machine_keys() {
  std::set<std::string> sections;
  for (const auto& s : config::machine_config_keys()) sections.insert(std::string(s.path));
  std::set<std::string> leaves;
  for (const auto& s : config::machine_config_keys()) {
    for (const std::string_view k : s.keys) {
      const std::string full = s.path.empty() ? std::string(k) : std::string(s.path) + "." + std::string(k);
      if (sections.count(full) == 0 && sections.count(full + "[]") == 0) leaves.insert(full);
    }
  }
  return leaves;
}

// A profile's keys: its top level, `registers.<role>`, `registers.*.<field key>` and `huanyang.<key>`.
std::set<std::string> profile_keys() {
  std::set<std::string> keys;
  for (const std::string_view k : drive::drive_profile_keys())
    if (k != "registers" && k != "huanyang") keys.insert(std::string(k));
  for (const std::string_view k : drive::drive_profile_register_keys()) keys.insert("registers." + std::string(k));
  for (const std::string_view k : drive::drive_profile_field_keys()) keys.insert("registers.*." + std::string(k));
  for (const std::string_view k : drive::drive_profile_huanyang_keys()) keys.insert("huanyang." + std::string(k));
  return keys;
}

void expect_same(const std::string& reader, const std::set<std::string>& accepted,
                 const std::map<std::string, int>& documented) {
  for (const std::string& k : accepted)
    EXPECT_EQ(documented.count(k), 1u) << "the " << reader << " reader accepts `" << k << "`: document it in " << kDoc;
  for (const auto& [k, line] : documented)
    EXPECT_EQ(accepted.count(k), 1u) << kDoc << ":" << line << ": `" << k << "` is not a key the " << reader
                                     << " reader accepts";
}

TEST(ConfigDoc, EveryMachineKeyIsDocumentedAndEveryDocumentedKeyExists) {
  const auto doc = documented_keys();
  ASSERT_EQ(doc.count("machine"), 1u) << "no <!-- config-keys: machine --> rows in " << kDoc;
  expect_same("machine config", machine_keys(), doc.at("machine"));
}

TEST(ConfigDoc, EveryDriveProfileKeyIsDocumentedAndEveryDocumentedKeyExists) {
  const auto doc = documented_keys();
  ASSERT_EQ(doc.count("drive-profile"), 1u) << "no <!-- config-keys: drive-profile --> rows in " << kDoc;
  expect_same("drive profile", profile_keys(), doc.at("drive-profile"));
}

// Each reader asks for every key of its table and reads no other (else std::logic_error):
// run every path, the optional sections (operator, cutting, axes[].home) included.
TEST(ConfigDoc, ReadersKeepToTheirTables) {
  for (const auto& e : std::filesystem::directory_iterator(std::string(CNC_SOURCE_DIR) + "/config/machines")) {
    if (e.path().extension() != ".yaml") continue;
    EXPECT_NO_THROW(config::load_machine_config(e.path().string())) << e.path();
  }
  std::ifstream in(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  std::stringstream text;
  text << in.rdbuf();
  std::string yaml = text.str();
  const std::string axis = "    sim: {bandwidth_hz: 40, damping: 1.0}\n";
  const size_t at = yaml.find(axis);
  ASSERT_NE(at, std::string::npos);
  yaml.insert(at + axis.size(), "    home: {method: switch, direction: -1, switch_position_mm: -4}\n");
  yaml += "operator: {homing_required: true, safe_z_mm: 2}\n";
  const config::MachineConfig c = config::parse_machine_config(yaml, std::string(CNC_SOURCE_DIR) + "/config/machines/x.yaml");
  EXPECT_EQ(c.axes[0].home.method, "switch");
  EXPECT_TRUE(c.operator_.homing_required);
  for (const auto& e : std::filesystem::directory_iterator(std::string(CNC_SOURCE_DIR) + "/config/drives"))
    EXPECT_NO_THROW(drive::load_drive_profile(e.path().string())) << e.path();
}

TEST(ConfigDoc, NoOtherReaderIsNamed) {
  for (const auto& [reader, keys] : documented_keys())
    EXPECT_TRUE(reader == "machine" || reader == "drive-profile") << kDoc << ": unknown reader '" << reader << "'";
}

}  // namespace
}  // namespace cnc
