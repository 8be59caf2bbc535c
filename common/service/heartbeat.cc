#include "common/service/heartbeat.h"

#include <unistd.h>

#include "cnc/lcmt_heartbeat.hpp"
#include "common/util/clock.h"
#include "common/util/install.h"

namespace cnc::service {

Heartbeat::Heartbeat(bus::Bus& bus, const config::MachineConfig& cfg, std::string service_name)
    : bus_(bus), channel_(cfg.channel(config::channels::kHeartbeat)), name_(std::move(service_name)),
      period_s_(cfg.heartbeat_period_s), rejects_(bus, cfg.channel(config::channels::kAlarm), name_) {
  char host[256] = {};
  if (gethostname(host, sizeof host - 1) == 0) host_ = host;
}

void Heartbeat::tick(int8_t state, int64_t loop_overruns, const std::string& detail, bool force) {
  const double now = util::monotonic_s();
  if (bus_.signing()) rejects_.report(now);
  if (!force && now - last_s_ < period_s_) return;
  last_s_ = now;
  cnc::lcmt_heartbeat hb{};
  hb.service = name_;
  hb.pid = static_cast<int32_t>(getpid());
  hb.state = state;
  hb.loop_overruns = loop_overruns;
  hb.detail = detail;
  hb.version = util::version();
  hb.host = host_;
  for (const auto& [ch, st] : bus_.stats()) {
    hb.channel.push_back(ch);
    hb.received.push_back(st.received);
    hb.seq_gaps.push_back(st.seq_gaps);
    hb.decode_failures.push_back(st.decode_failures);
    hb.published.push_back(st.published);
    hb.rejected_unsigned.push_back(st.rejected_unsigned);
    hb.rejected_unknown_key.push_back(st.rejected_unknown_key);
    hb.rejected_forged.push_back(st.rejected_forged);
    hb.rejected_stale.push_back(st.rejected_stale);
    hb.rejected_replayed.push_back(st.rejected_replayed);
  }
  hb.num_channels = static_cast<int32_t>(hb.channel.size());
  bus_.publish(channel_, hb);
}

}  // namespace cnc::service
