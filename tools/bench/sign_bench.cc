// cnc-bench-sign: what signing costs per message (HMAC-SHA-512-256, libsodium's
// crypto_auth, with the key's pads absorbed once), against the plain LCM encode of
// the same message measured in the same run, for the cell's messages at their
// sizes; and the whole publish + receive path of a setpoint over memq:// with
// signing off and on. Not a test: it prints figures.
//
//   cnc-bench-sign [--iterations N] [--repeats R]
//
// Each figure is the median over R repeats of N iterations (ns per message).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/auth.h"
#include "common/bus/bus.h"
#include "common/util/cli.h"

namespace {
using Clock = std::chrono::steady_clock;

volatile uint8_t g_sink = 0;

template <class F>
double median_ns(int iterations, int repeats, F&& f) {
  std::vector<double> r;
  for (int k = 0; k < repeats; ++k) {
    const auto t0 = Clock::now();
    for (int i = 0; i < iterations; ++i) f(i);
    const auto t1 = Clock::now();
    r.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / iterations);
  }
  std::sort(r.begin(), r.end());
  return r[r.size() / 2];
}

template <class Msg>
void row(const char* name, Msg m, const cnc::bus::Key& key, int n, int reps) {
  const int size = m.getEncodedSize();
  std::vector<uint8_t> buf(static_cast<size_t>(size) + cnc::bus::kTrailerBytes);
  const std::string ch = "SIM3.CHANNEL";
  const double enc = median_ns(n, reps, [&](int i) {
    m.seq = i;
    m.encode(buf.data(), 0, size);
    g_sink = static_cast<uint8_t>(g_sink + buf[20]);
  });
  const double sig = median_ns(n, reps, [&](int i) {
    buf[20] = static_cast<uint8_t>(i);
    cnc::bus::sign(key, ch, buf.data(), static_cast<size_t>(size), buf.data() + size);
    g_sink = static_cast<uint8_t>(g_sink + buf[static_cast<size_t>(size) + 5]);
  });
  cnc::bus::sign(key, ch, buf.data(), static_cast<size_t>(size), buf.data() + size);
  bool ok = true;
  const double ver = median_ns(n, reps, [&](int) { ok = cnc::bus::verify(key, ch, buf.data(), buf.size()) && ok; });
  std::printf("%-26s %6d %8.0f %8.0f %8.0f %7.2f %7.2f%s\n", name, size, enc, sig, ver, sig / enc, ver / enc,
              ok ? "" : "  (verify FAILED)");
}

cnc::lcmt_setpoint setpoint() {
  cnc::lcmt_setpoint m{};
  m.num_axes = 3;
  m.position_mm = {100.25, 45.5, -3.0};
  return m;
}
}  // namespace

int main(int argc, char** argv) {
  int n = 200000, reps = 7;
  CLI::App app{"what signing costs per message (sign, verify) against the plain encode", "cnc-bench-sign"};
  cnc::util::cli::setup(app);
  app.add_option("--iterations", n, "messages per measurement")->type_name("N")->check(CLI::Range(1, 1 << 30));
  app.add_option("--repeats", reps, "measurements; the median counts")->type_name("R")->check(CLI::Range(1, 1000));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  cnc::bus::KeySet keys;
  keys.add(cnc::bus::generate_key());
  const cnc::bus::Key& key = keys.keys[0];

  std::printf("per message, ns (median of %d x %d); trailer %zu bytes\n", reps, n, cnc::bus::kTrailerBytes);
  std::printf("%-26s %6s %8s %8s %8s %7s %7s\n", "message", "bytes", "encode", "sign", "verify", "sign/enc",
              "ver/enc");
  row("lcmt_setpoint (3 axes)", setpoint(), key, n, reps);
  {
    cnc::lcmt_program_command c{};
    c.command = cnc::lcmt_program_command::OVERRIDE;
    c.feed_override = 0.8;
    row("lcmt_program_command", c, key, n, reps);
  }
  {
    cnc::lcmt_axis_status s{};
    s.num_axes = 3;
    s.axis_name = {"X", "Y", "Z"};
    s.commanded_mm = s.actual_mm = s.following_error_mm = {1, 2, 3};
    s.drive_state = {2, 2, 2};
    s.fault = {"", "", ""};
    s.transactions = s.timeouts = s.exceptions = s.crc_errors = s.reconnects = {0, 0, 0};
    row("lcmt_axis_status (3 axes)", s, key, n, reps);
  }
  {
    cnc::lcmt_program_block b{};
    b.kind = cnc::lcmt_program_block::LINE;
    b.source_file = "/home/cnc/programs/part.ngc";
    b.num_axes = 3;
    b.start = b.end = b.center = {1, 2, 3};
    row("lcmt_program_block (line)", b, key, n, reps);
    b.kind = cnc::lcmt_program_block::NURBS;
    b.order = 4;
    b.num_control_points = 40;
    b.num_knots = 44;
    b.knots.assign(44, 0.5);
    b.control_points.assign(40, std::vector<double>{1, 2, 3});
    b.weights.assign(40, 1.0);
    row("lcmt_program_block (NURBS 40)", b, key, n / 4, reps);
  }
  {
    cnc::lcmt_heartbeat h{};
    h.service = "cnc-interpolator";
    h.num_channels = 13;
    for (int i = 0; i < 13; ++i) h.channel.push_back("SIM3.CHANNEL_" + std::to_string(i));
    h.received = h.seq_gaps = h.decode_failures = h.published = h.rejected_unsigned = h.rejected_unknown_key =
        h.rejected_forged = h.rejected_stale = h.rejected_replayed = std::vector<int64_t>(13, 12345);
    row("lcmt_heartbeat (13 channels)", h, key, n / 4, reps);
  }

  // The bus: publish (stamp, encode, sign) and receive (verify, replay window,
  // decode, handler) of one setpoint over memq://, signing off and on.
  std::printf("\nBus publish + receive of a setpoint over memq://, ns per message\n");
  for (const bool on : {false, true}) {
    cnc::bus::Security sec;
    sec.enabled = on;
    sec.keys = keys;
    cnc::bus::Bus bus("memq://", 7, 100000, sec);
    int64_t got = 0;
    bus.subscribe<cnc::lcmt_setpoint>("SIM3.SETPOINTS", [&](const cnc::lcmt_setpoint&) { ++got; });
    auto m = setpoint();
    const int k = n / 10;
    const double t = median_ns(k, reps, [&](int) {
      bus.publish("SIM3.SETPOINTS", m);
      bus.drain(1);
    });
    std::printf("  signing %-3s %8.0f   (%lld received, %lld dropped)\n", on ? "on" : "off", t,
                static_cast<long long>(got), static_cast<long long>(bus.stats("SIM3.SETPOINTS").rejected()));
  }
  return g_sink == 255 ? 0 : 0;
}
