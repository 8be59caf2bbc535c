#include "services/mqtt/fleet_view.h"

#include <utility>

namespace cnc::mqtt {

using json = nlohmann::json;

FleetView::FleetView(std::string prefix, size_t jobs_kept) : prefix_(std::move(prefix)), jobs_kept_(jobs_kept) {}

bool FleetView::on_message(const std::string& topic, const std::string& payload) {
  if (topic.size() <= prefix_.size() + 1 || topic.compare(0, prefix_.size(), prefix_) != 0 || topic[prefix_.size()] != '/')
    return false;
  const std::string rest = topic.substr(prefix_.size() + 1);
  const size_t slash = rest.find('/');
  if (slash == std::string::npos || slash == 0) return false;
  const std::string name = rest.substr(0, slash), what = rest.substr(slash + 1);
  if (what != "status" && what != "state" && what != "job/end" && what != "job/last") return false;
  json j = json::parse(payload, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return false;
  ++records_;
  Cell& c = cells_[name];
  if (what == "status") c.status = std::move(j);
  else if (what == "state") c.state = std::move(j);
  else add_job(c, std::move(j));
  return true;
}

// job/last repeats the newest job/end (and is sent again at each subscription): kept once.
void FleetView::add_job(Cell& c, json job) {
  if (!job.contains("job")) return;
  for (const json& k : c.jobs)
    if (k["job"] == job["job"]) return;
  // Newest first by start time: a retained job/last may come after newer job/end records.
  auto at = c.jobs.begin();
  const auto start = job.value("start_utime", 0LL);
  while (at != c.jobs.end() && at->value("start_utime", 0LL) > start) ++at;
  c.jobs.insert(at, std::move(job));
  while (c.jobs.size() > jobs_kept_) c.jobs.pop_back();
}

json FleetView::to_json() const {
  json cells = json::array();
  for (const auto& [name, c] : cells_) {
    json jobs = json::array();
    for (const json& j : c.jobs) jobs.push_back(j);
    cells.push_back({{"cell", name}, {"status", c.status}, {"state", c.state}, {"jobs", jobs}});
  }
  return {{"prefix", prefix_}, {"cells", cells}, {"records", records_}};
}

}  // namespace cnc::mqtt
