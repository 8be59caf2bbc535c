// cnc-servo-sim: a Modbus TCP server that emulates the cell's servo drives, one
// unit id per axis, with the register map of common/drive/sim_profile.h and the
// dynamics of ServoModel. Single-threaded: select() on the listening socket and
// the clients, with the model stepped on a 1 ms grid between requests.
#include <modbus.h>
#include <sys/select.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <vector>

#include "common/drive/sim_profile.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "tools/servo_sim/servo_model.h"

namespace sim = cnc::drive::sim;

namespace {

struct SimAxis {
  std::string name;
  int unit;
  modbus_mapping_t* map;
  cnc::servo_sim::ServoModel model;
  // Velocity feed-forward, estimated from the last two target writes.
  int32_t last_target_counts = 0;
  double last_write_s = -1;
  double feedforward_mm_s = 0;
};

void note_target_write(SimAxis& a, double now_s) {
  const int32_t t = sim::get_i32_low_first(&a.map->tab_registers[sim::kTargetPosition]);
  const double dt = now_s - a.last_write_s;
  a.feedforward_mm_s = (a.last_write_s > 0 && dt > 1e-4 && dt < 0.02)
                           ? sim::counts_to_mm(t - a.last_target_counts) / dt
                           : 0.0;
  a.last_target_counts = t;
  a.last_write_s = now_s;
}

void publish_state(SimAxis& a) {
  uint16_t* r = a.map->tab_registers;
  const bool enabled = (r[sim::kControlword] & sim::kCwEnable) != 0;
  r[sim::kStatusword] = enabled ? sim::kSwEnabled : 0;
  sim::put_i32_low_first(&r[sim::kActualPosition], sim::mm_to_counts(a.model.position_mm()));
  sim::put_i32_low_first(&r[sim::kActualVelocity], sim::mm_to_counts(a.model.velocity_mm_s()));
}

int run_sim(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  int port = -1;
  std::vector<SimAxis> axes;
  for (const auto& a : cfg.axes) {
    if (a.drive.transport != "modbus_tcp") continue;
    if (port < 0) port = a.drive.port;
    if (a.drive.port != port) {
      throw std::runtime_error("axis " + a.name + ": the simulator serves one TCP port; axes use " +
                               std::to_string(port) + " and " + std::to_string(a.drive.port));
    }
    modbus_mapping_t* map = modbus_mapping_new(0, 0, sim::kNumRegisters, 0);
    if (map == nullptr) throw std::runtime_error("modbus_mapping_new failed");
    axes.push_back(SimAxis{a.name, a.drive.unit_id, map,
                           cnc::servo_sim::ServoModel(a.sim, a.max_velocity_mm_s, a.home_mm),
                           sim::mm_to_counts(a.home_mm), -1.0, 0.0});
    sim::put_i32_low_first(&map->tab_registers[sim::kTargetPosition], sim::mm_to_counts(a.home_mm));
    publish_state(axes.back());
  }
  if (axes.empty()) throw std::runtime_error("no axis uses transport modbus_tcp");
  if (!args.option("port").empty()) port = std::stoi(args.option("port"));

  const std::string bind = args.option("bind", "127.0.0.1");
  modbus_t* ctx = modbus_new_tcp(bind.c_str(), port);
  const int listen_fd = modbus_tcp_listen(ctx, 8);
  if (listen_fd < 0) throw std::runtime_error("cannot listen on " + bind + ":" + std::to_string(port) + ": " +
                                              modbus_strerror(errno));
  spdlog::info("cnc-servo-sim: {} drives on {}:{}", axes.size(), bind, port);

  if (const std::string why = cnc::util::make_realtime(cfg.realtime_priority); !why.empty())
    spdlog::warn("real-time scheduling not available ({}): running with normal scheduling", why);
  std::map<int, bool> clients;
  const double dt = cfg.servo_period_s;
  double next_step = cnc::util::monotonic_s();
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  const int header = modbus_get_header_length(ctx);
  while (!cnc::util::stop_requested()) {
    // Step the dynamics on the servo grid.
    double now = cnc::util::monotonic_s();
    int steps = 0;
    while (now >= next_step && steps < 1000) {
      for (auto& a : axes) {
        const uint16_t* r = a.map->tab_registers;
        const double target = sim::counts_to_mm(sim::get_i32_low_first(&r[sim::kTargetPosition]));
        // No write for two periods: the target stands still.
        if (now - a.last_write_s > 2 * dt) a.feedforward_mm_s = 0;
        a.model.step(dt, target, a.feedforward_mm_s, (r[sim::kControlword] & sim::kCwEnable) != 0);
        publish_state(a);
      }
      next_step += dt;
      ++steps;
    }
    if (steps >= 1000) next_step = now + dt;

    fd_set rd;
    FD_ZERO(&rd);
    FD_SET(listen_fd, &rd);
    int maxfd = listen_fd;
    for (const auto& [fd, _] : clients) {
      FD_SET(fd, &rd);
      maxfd = std::max(maxfd, fd);
    }
    const double wait = std::max(0.0, next_step - cnc::util::monotonic_s());
    timeval tv{0, static_cast<suseconds_t>(wait * 1e6)};
    const int n = select(maxfd + 1, &rd, nullptr, nullptr, &tv);
    if (n <= 0) continue;
    if (FD_ISSET(listen_fd, &rd)) {
      int fd = listen_fd;
      const int c = modbus_tcp_accept(ctx, &fd);
      if (c >= 0) clients[c] = true;
    }
    std::vector<int> closed;
    for (const auto& [fd, _] : clients) {
      if (!FD_ISSET(fd, &rd)) continue;
      modbus_set_socket(ctx, fd);
      const int len = modbus_receive(ctx, query);
      if (len <= 0) {
        if (len < 0) closed.push_back(fd);
        continue;
      }
      const int unit = query[header - 1];
      SimAxis* target = nullptr;
      for (auto& a : axes)
        if (a.unit == unit) target = &a;
      if (target == nullptr) {
        modbus_reply_exception(ctx, query, MODBUS_EXCEPTION_GATEWAY_TARGET);
        continue;
      }
      const int function = query[header];
      modbus_reply(ctx, query, len, target->map);
      if (function == MODBUS_FC_WRITE_AND_READ_REGISTERS || function == MODBUS_FC_WRITE_MULTIPLE_REGISTERS)
        note_target_write(*target, cnc::util::monotonic_s());
      publish_state(*target);
    }
    for (int fd : closed) {
      close(fd);
      clients.erase(fd);
    }
  }
  for (const auto& [fd, _] : clients) close(fd);
  close(listen_fd);
  modbus_free(ctx);

  // Final positions: for tests and for the demo summary.
  std::string report = "{";
  for (size_t i = 0; i < axes.size(); ++i) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s\"%s\": %.7f", i ? ", " : "", axes[i].name.c_str(), axes[i].model.position_mm());
    report += buf;
  }
  report += "}";
  spdlog::info("cnc-servo-sim: final positions {}", report);
  if (!args.option("final-state").empty()) {
    std::ofstream(args.option("final-state")) << report << "\n";
  }
  for (auto& a : axes) modbus_mapping_free(a.map);
  return cnc::service::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-servo-sim", "Modbus TCP servo drive simulator", {"port", "bind", "final-state"}, {}};
  return cnc::service::run(spec, argc, argv, run_sim);
}
