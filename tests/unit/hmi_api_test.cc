// The HMI's API: its action table is the one docs/hmi-api.md shows, and the
// dispatcher answers by that table without any HTTP (over an in-memory bus).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "services/hmi/api.h"
#include "services/hmi/dry_run.h"
#include "services/hmi/programs.h"
#include "tests/hmi_offline_options.h"

using cnc::hmi::Api;
using json = nlohmann::json;

namespace {

const std::string kDoc = std::string(CNC_SOURCE_DIR) + "/docs/hmi-api.md";
const std::string kBegin = "<!-- actions: generated from services/hmi/api.cc -->\n";
const std::string kEnd = "<!-- end of actions -->\n";

// The table as docs/hmi-api.md shows it.
std::string render_table() {
  std::string t = "| action | fields | sends | answers | view only |\n|---|---|---|---|---|\n";
  for (const Api::Action& a : Api::actions())
    t += std::string("| `") + a.name + "` | " + a.fields + " | " + a.sends + " | " + a.answers + " | " +
         (a.view_only ? "yes" : "") + " |\n";
  return t;
}

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The action names of the doc's table (the first cell of each row, between backquotes).
std::set<std::string> doc_actions(const std::string& table) {
  std::set<std::string> names;
  std::istringstream in(table);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("| `", 0) != 0) continue;
    const size_t end = line.find('`', 3);
    if (end != std::string::npos) names.insert(line.substr(3, end - 3));
  }
  return names;
}

}  // namespace

TEST(HmiApiTable, NamesAreUniqueAndHaveHandlers) {
  std::set<std::string> seen;
  for (const Api::Action& a : Api::actions()) {
    EXPECT_TRUE(seen.insert(a.name).second) << a.name << " twice";
    EXPECT_NE(a.handler, nullptr) << a.name;
    EXPECT_EQ(Api::find_action(a.name), &a);
  }
  EXPECT_EQ(Api::find_action("no_such_action"), nullptr);
}

TEST(HmiApiTable, DocShowsTheCodesTable) {
  std::string doc = read_file(kDoc);
  const size_t b = doc.find(kBegin), e = doc.find(kEnd);
  ASSERT_NE(b, std::string::npos) << kDoc << " has no '" << kBegin << "'";
  ASSERT_NE(e, std::string::npos) << kDoc << " has no '" << kEnd << "'";
  ASSERT_LT(b, e);
  const std::string shown = doc.substr(b + kBegin.size(), e - b - kBegin.size());
  const std::string want = render_table();
  if (std::getenv("CNC_WRITE_DOCS") != nullptr && shown != want) {
    doc.replace(b + kBegin.size(), e - b - kBegin.size(), want);
    std::ofstream(kDoc) << doc;
    GTEST_SKIP() << "wrote the actions table into " << kDoc;
  }
  std::set<std::string> code;
  for (const Api::Action& a : Api::actions()) code.insert(a.name);
  const std::set<std::string> docs = doc_actions(shown);
  for (const auto& n : code) EXPECT_TRUE(docs.count(n)) << "action '" << n << "' is missing from " << kDoc;
  for (const auto& n : docs) EXPECT_TRUE(code.count(n)) << kDoc << " documents '" << n << "', which the API does not have";
  EXPECT_EQ(shown, want) << kDoc << "'s table differs from services/hmi/api.cc's (CNC_WRITE_DOCS=1 writes it)";
}

// The dispatcher with no HTTP: a client is a number, its answers are collected.
class HmiApi : public ::testing::Test {
 protected:
  HmiApi()
      : cfg_(cnc::config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml")),
        bus_("memq://") {
    cnc::hmi::Outbox out;
    out.broadcast = [this](const json& j, bool) { broadcast_.push_back(j); };
    out.send_to = [this](uint64_t client, const json& j) {
      EXPECT_EQ(client, 7u);
      sent_.push_back(j);
    };
    const cnc::hmi::ApiOptions opt = cnc::hmi::offline_api_options();
    api_ = std::make_unique<Api>(cfg_, bus_, opt, out);
  }
  ~HmiApi() override { api_->stop(); }
  json last() { return sent_.empty() ? json() : sent_.back(); }

  cnc::config::MachineConfig cfg_;
  cnc::bus::Bus bus_;
  std::unique_ptr<Api> api_;
  std::vector<json> sent_, broadcast_;
};

TEST_F(HmiApi, Hello) {
  api_->open(7, true, "op");
  ASSERT_GE(sent_.size(), 3u);
  EXPECT_EQ(sent_[0]["t"], "hello");
  EXPECT_EQ(sent_[0]["machine"], cfg_.name);
  EXPECT_EQ(sent_[0]["axes"].size(), cfg_.axes.size());
  EXPECT_EQ(sent_[0]["user"], "op");
  EXPECT_EQ(sent_[1]["t"], "program");
  EXPECT_EQ(last()["t"], "alarms");
}

TEST(HmiApiHello, NamesTheRotaryAndWrappedAxes) {
  // The page shows a wrapped axis in [0, 360) (app.js wrap360), as LinuxCNC's displays do.
  auto cfg = cnc::config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  cfg.axes[2].rotary = true;
  cfg.axes[2].wrapped = true;
  cnc::bus::Bus bus("memq://");
  std::vector<json> sent;
  cnc::hmi::Outbox out;
  out.broadcast = [](const json&, bool) {};
  out.send_to = [&](uint64_t, const json& j) { sent.push_back(j); };
  Api api(cfg, bus, cnc::hmi::offline_api_options(), out);
  api.open(7, true, "op");
  ASSERT_FALSE(sent.empty());
  ASSERT_EQ(sent[0]["axes"].size(), cfg.axes.size());
  EXPECT_EQ(sent[0]["axes"][0]["wrapped"], false);
  EXPECT_EQ(sent[0]["axes"][0]["rotary"], false);
  EXPECT_EQ(sent[0]["axes"][2]["wrapped"], true);
  EXPECT_EQ(sent[0]["axes"][2]["rotary"], true);
  api.stop();
}

TEST_F(HmiApi, AnswersByTheTable) {
  api_->message(7, true, R"({"id": 1, "action": "ping"})");
  EXPECT_EQ(last(), (json{{"t", "pong"}, {"id", 1}}));
  api_->message(7, true, "{not json");
  EXPECT_EQ(last()["ok"], false);
  EXPECT_TRUE(last()["id"].is_null());
  EXPECT_EQ(last()["text"].get<std::string>().rfind("not JSON: ", 0), 0u);
  // JSON that is no request (the page never sends it; a script might): answered, nothing thrown.
  for (const char* text : {"[1]", "5", "null", "\"ping\"", R"({"id": 9, "action": 3})"}) {
    sent_.clear();
    EXPECT_NO_THROW(api_->message(7, true, text)) << text;
    ASSERT_EQ(sent_.size(), 1u) << text;
    EXPECT_EQ(last()["ok"], false) << text;
    EXPECT_EQ(last()["text"], "expected an object {\"action\": \"NAME\", ...}") << text;
  }
  EXPECT_EQ(last()["id"], 9);
  api_->message(7, true, R"({"id": 2, "action": "fly"})");
  EXPECT_EQ(last(), (json{{"t", "result"}, {"id", 2}, {"ok", false}, {"text", "unknown action 'fly'"}}));
  api_->message(7, true, R"({"id": 3, "action": "override", "value": "fast"})");
  EXPECT_EQ(last()["text"], "override: 'value' must be a number");
  api_->message(7, true, R"({"id": 4, "action": "jog", "axis": "Q"})");
  EXPECT_EQ(last()["text"], "jog: the machine has no axis \"Q\"");
  api_->message(7, true, R"({"id": 5, "action": "mdi"})");
  EXPECT_EQ(last()["text"], "mdi: no line");
  api_->message(7, true, R"({"id": 6, "action": "load", "path": "../x.ngc"})");
  EXPECT_EQ(last()["text"].get<std::string>().rfind("load refused: ", 0), 0u);
}

TEST_F(HmiApi, ViewOnlyClientsMayOnlyLook) {
  for (const Api::Action& a : Api::actions()) {
    sent_.clear();
    api_->message(7, false, json{{"id", 9}, {"action", a.name}}.dump());
    const bool refused = !sent_.empty() && sent_.back()["text"] == "view only: log in to operate the machine";
    EXPECT_EQ(refused, !a.view_only) << a.name;
  }
  api_->message(7, false, R"({"id": 10, "action": "fly"})");
  EXPECT_EQ(last()["text"], "view only: log in to operate the machine");
}

namespace {

// The preview's dry run (cnc-plan in a child process) as the program server loaded the
// program: with its block delete switch, from where the machine stands.
json preview(bool block_delete, const std::string& program, std::vector<double> start = {}) {
  cnc::hmi::DryRun dry(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml", CNC_PLAN_EXE);
  dry.start(7, program, block_delete, std::move(start));
  for (int i = 0; i < 500; ++i) {
    if (std::string r = dry.take(); !r.empty()) return json::parse(r);
    usleep(20'000);
  }
  return json{};
}

TEST(HmiDryRun, ThePreviewTakesTheServersBlockDeleteSwitch) {
  char dir[] = "/tmp/cnc-hmi-dry-run.XXXXXX";
  ASSERT_NE(mkdtemp(dir), nullptr);
  const std::string program = std::string(dir) + "/slash.ngc";
  std::ofstream(program) << "G21 G90\n/G0 X9\nG0 Y2\nM2\n";
  double x_max[2] = {-1, -1};
  for (bool on : {true, false}) {
    const json p = preview(on, program);
    ASSERT_TRUE(p.contains("points")) << p.dump();
    const auto& pts = p["points"];
    ASSERT_GE(pts.size(), 6u);
    double x = -1e9;
    for (size_t i = 0; i + 2 < pts.size(); i += 3) x = std::max(x, pts[i].get<double>());
    x_max[on ? 1 : 0] = x;
  }
  std::filesystem::remove_all(dir);
  EXPECT_NEAR(x_max[1], 0.0, 1e-9) << "block delete on: the '/' line's X9 is skipped";
  EXPECT_NEAR(x_max[0], 9.0, 1e-9) << "block delete off: the '/' line's X9 is made";
}

TEST(HmiDryRun, ThePreviewStartsWhereTheMachineStands) {
  char dir[] = "/tmp/cnc-hmi-dry-run.XXXXXX";
  ASSERT_NE(mkdtemp(dir), nullptr);
  const std::string program = std::string(dir) + "/incremental.ngc";
  std::ofstream(program) << "G21 G91\nG1 X10 Y-5 F600\nM2\n";
  const json p = preview(true, program, {100.25, 50, -10});
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(p.contains("points")) << p.dump();
  const auto& pts = p["points"];
  ASSERT_GE(pts.size(), 6u);
  // The first point (the first cycle's, a few um on) where the machine stands, the last
  // 10 mm along X and -5 along Y from it.
  EXPECT_NEAR(pts[0].get<double>(), 100.25, 0.01);
  EXPECT_NEAR(pts[1].get<double>(), 50.0, 0.01);
  EXPECT_NEAR(pts[2].get<double>(), -10.0, 1e-9);
  const size_t n = pts.size();
  EXPECT_NEAR(pts[n - 3].get<double>(), 110.25, 1e-9);
  EXPECT_NEAR(pts[n - 2].get<double>(), 45.0, 1e-9);
  EXPECT_NEAR(pts[n - 1].get<double>(), -10.0, 1e-9);
}

// A program the dry run refuses: the preview says why and where, in the dry run's words.
TEST(HmiDryRun, ARefusalNamesThePlace) {
  char dir[] = "/tmp/cnc-hmi-dry-run.XXXXXX";
  ASSERT_NE(mkdtemp(dir), nullptr);
  const std::string program = std::string(dir) + "/incremental.ngc";
  std::ofstream(program) << "G21 G91\nG1 X10 Y-5 F600\nM2\n";
  const json p = preview(true, program, {395, 50, -10});
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(p.contains("error")) << p.dump();
  const std::string e = p["error"].get<std::string>();
  EXPECT_NE(e.find("incremental.ngc:2:1: X 405.0000 mm (machine coordinates, the block's end) is outside the axis's "
                   "travel [-5, 400]"),
            std::string::npos)
      << e;
  EXPECT_FALSE(p.contains("points"));
}

}  // namespace

namespace {

// A folder of its own under /tmp, removed at the end.
struct TempDir {
  std::string path;
  TempDir() {
    char d[] = "/tmp/cnc-hmi-api.XXXXXX";
    path = mkdtemp(d) != nullptr ? d : "";
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

}  // namespace

// The preview tells rapids from feeds, and carries the interpreter's modal state per
// line (the active codes, F, S, the work offset) for the page's display.
TEST(HmiDryRun, ThePreviewMarksRapidsAndCarriesTheModes) {
  TempDir dir;
  const std::string program = dir.path + "/modes.ngc";
  std::ofstream(program) << "G21 G90 G17\nG0 X10 Y5 Z2\nG10 L2 P2 X3.5 Y-1\nG55 G1 Z-1 F450 S3000 M3\nG1 X20\nM2\n";
  const json p = preview(true, program);
  ASSERT_TRUE(p.contains("rapid")) << p.dump();
  const auto& rapid = p["rapid"];
  const auto& lines = p["lines"];
  ASSERT_EQ(rapid.size(), lines.size());
  size_t rapids = 0, feeds = 0;
  for (size_t i = 0; i < rapid.size(); ++i) {
    if (lines[i] == 2) {
      EXPECT_EQ(rapid[i], 1) << "line 2 is a rapid, point " << i;
    }
    if (lines[i] == 5) {
      EXPECT_EQ(rapid[i], 0) << "line 5 is a feed, point " << i;
    }
    (rapid[i] == 1 ? rapids : feeds) += 1;
  }
  EXPECT_GT(rapids, 5u);
  EXPECT_GT(feeds, 5u);
  // modes: [line, codes, F, S, T, [x, y, z]], a row where the state changed.
  const auto& modes = p["modes"];
  ASSERT_GE(modes.size(), 3u) << p.dump();
  const json* at2 = nullptr;
  const json* at4 = nullptr;
  for (const auto& r : modes) {
    if (r[0] == 2) at2 = &r;
    if (r[0] == 4) at4 = &r;
  }
  ASSERT_NE(at2, nullptr) << modes.dump();
  ASSERT_NE(at4, nullptr) << modes.dump();
  EXPECT_EQ((*at2)[1].get<std::string>().rfind("G0 G17 G21 G40 G49 G54 ", 0), 0u) << (*at2)[1];
  const std::string codes4 = (*at4)[1].get<std::string>();
  EXPECT_EQ(codes4.rfind("G1 G17 G21 G40 G49 G55 ", 0), 0u) << codes4;
  EXPECT_NE(codes4.find(" M3 "), std::string::npos) << codes4;
  EXPECT_DOUBLE_EQ((*at4)[2].get<double>(), 450.0);
  EXPECT_DOUBLE_EQ((*at4)[3].get<double>(), 3000.0);
  EXPECT_NEAR((*at4)[5][0].get<double>(), 3.5, 1e-9);
  EXPECT_NEAR((*at4)[5][1].get<double>(), -1.0, 1e-9);
  EXPECT_NEAR((*at4)[5][2].get<double>(), 0.0, 1e-9);
}

// The work offsets and tools as the var file and the tool table hold them.
TEST_F(HmiApi, OffsetsFromTheVarFileAndTheToolTable) {
  TempDir dir;
  cfg_.program.var_file = dir.path + "/cell.var";
  cfg_.program.tool_table = dir.path + "/tools.tbl";
  std::ofstream(cfg_.program.var_file) << "5210 1\n5211 0.5\n5213 -2\n5220 2\n5221 10\n5241 12.5\n5242 -3\n5243 -40\n5250 15\n";
  std::ofstream(cfg_.program.tool_table) << "T1 P1 Z12.5 D6 ;drill 6\nT7 P7 Z-3.25 D10\n";
  api_->message(7, false, R"({"id": 1, "action": "offsets"})");
  const json m = last();
  ASSERT_EQ(m["t"], "offsets") << m.dump();
  EXPECT_EQ(m["error"], "");
  EXPECT_EQ(m["coord"], 2);
  ASSERT_EQ(m["systems"].size(), 9u);
  EXPECT_EQ(m["systems"][0]["name"], "G54");
  EXPECT_DOUBLE_EQ(m["systems"][0]["values"][0].get<double>(), 10.0);
  EXPECT_EQ(m["systems"][1]["name"], "G55");
  EXPECT_DOUBLE_EQ(m["systems"][1]["values"][0].get<double>(), 12.5);
  EXPECT_DOUBLE_EQ(m["systems"][1]["values"][1].get<double>(), -3.0);
  EXPECT_DOUBLE_EQ(m["systems"][1]["values"][2].get<double>(), -40.0);
  EXPECT_DOUBLE_EQ(m["systems"][1]["rotation"].get<double>(), 15.0);
  EXPECT_EQ(m["systems"][8]["name"], "G59.3");
  EXPECT_EQ(m["g92"]["active"], true);
  EXPECT_DOUBLE_EQ(m["g92"]["values"][0].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(m["g92"]["values"][2].get<double>(), -2.0);
  ASSERT_EQ(m["tools"].size(), 2u);
  EXPECT_EQ(m["tools"][0]["number"], 1);
  EXPECT_DOUBLE_EQ(m["tools"][0]["offset"][2].get<double>(), 12.5);
  EXPECT_DOUBLE_EQ(m["tools"][0]["diameter"].get<double>(), 6.0);
  EXPECT_EQ(m["tools"][0]["comment"], "drill 6");
  EXPECT_DOUBLE_EQ(m["tools"][1]["offset"][2].get<double>(), -3.25);
  EXPECT_EQ(m["locked"], "");
  // A var file the interpreter would refuse: said, not thrown.
  std::ofstream(cfg_.program.var_file) << "5221 nan-ish\n";
  api_->message(7, false, R"({"id": 2, "action": "offsets"})");
  EXPECT_NE(last()["error"].get<std::string>().find("cell.var"), std::string::npos) << last().dump();
}

// Offset and tool edits: the MDI line an operator would type, through the same
// interlock; refused (and said so) while a program runs.
TEST_F(HmiApi, OffsetAndToolEditsAreMdiLinesRefusedWhileAProgramRuns) {
  std::vector<std::string> lines;
  bus_.subscribe<cnc::lcmt_program_command>(cfg_.channel(cnc::config::channels::kProgramCmd),
                                            [&](const auto& c) {
                                              if (c.command == cnc::lcmt_program_command::MDI) lines.push_back(c.text);
                                            });
  api_->message(7, true, R"({"id": 1, "action": "set_offset", "system": "G55", "values": {"X": 12.5, "Z": -40}})");
  api_->message(7, true, R"({"id": 2, "action": "set_tool", "tool": 3, "length": -12.25, "diameter": 6})");
  api_->message(7, true, R"({"id": 3, "action": "clear_g92"})");
  api_->message(7, true, R"({"id": 4, "action": "set_tool", "tool": 5, "length": 100})");
  bus_.drain();
  EXPECT_EQ(lines, (std::vector<std::string>{"G10 L2 P2 X12.5 Z-40", "G10 L1 P3 Z-12.25 R3", "G92.1", "G10 L1 P5 Z100"}));
  EXPECT_TRUE(sent_.empty()) << last().dump();  // answered once the cell ran the line (not here)

  api_->message(7, true, R"({"id": 5, "action": "set_offset", "system": "G53", "values": {"X": 1}})");
  EXPECT_EQ(last()["text"], "set_offset: 'system' must be one of G54 .. G59.3 (G92: clear_g92), not 'G53'");
  api_->message(7, true, R"({"id": 6, "action": "set_offset", "system": "G54", "values": {"Q": 1}})");
  EXPECT_EQ(last()["text"], "set_offset: the machine has no axis 'Q'");
  api_->message(7, true, R"({"id": 7, "action": "set_offset", "system": "G54", "values": {}})");
  EXPECT_EQ(last()["text"].get<std::string>().rfind("set_offset: 'values' must name at least one axis", 0), 0u);
  api_->message(7, true, R"({"id": 8, "action": "set_offset", "system": "G54", "values": {"X": "far"}})");
  EXPECT_EQ(last()["text"], "set_offset: 'X' must be a number");
  api_->message(7, true, R"({"id": 9, "action": "set_tool", "tool": 0, "length": 1})");
  EXPECT_EQ(last()["text"], "set_tool: 'tool' must be a tool number >= 1");
  api_->message(7, true, R"({"id": 10, "action": "set_tool", "tool": 2})");
  EXPECT_EQ(last()["text"], "set_tool: give 'length' (Z offset, mm) or 'diameter' (mm)");
  api_->message(7, true, R"({"id": 11, "action": "set_tool", "tool": 2, "diameter": -1})");
  EXPECT_EQ(last()["text"], "set_tool: diameter -1 mm is not a tool diameter (>= 0)");

  // A program runs: every edit refused with the reason, nothing sent; the offsets say so.
  cnc::lcmt_program_state st{};
  st.state = cnc::lcmt_program_state::RUNNING;
  st.program_token = 5;
  st.program_path = "/tmp/x.ngc";
  ASSERT_TRUE(bus_.publish(cfg_.channel(cnc::config::channels::kProgramState), st));
  bus_.drain();
  lines.clear();
  const std::string why =
      "a program runs (program running, interpolator idle): offsets and tools are changed between programs";
  api_->message(7, true, R"({"id": 12, "action": "set_offset", "system": "G54", "values": {"X": 1}})");
  EXPECT_EQ(last()["text"], "set_offset refused: " + why);
  EXPECT_EQ(last()["ok"], false);
  api_->message(7, true, R"({"id": 13, "action": "set_tool", "tool": 1, "length": 1})");
  EXPECT_EQ(last()["text"], "set_tool refused: " + why);
  api_->message(7, true, R"({"id": 14, "action": "clear_g92"})");
  EXPECT_EQ(last()["text"], "clear_g92 refused: " + why);
  api_->message(7, true, R"({"id": 15, "action": "offsets"})");
  EXPECT_EQ(last()["locked"], why);
  bus_.drain();
  EXPECT_TRUE(lines.empty());
}

// Upload's checks, each refusal naming why; a file written only when they pass.
TEST(HmiUpload, TheChecksNameWhy) {
  TempDir dir;
  const std::string& d = dir.path;
  using cnc::hmi::check_upload;
  EXPECT_EQ(check_upload(d, "part.ngc", "G0 X1\nM2\n", 1024, false), "");
  EXPECT_EQ(check_upload(d, "Part_2-b+c.NC", "M2\n", 1024, false), "");
  EXPECT_EQ(check_upload(d, "", "M2\n", 1024, false), "no file name");
  EXPECT_EQ(check_upload(d, "sub/part.ngc", "M2\n", 1024, false),
            "'sub/part.ngc' names a folder: a plain file name only (programs go into " + d + " itself)");
  EXPECT_EQ(check_upload(d, "../part.ngc", "M2\n", 1024, false),
            "'../part.ngc' names a folder: a plain file name only (programs go into " + d + " itself)");
  EXPECT_EQ(check_upload(d, "C:\\part.ngc", "M2\n", 1024, false),
            "'C:\\part.ngc' names a folder: a plain file name only (programs go into " + d + " itself)");
  EXPECT_EQ(check_upload(d, ".hidden.ngc", "M2\n", 1024, false), "'.hidden.ngc' is a hidden file (starts with '.')");
  EXPECT_EQ(check_upload(d, "part 1.ngc", "M2\n", 1024, false),
            "'part 1.ngc' has a character other than letters, digits and . _ - +");
  EXPECT_EQ(check_upload(d, "part.sh", "M2\n", 1024, false),
            "'part.sh' is not a program's name: the extension must be .ngc, .nc or .tap");
  EXPECT_EQ(check_upload(d, "part", "M2\n", 1024, false),
            "'part' is not a program's name: the extension must be .ngc, .nc or .tap");
  EXPECT_EQ(check_upload(d, std::string(101, 'a'), "M2\n", 1024, false), "the name is 101 characters long, more than 100");
  EXPECT_EQ(check_upload(d, "big.ngc", std::string(1025, 'G'), 1024, false),
            "'big.ngc' is 1025 bytes, more than hmi.upload_max_bytes (1024)");
  EXPECT_EQ(check_upload(d, "bin.ngc", std::string("G0\0X1", 5), 1024, false),
            "'bin.ngc' is not text (a NUL byte at offset 2)");
  EXPECT_EQ(check_upload(d + "/none", "part.ngc", "M2\n", 1024, false),
            "the program directory " + d + "/none (hmi.program_dir) is not there");
  // An existing file: kept unless replaced on purpose; a link or folder never replaced.
  EXPECT_EQ(cnc::hmi::write_upload(d, "part.ngc", "G0 X1\nM2\n"), "");
  EXPECT_EQ(check_upload(d, "part.ngc", "M2\n", 1024, false),
            "'part.ngc' exists in " + d + ": kept (replace it on purpose: replace true)");
  EXPECT_EQ(check_upload(d, "part.ngc", "M2\n", 1024, true), "");
  std::filesystem::create_symlink("/etc/passwd", d + "/link.ngc");
  EXPECT_EQ(check_upload(d, "link.ngc", "M2\n", 1024, true),
            "'link.ngc' exists in " + d + " and is not a plain file: it is not replaced");
  // Nothing left behind but the programs (no temporary file).
  std::set<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(d)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"link.ngc", "part.ngc"}));
}

TEST_F(HmiApi, UploadNeedsALoginAndKeepsAnExistingFile) {
  TempDir dir;
  cfg_.hmi.program_dir = dir.path;
  cfg_.hmi.upload_max_bytes = 2048;
  api_->message(7, true, R"({"id": 1, "action": "upload", "name": "a.ngc", "text": "M2\n"})");
  EXPECT_EQ(last()["text"], "upload refused: uploading needs a logged-in user (hmi.users_file)");
  EXPECT_FALSE(std::filesystem::exists(dir.path + "/a.ngc"));
  api_->message(7, true, R"({"id": 2, "action": "upload", "name": "a.ngc", "text": "G0 X1\nM2\n"})", "op");
  EXPECT_EQ(last()["text"], "uploaded a.ngc (9 bytes)");
  EXPECT_EQ(last()["ok"], true);
  ASSERT_FALSE(broadcast_.empty());
  EXPECT_EQ(broadcast_.back()["t"], "programs");
  EXPECT_EQ(broadcast_.back()["programs"], json::array({"a.ngc"}));
  api_->message(7, true, R"({"id": 3, "action": "upload", "name": "a.ngc", "text": "M2\n"})", "op");
  EXPECT_EQ(last()["text"], "upload refused: 'a.ngc' exists in " + dir.path + ": kept (replace it on purpose: replace true)");
  EXPECT_EQ(read_file(dir.path + "/a.ngc"), "G0 X1\nM2\n");
  api_->message(7, true, R"({"id": 4, "action": "upload", "name": "a.ngc", "text": "M2\n", "replace": true})", "op");
  EXPECT_EQ(last()["text"], "uploaded a.ngc (3 bytes)");
  EXPECT_EQ(read_file(dir.path + "/a.ngc"), "M2\n");
  api_->message(7, true, json{{"id", 5}, {"action", "upload"}, {"name", "b.ngc"}, {"text", std::string(2049, 'G')}}.dump(),
                "op");
  EXPECT_EQ(last()["text"], "upload refused: 'b.ngc' is 2049 bytes, more than hmi.upload_max_bytes (2048)");
  api_->message(7, true, R"({"id": 6, "action": "upload", "name": "c.ngc", "text": 5})", "op");
  EXPECT_EQ(last()["text"], "upload refused: 'text' (the program) must be a string");
  // A view-only client may not upload at all.
  api_->message(7, false, R"({"id": 7, "action": "upload", "name": "d.ngc", "text": "M2\n"})", "op");
  EXPECT_EQ(last()["text"], "view only: log in to operate the machine");
}
