#pragma once
// cnc-fleet's core: the cells a broker knows, from their cnc-mqtt records (status,
// state, job/end, job/last under PREFIX/CELL/...), as one JSON document for the fleet
// page. No broker, no HTTP, no clock.
#include <cstddef>
#include <deque>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

namespace cnc::mqtt {

class FleetView {
 public:
  // prefix: mqtt.topic_prefix of the cells; jobs_kept: the last jobs listed per cell.
  explicit FleetView(std::string prefix, size_t jobs_kept = 5);
  // One message as the broker delivered it; false when it is no cell's record (ignored).
  bool on_message(const std::string& topic, const std::string& payload);
  // {"cells": [{"cell", "status", "state", "jobs": [newest first]}...] by name, "records": N}
  nlohmann::json to_json() const;

 private:
  struct Cell {
    nlohmann::json status, state;
    std::deque<nlohmann::json> jobs;  // newest first
  };
  void add_job(Cell& c, nlohmann::json job);

  std::string prefix_;
  size_t jobs_kept_;
  std::map<std::string, Cell> cells_;
  long long records_ = 0;
};

}  // namespace cnc::mqtt
