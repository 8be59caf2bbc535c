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
