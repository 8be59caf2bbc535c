// libFuzzer target: the HMI's WebSocket messages as the API dispatches them
// (services/hmi/api.h), on an in-process bus (memq://) with no cell behind it and
// without HTTP: byte 0 says whether the client may operate the machine, the rest is
// the message's text. The API must answer the client by the action's deadline at the
// latest (every action but the runs worker's, which answers from its thread), never
// let an exception out, and everything it sends, to the client or to all, must
// serialise (nlohmann's dump throws on a string that is not UTF-8).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/util/clock.h"
#include "services/hmi/api.h"
#include "tests/hmi_offline_options.h"

namespace {
using nlohmann::json;

struct World {
  cnc::config::MachineConfig cfg =
      cnc::config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  cnc::bus::Bus bus{"memq://"};
  std::unique_ptr<cnc::hmi::Api> api;
  int64_t sent = 0;
  double now = 0;

  static void check(const json& j) {
    try {
      (void)j.dump();
    } catch (const json::exception& e) {
      std::fprintf(stderr, "the API sent a message that does not serialise: %s\n", e.what());
      std::abort();
    }
  }

  World() {
    cnc::hmi::Outbox out;
    out.broadcast = [](const json& j, bool) { check(j); };
    out.send_to = [this](uint64_t client, const json& j) {
      if (client != 7) std::abort();
      check(j);
      ++sent;
    };
    const cnc::hmi::ApiOptions opt = cnc::hmi::offline_api_options();
    api = std::make_unique<cnc::hmi::Api>(cfg, bus, opt, out);
    api->open(7, true, "fuzz");
  }
};

World& world() {
  static World* w = new World();  // never destroyed: libFuzzer exits without unwinding
  return *w;
}

bool answered_later(const std::string& text) {
  // The runs worker's actions (runs, playback, report) answer from its thread.
  json j = json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("action") || !j["action"].is_string()) return false;
  const std::string a = j["action"].get<std::string>();
  return a == "runs" || a == "playback" || a == "report";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  World& w = world();
  const bool may_control = (data[0] & 1) != 0;
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  const int64_t before = w.sent;
  w.api->message(7, may_control, text);  // throws nothing: an escape ends the process
  // An action the cell must answer is answered by the cell or by its deadline: past
  // every deadline (the API's clock on by a minute), the client has its answer.
  w.now = std::max(w.now, cnc::util::monotonic_s()) + 60.0;  // the API's clock is the monotonic one
  w.api->update(w.now);
  w.bus.handle(0);
  if (w.sent == before && !answered_later(text)) {
    std::fprintf(stderr, "no answer to: %s\n", text.c_str());
    std::abort();
  }
  return 0;
}
