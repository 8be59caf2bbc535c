#pragma once
// The HMI API with no tools behind it (hmi_api_test, fuzz_hmi_api): every helper
// program and folder it would run or read is one that does not exist.
#include "services/hmi/api.h"

namespace cnc::hmi {

inline ApiOptions offline_api_options() {
  ApiOptions opt;
  opt.machine_file = "/nonexistent.yaml";
  opt.plan_exe = "/nonexistent/cnc-plan";
  opt.logexport_exe = "/nonexistent/cnc-logexport";
  opt.make_report = "/nonexistent/make_report.py";
  opt.runs_dir = "/nonexistent";
  return opt;
}

}  // namespace cnc::hmi
