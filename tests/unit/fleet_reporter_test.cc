// cnc-mqtt's core: a run's start and end records once each, with its summary; aborted
// runs; MDI lines are no jobs; alarms inside and outside a run; the retained state.
// cnc-fleet's: the cells, their state and last jobs from those records.
#include "services/mqtt/fleet_reporter.h"
#include "services/mqtt/fleet_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

namespace {

using cnc::mqtt::FleetReporter;
using cnc::mqtt::ProgramStateIn;
using cnc::mqtt::Record;
using json = nlohmann::json;

constexpr int kLoaded = 1, kRunning = 2, kHeld = 3, kDone = 4, kStopped = 6;

ProgramStateIn ps(int64_t utime, int state, int64_t token, const std::string& path = "/p/part.ngc") {
  ProgramStateIn p;
  p.utime = utime;
  p.state = state;
  p.token = token;
  p.path = path;
  return p;
}

FleetReporter reporter() { return FleetReporter("plant/sim3", "sim3", {"X", "Y", "Z"}, 1.0, "0.1.0+1.gabc", true); }

TEST(FleetReporter, ARunIsOneStartAndOneEndWithItsSummary) {
  FleetReporter r = reporter();
  std::vector<Record> out;
  r.on_log_path("/runs/cell.lcmlog");
  r.on_program_state(ps(1'000'000, kLoaded, 7), &out);
  EXPECT_TRUE(out.empty());
  r.on_program_state(ps(2'000'000, kRunning, 7), &out);
  r.on_program_state(ps(2'100'000, kRunning, 7), &out);  // repeated: no second start
  r.on_program_state(ps(2'500'000, kHeld, 7), &out);
  r.on_program_state(ps(3'000'000, kRunning, 7), &out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].topic, "plant/sim3/job/start");
  EXPECT_TRUE(out[0].durable);
  EXPECT_FALSE(out[0].retained);
  const json start = json::parse(out[0].payload);
  EXPECT_EQ(start["program"], "part.ngc");
  EXPECT_EQ(start["log"], "/runs/cell.lcmlog");
  const double fe_a[] = {0.001, -0.004, 0.002}, fe_b[] = {0.0, std::numeric_limits<double>::quiet_NaN(), 0.003};
  const double pos[] = {1, 2, 3};
  r.on_axis_status(pos, fe_a, 3);
  r.on_axis_status(pos, fe_b, 3);
  r.on_alarm({2'600'000, "cnc-monitor", 1, "rmax_over_target", "R_max 4 um"}, &out);
  cnc::mqtt::InterpStateIn is;
  is.program_token = 7;
  is.program_time_s = 1.5;
  is.blocks_done = 12;
  r.on_interp_state(is);
  r.on_program_state(ps(4'250'000, kDone, 7), &out);
  r.on_program_state(ps(4'300'000, kDone, 7), &out);  // repeated: no second end
  ASSERT_EQ(out.size(), 4u);
  EXPECT_EQ(out[1].topic, "plant/sim3/alarm");
  EXPECT_EQ(json::parse(out[1].payload)["job"], start["job"]);
  EXPECT_EQ(out[2].topic, "plant/sim3/job/end");
  EXPECT_EQ(out[3].topic, "plant/sim3/job/last");
  EXPECT_TRUE(out[3].retained);
  const json end = json::parse(out[2].payload);
  EXPECT_EQ(end["job"], start["job"]);
  EXPECT_EQ(end["outcome"], "done");
  EXPECT_NEAR(end["duration_s"].get<double>(), 2.25, 1e-9);
  EXPECT_NEAR(end["program_time_s"].get<double>(), 1.5, 1e-12);
  EXPECT_EQ(end["blocks_done"], 12);
  EXPECT_EQ(end["alarms"], 1);
  EXPECT_EQ(end["alarm_list"][0]["code"], "rmax_over_target");
  EXPECT_NEAR(end["max_following_error_mm"].get<double>(), 0.004, 1e-12);
  EXPECT_EQ(end["log"], "/runs/cell.lcmlog");
  EXPECT_EQ(r.jobs_started(), 1);
  EXPECT_EQ(r.jobs_ended(), 1);
  // Run again (same token): a new job with another id.
  out.clear();
  r.on_program_state(ps(5'000'000, kRunning, 7), &out);
  r.on_program_state(ps(5'500'000, kStopped, 7), &out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_NE(json::parse(out[0].payload)["job"], start["job"]);
  EXPECT_EQ(json::parse(out[1].payload)["outcome"], "stopped");
}

TEST(FleetReporter, ALoadDuringARunAbortsItAndMdiLinesAreNoJobs) {
  FleetReporter r = reporter();
  std::vector<Record> out;
  r.on_program_state(ps(1'000'000, kRunning, 1), &out);
  r.on_program_state(ps(2'000'000, kLoaded, 2, "/p/other.ngc"), &out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(json::parse(out[1].payload)["outcome"], "aborted");
  out.clear();
  r.on_program_state(ps(3'000'000, kRunning, 3, "/state/mdi-1.ngc"), &out);
  r.on_program_state(ps(3'100'000, kDone, 3, "/state/mdi-1.ngc"), &out);
  r.on_alarm({3'050'000, "cnc-interpolator", 2, "interp_fault", "x"}, &out);
  ASSERT_EQ(out.size(), 1u);  // the alarm only
  EXPECT_TRUE(json::parse(out[0].payload)["job"].is_null());
  EXPECT_EQ(json::parse(out[0].payload)["severity"], "fault");
}

TEST(FleetReporter, TheStateIsRetainedAtItsPeriodAndOnAChangeAndItsNumbersAreFinite) {
  FleetReporter r = reporter();
  std::vector<Record> out;
  r.tick(0.0, 1, false, &out);
  ASSERT_EQ(out.size(), 1u);
  r.tick(0.5, 2, false, &out);
  EXPECT_EQ(out.size(), 1u);
  r.on_program_state(ps(3, kLoaded, 1), &out);
  r.tick(0.6, 3, false, &out);  // the program's state changed: at once
  ASSERT_EQ(out.size(), 2u);
  r.tick(1.0, 4, false, &out);
  EXPECT_EQ(out.size(), 2u);
  cnc::mqtt::InterpStateIn is;
  is.feed_override = std::numeric_limits<double>::infinity();
  is.position_mm = {1.5, std::nan(""), 3};
  r.on_interp_state(is);
  r.tick(1.7, 5, false, &out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[2].topic, "plant/sim3/state");
  EXPECT_TRUE(out[2].retained);
  EXPECT_FALSE(out[2].durable);
  const json s = json::parse(out[2].payload);
  EXPECT_EQ(s["program"]["state"], "loaded");
  EXPECT_TRUE(s["overrides"]["feed"].is_null());
  EXPECT_EQ(s["position_mm"]["X"], 1.5);
  EXPECT_TRUE(s["position_mm"]["Y"].is_null());
  EXPECT_EQ(s["interp"]["mode"], "program");
  EXPECT_TRUE(s["spindle"].is_null());
  r.tick(1.8, 6, true, &out);  // forced (a reconnection)
  EXPECT_EQ(out.size(), 4u);
  EXPECT_EQ(json::parse(r.will().payload)["status"], "offline");
  EXPECT_TRUE(r.will().retained);
  EXPECT_EQ(json::parse(r.birth(1).payload)["status"], "online");
}

}  // namespace

namespace {

using cnc::mqtt::FleetView;

TEST(FleetView, TheCellsTheirStateAndLastJobsNewestFirstEachOnce) {
  FleetView v("plant/hall2", 2);
  EXPECT_FALSE(v.on_message("plant/hall2/sim3/alarm", R"({"code":"x"})"));  // not a page's record
  EXPECT_FALSE(v.on_message("other/sim3/status", R"({"status":"online"})"));
  EXPECT_FALSE(v.on_message("plant/hall2/sim3/state", "not json"));
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/status", R"({"status":"online"})"));
  EXPECT_TRUE(v.on_message("plant/hall2/mill1/status", R"({"status":"offline","reason":"connection lost"})"));
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/state", R"({"program":{"state":"running"}})"));
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/job/end", R"({"job":"a","start_utime":1})"));
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/job/end", R"({"job":"b","start_utime":3})"));
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/job/last", R"({"job":"b","start_utime":3})"));  // again: kept once
  EXPECT_TRUE(v.on_message("plant/hall2/sim3/job/end", R"({"job":"c","start_utime":2})"));
  const nlohmann::json j = v.to_json();
  ASSERT_EQ(j["cells"].size(), 2u);
  EXPECT_EQ(j["cells"][0]["cell"], "mill1");
  EXPECT_EQ(j["cells"][0]["status"]["reason"], "connection lost");
  const nlohmann::json& sim3 = j["cells"][1];
  EXPECT_EQ(sim3["state"]["program"]["state"], "running");
  ASSERT_EQ(sim3["jobs"].size(), 2u);  // the newest two
  EXPECT_EQ(sim3["jobs"][0]["job"], "b");
  EXPECT_EQ(sim3["jobs"][1]["job"], "c");
  EXPECT_EQ(j["records"], 7);
}

}  // namespace
