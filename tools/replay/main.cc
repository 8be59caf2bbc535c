// cnc-replay: re-runs the interpolator core from the inputs recorded in a log, at
// their stamped cycles, with no socket and no clock, and compares every setpoint
// with the logged one bit for bit. Exit 0 when identical; 1 at the first
// divergence, which it names (cycle, time, block, line, field, both values); 2 when
// the log cannot be replayed here (no config, inputs lost; or it diverges and was
// recorded by another motion revision, common/bus/log_format.h, which it names).
//
//   cnc-replay --log LOG [--machine FILE] [--program FILE] [--key KEYFILE]
//
// --key verifies the MAC of every message of the log first (the logger keeps
// them): a log with a message that does not verify (unsigned, unknown key, forged,
// repeated) is not replayed (exit 2), the counts per cause are printed.
//
// The config is the machine file the interpolator recorded in the log (its relative
// paths beside the file it was loaded from). --machine replays with another config,
// --program with another version of a program: its blocks replace the recorded
// blocks of every recorded program with the same file name, interpreted as the dry
// run does (pps::dry_run_setup: the cell's setup, the var file and tool table never
// written), with the block delete switch the recorded program was loaded with
// (PROGRAM_STATE). Both show where a change would alter the run.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <optional>
#include <vector>

#include "cnc/lcmt_config.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_interp_input_v2.hpp"
#include "cnc/lcmt_setpoint_v1.hpp"
#include "common/bus/log_format.h"
#include "common/config/yaml_reader.h"
#include "common/bus/bus.h"
#include "common/program/block_msg.h"
#include "common/service/service.h"
#include "common/util/signals.h"
#include "services/interpolator/inputs.h"
#include "services/part_program_server/program_server.h"

namespace {

constexpr int kExitDiverged = 1;
constexpr int kExitUnreplayable = 2;

template <class Msg>
bool decode(const void* data, size_t size, Msg* m) {
  try {
    const size_t n = cnc::bus::payload_size(data, size);  // a signed cell's trailer follows the message
    return m->decode(data, 0, static_cast<int>(n)) == static_cast<int>(n);
  } catch (...) {
    return false;
  }
}

// A setpoint as logs of format 1 hold it, into today's message (no stream, no engagement).
bool decode_v1(const void* data, size_t size, cnc::lcmt_setpoint* out) {
  cnc::lcmt_setpoint_v1 v;
  if (!decode(data, size, &v)) return false;
  *out = cnc::lcmt_setpoint{};
  out->utime = v.utime;
  out->seq = v.seq;
  out->sender = v.sender;
  out->cycle = v.cycle;
  out->period_s = v.period_s;
  out->num_axes = v.num_axes;
  out->position_mm = v.position_mm;
  out->feed_mm_per_min = v.feed_mm_per_min;
  out->program_token = v.program_token;
  out->block_index = v.block_index;
  out->source_line = v.source_line;
  out->u = v.u;
  out->limit = v.limit;
  out->state = v.state;
  out->num_prev_values = v.num_prev_values;
  out->prev_position_mm = v.prev_position_mm;
  return true;
}

// An input as logs of formats 1 and 2 hold it (blocks without the path tolerance).
bool decode_v2(const void* data, size_t size, cnc::lcmt_interp_input* out) {
  cnc::lcmt_interp_input_v2 v;
  if (!decode(data, size, &v)) return false;
  out->utime = v.utime;
  out->seq = v.seq;
  out->sender = v.sender;
  out->index = v.index;
  out->cycle = v.cycle;
  out->kind = v.kind;
  out->block = cnc::program::from_v2(v.block);
  out->command = v.command;
  out->plans = v.plans;
  return true;
}

std::string bits(double v) {
  uint64_t u;
  std::memcpy(&u, &v, sizeof u);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g (0x%016" PRIx64 ")", v, u);
  return buf;
}

bool same(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// First field where the replayed setpoint differs from the logged one; "" if none.
std::string compare(const cnc::lcmt_setpoint& logged, const cnc::interp::Setpoint& sp, double period_s) {
  if (logged.num_axes != sp.num_axes) return "num_axes: logged " + std::to_string(logged.num_axes) + ", replayed " +
                                              std::to_string(sp.num_axes);
  for (int a = 0; a < sp.num_axes; ++a)
    if (!same(logged.position_mm[a], sp.position_mm[a]))
      return "position_mm[" + std::to_string(a) + "]: logged " + bits(logged.position_mm[a]) + ", replayed " +
             bits(sp.position_mm[a]);
  if (!same(logged.feed_mm_per_min, sp.feed_mm_per_min))
    return "feed_mm_per_min: logged " + bits(logged.feed_mm_per_min) + ", replayed " + bits(sp.feed_mm_per_min);
  if (!same(logged.u, sp.u)) return "u: logged " + bits(logged.u) + ", replayed " + bits(sp.u);
  if (logged.block_index != sp.block_index)
    return "block_index: logged " + std::to_string(logged.block_index) + ", replayed " + std::to_string(sp.block_index);
  if (logged.source_line != sp.source_line)
    return "source_line: logged " + std::to_string(logged.source_line) + ", replayed " + std::to_string(sp.source_line);
  if (logged.limit != static_cast<int8_t>(sp.limit))
    return std::string("limit: logged ") + cnc::interp::to_string(static_cast<cnc::interp::Limit>(logged.limit)) +
           ", replayed " + cnc::interp::to_string(sp.limit);
  if (logged.state != static_cast<int8_t>(sp.state))
    return std::string("state: logged ") + cnc::interp::to_string(static_cast<cnc::interp::RunState>(logged.state)) +
           ", replayed " + cnc::interp::to_string(sp.state);
  if (!same(logged.period_s, period_s)) return "period_s: logged " + bits(logged.period_s) + ", replayed " + bits(period_s);
  return "";
}

int replay(const cnc::config::MachineConfig&, const cnc::service::Args& args) {
  cnc::util::end_at_once_on_stop_signals();  // no loop here polls the stop flag
  const std::string log = args.option("log");
  if (log.empty()) {
    std::fprintf(stderr, "cnc-replay: --log FILE is required\n");
    return cnc::service::kExitBadInput;
  }
  // Everything each interpolator run in the log recorded (a run: one interpolator
  // process, told apart by its sender; a restart is a new run); --run picks one.
  int run_no = 1;
  if (const std::string r = args.option("run"); !r.empty()) {
    char* end = nullptr;
    const long v = std::strtol(r.c_str(), &end, 10);
    if (end == r.c_str() || *end != '\0' || v < 1 || v > 1000000) {
      std::fprintf(stderr, "cnc-replay: --run '%s' is not a run number (1, 2, ...)\n", r.c_str());
      return cnc::service::kExitBadInput;
    }
    run_no = static_cast<int>(v);
  }
  // Two passes over the log, so that memory does not grow with its length (a run of
  // ten million blocks logs 10 GB): the first finds the runs, checks the inputs are
  // complete and notes where programs change; the second replays as it reads.
  std::vector<cnc::lcmt_config> runs;  // each run's config, in the order they began
  struct Seen {
    std::map<int64_t, int64_t> indices;  // input indices logged, as [first, end) intervals
    int64_t inputs = 0, copies = 0, setpoints = 0;
    int64_t first_cycle = -1, last_cycle = -1;  // of the setpoints
    std::map<int64_t, int64_t> token_at;  // input index where the blocks' program token changed -> token
    int64_t last_token = 0;
  };
  std::map<int32_t, Seen> seen;
  std::map<int64_t, bool> block_delete_of;  // program token -> the switch it was loaded with
  cnc::bus::LogFormat format;  // format 1 unless the log says otherwise
  bool format_seen = false;
  const std::string key_file = args.option("key");
  std::optional<cnc::bus::LogVerifier> verifier;
  if (!key_file.empty()) verifier.emplace(cnc::bus::read_key_file(key_file));
  // Adds index to the intervals; false when it was there already (a copy sent again).
  const auto add_index = [](std::map<int64_t, int64_t>& iv, int64_t i) {
    auto next = iv.upper_bound(i);
    if (next != iv.begin()) {
      auto prev = std::prev(next);
      if (i < prev->second) return false;
      if (i == prev->second) {
        prev->second = i + 1;
        if (next != iv.end() && next->first == i + 1) {
          prev->second = next->second;
          iv.erase(next);
        }
        return true;
      }
    }
    if (next != iv.end() && next->first == i + 1) {
      const int64_t e = next->second;
      iv.erase(next);
      iv.emplace(i, e);
    } else {
      iv.emplace(i, i + 1);
    }
    return true;
  };
  {
    cnc::bus::Bus bus("file://" + log + "?speed=0");
    if (verifier)
      bus.subscribe_raw(".*", [&](const std::string& ch, const void* d, size_t n, int64_t) {
        if (ch != cnc::bus::kLogFormatChannel) verifier->check(ch, d, n);  // the logger's own, unsigned
      });
    bus.subscribe_raw(cnc::bus::exact_channel(cnc::bus::kLogFormatChannel), [&](const std::string&, const void* d,
                                                                               size_t n, int64_t) {
      if (!format_seen) format_seen = cnc::bus::parse_log_format(d, n, &format);
    });
    bus.subscribe_raw(".*INTERP_CONFIG", [&](const std::string&, const void* d, size_t n, int64_t) {
      cnc::lcmt_config c;
      if (!decode(d, n, &c) || c.service != "cnc-interpolator") return;
      if (std::none_of(runs.begin(), runs.end(), [&](const auto& r) { return r.sender == c.sender; }))
        runs.push_back(std::move(c));
    });
    bus.subscribe_raw(".*INTERP_INPUT", [&](const std::string&, const void* d, size_t n, int64_t) {
      cnc::lcmt_interp_input in;
      if (!(decode(d, n, &in) || decode_v2(d, n, &in))) return;
      Seen& w = seen[in.sender];
      ++w.inputs;
      if (!add_index(w.indices, in.index)) ++w.copies;
      if (in.kind == cnc::lcmt_interp_input::BLOCK && in.block.program_token != w.last_token) {
        w.last_token = in.block.program_token;
        w.token_at.emplace(in.index, in.block.program_token);
      }
    });
    // The block delete switch each program was loaded with (the server's, not an
    // interpolator input): --program reads the edited program with it.
    bus.subscribe_raw(".*PROGRAM_STATE", [&](const std::string&, const void* d, size_t n, int64_t) {
      cnc::lcmt_program_state st;
      if (decode(d, n, &st) && st.state == cnc::lcmt_program_state::LOADED)
        block_delete_of.emplace(st.program_token, st.block_delete != 0);
    });
    bus.subscribe_raw(".*SETPOINTS", [&](const std::string&, const void* d, size_t n, int64_t) {
      cnc::lcmt_setpoint sp;
      if (!(decode(d, n, &sp) || decode_v1(d, n, &sp))) return;
      Seen& w = seen[sp.sender];
      ++w.setpoints;
      if (w.first_cycle < 0 || sp.cycle < w.first_cycle) w.first_cycle = sp.cycle;
      w.last_cycle = std::max(w.last_cycle, sp.cycle);
    });
    while (bus.handle(1000) > 0) {
    }
    for (const auto& [ch, st] : bus.stats()) {
      if (ch.ends_with("INTERP_INPUT") && st.decode_failures > 0) {
        std::fprintf(stderr, "cnc-replay: %lld undecodable inputs on %s\n", static_cast<long long>(st.decode_failures),
                     ch.c_str());
        return kExitUnreplayable;
      }
    }
  }
  if (verifier) {
    std::printf("signatures: %lld verified, %lld bad\n", static_cast<long long>(verifier->verified()),
                static_cast<long long>(verifier->bad()));
    if (verifier->bad() > 0) {
      for (const auto& [ch, c] : verifier->counts()) {
        if (c.bad_total() == 0) continue;
        std::fprintf(stderr, "cnc-replay: %s: %lld unsigned, %lld unknown key, %lld forged, %lld replayed\n",
                     ch.c_str(), static_cast<long long>(c.bad[0]), static_cast<long long>(c.bad[1]),
                     static_cast<long long>(c.bad[2]), static_cast<long long>(c.bad[4]));
      }
      std::fprintf(stderr, "cnc-replay: the log does not verify under %s: not replayed\n", key_file.c_str());
      return kExitUnreplayable;
    }
  }
  if (const std::string why = cnc::bus::unreadable_log_format(format); !why.empty()) {
    std::fprintf(stderr, "cnc-replay: %s: %s\n", log.c_str(), why.c_str());
    return kExitUnreplayable;
  }
  std::printf("log format %d%s, motion revision %d\n", format.format,
              format.version.empty() ? " (before format records)" : (" recorded by cnc " + format.version).c_str(),
              format.motion);
  // A log of another motion revision replays, and where it diverges that is by design.
  const auto diverged = [&]() {
    if (format.motion == cnc::bus::kMotionRevision) return kExitDiverged;
    std::printf("expected: the log's motion revision %d is not this cnc's %d (the same inputs make other setpoints by "
                "design); replay it with the version that recorded it%s\n",
                format.motion, cnc::bus::kMotionRevision,
                format.version.empty() ? "" : (" (cnc " + format.version + ")").c_str());
    return kExitUnreplayable;
  };
  if (runs.empty()) {
    std::fprintf(stderr, "cnc-replay: %s holds no interpolator config (INTERP_CONFIG): not a cell log?\n", log.c_str());
    return kExitUnreplayable;
  }
  std::printf("interpolator runs in the log: %zu; replaying run %d\n", runs.size(), run_no);
  if (static_cast<size_t>(run_no) > runs.size()) {
    std::fprintf(stderr, "cnc-replay: --run %d: the log holds %zu interpolator run(s)\n", run_no, runs.size());
    return cnc::service::kExitBadInput;
  }
  const cnc::lcmt_config* config = &runs[static_cast<size_t>(run_no - 1)];
  const int32_t sender = config->sender;
  int64_t foreign = 0;
  for (const auto& [who, w] : seen)
    if (who != sender) foreign += w.inputs + w.setpoints;
  const Seen& mine = seen[sender];
  // Inputs from the interpolator that sent the config, each index once (an input
  // the logger did not confirm in time was sent again: the copies are equal), in
  // index order; none may be missing.
  if (!mine.indices.empty()) {
    const auto& [first, end] = *mine.indices.begin();
    if (first != 0) {
      std::fprintf(stderr, "cnc-replay: the log starts after the interpolator's first input (index %lld)\n",
                   static_cast<long long>(first));
      return kExitUnreplayable;
    }
    if (mine.indices.size() > 1) {
      std::fprintf(stderr, "cnc-replay: inputs lost: INTERP_INPUT index %lld..%lld missing; the run cannot be reproduced\n",
                   static_cast<long long>(end), static_cast<long long>(std::next(mine.indices.begin())->first - 1));
      return kExitUnreplayable;
    }
  }
  const int64_t num_inputs = mine.indices.empty() ? 0 : mine.indices.begin()->second;
  if (mine.copies > 0) std::printf("inputs: %lld sent again after a loss, taken once\n", static_cast<long long>(mine.copies));
  if (mine.setpoints == 0) {
    std::fprintf(stderr, "cnc-replay: no setpoints of that interpolator in %s\n", log.c_str());
    return kExitUnreplayable;
  }

  // The machine file as the run loaded it, its relative paths (tool table, var file,
  // subroutine path) beside the file it was loaded from, as cnc-logexport reads it.
  const auto recorded = [&]() {
    try {
      return cnc::config::parse_machine_config(config->yaml, config->source_file);
    } catch (const cnc::config::ConfigError& e) {
      throw cnc::config::ConfigError(log, "INTERP_CONFIG",
                                     std::string("the machine file the run recorded (") + config->source_file +
                                         ") does not load here: " + e.what() + "; --machine FILE replays with another");
    }
  };
  const cnc::config::MachineConfig cfg =
      args.machine_file.empty() ? recorded() : cnc::config::load_machine_config(args.machine_file);
  const int naxes = static_cast<int>(cfg.axes.size());

  // --program: the blocks of another program in place of the recorded ones. It is
  // parsed at each recorded load of a program of that name, from where the machine
  // then stood, as the live server does, with the dry run's setup: the cell's, but the
  // machine's var file and tool table are read, never written.
  std::optional<cnc::pps::ProgramServer> other;
  if (!args.option("program").empty()) other.emplace(cnc::pps::dry_run_setup(cfg), cnc::pps::ServerLimits{});

  const auto t0 = std::chrono::steady_clock::now();
  // The planner inline: every plan is ready when its block is submitted and is taken
  // at the cycle the log recorded (PLAN inputs), as live.
  cnc::interp::SyncPlanLink planner(cfg);
  cnc::interp::Interpolator core(cfg, planner);
  const int64_t last_cycle = mine.last_cycle;
  const auto base_name = [](const std::string& path) { return path.substr(path.find_last_of('/') + 1); };
  const std::string other_name = other ? base_name(args.option("program")) : "";
  bool substituting = false;  // the recorded program now running has other_name
  int64_t substituted = 0;
  int64_t applied = 0;
  int64_t compared = 0;
  // The second pass: inputs and setpoints of this run as the log gives them, held
  // only until their cycle is replayed (inputs by index: a copy sent again comes later).
  std::map<int64_t, cnc::lcmt_interp_input> inputs;  // index >= next_index
  std::map<int64_t, cnc::lcmt_setpoint> setpoints;   // cycle >= the cycle being replayed
  int64_t next_index = 0;
  cnc::bus::Bus bus("file://" + log + "?speed=0");
  bus.subscribe_raw(".*INTERP_INPUT", [&](const std::string&, const void* d, size_t n, int64_t) {
    cnc::lcmt_interp_input in;
    if ((decode(d, n, &in) || decode_v2(d, n, &in)) && in.sender == sender && in.index >= next_index)
      inputs.emplace(in.index, std::move(in));
  });
  bus.subscribe_raw(".*SETPOINTS", [&](const std::string&, const void* d, size_t n, int64_t) {
    cnc::lcmt_setpoint sp;
    if ((decode(d, n, &sp) || decode_v1(d, n, &sp)) && sp.sender == sender) setpoints.emplace(sp.cycle, std::move(sp));
  });
  bool log_ended = false;
  const auto read_more = [&]() {
    if (!log_ended && bus.handle(1000) <= 0) log_ended = true;
    return !log_ended;
  };
  // Setpoints come in cycle order but for a datagram overtaken on the way: a few later.
  constexpr int64_t kReorder = 16;
  for (int64_t cycle = 0; cycle <= last_cycle; ++cycle) {
    for (;;) {
      if (next_index >= num_inputs) break;
      while (!inputs.count(next_index) && read_more()) {
      }
      auto found = inputs.find(next_index);
      if (found == inputs.end()) {
        std::fprintf(stderr, "cnc-replay: input %lld not found again in %s\n", static_cast<long long>(next_index),
                     log.c_str());
        return kExitUnreplayable;
      }
      if (found->second.cycle > cycle) break;
      if (found->second.cycle < cycle) {
        std::fprintf(stderr, "cnc-replay: inputs out of cycle order at index %lld\n", static_cast<long long>(next_index));
        return kExitUnreplayable;
      }
      cnc::lcmt_interp_input in = std::move(found->second);
      inputs.erase(found);
      ++next_index;
      ++applied;
      if (in.kind == cnc::lcmt_interp_input::COMMAND && in.command.command == cnc::lcmt_program_command::LOAD) {
        substituting = other && base_name(in.command.program_path) == other_name;
        if (substituting) {
          // The program this LOAD became: the token of the next recorded block.
          if (const auto t = mine.token_at.upper_bound(in.index); t != mine.token_at.end())
            if (const auto bd = block_delete_of.find(t->second); bd != block_delete_of.end())
              other->set_block_delete(bd->second);
          std::vector<double> here(naxes);
          for (int a = 0; a < naxes; ++a)
            here[a] = core.last().num_axes > 0 ? core.last().position_mm[a] : cfg.axes[a].home_mm;
          const auto r = other->load(args.option("program"), 1, here);
          if (!r.ok) {
            std::fprintf(stderr, "cnc-replay: program refused: %s\n", r.error.c_str());
            return kExitUnreplayable;
          }
        }
      }
      if (substituting && in.kind == cnc::lcmt_interp_input::BLOCK) {
        ++substituted;
        const cnc::program::Block* b = other->block(in.block.block_index);
        if (b == nullptr) {
          std::printf("diverges at cycle %lld: the recorded block %lld is not in %s\n", static_cast<long long>(cycle),
                      static_cast<long long>(in.block.block_index), args.option("program").c_str());
          return diverged();
        }
        in.block = cnc::program::to_msg(*b, in.block.program_token);
      }
      const std::string why = cnc::interp::apply_recorded_input(core, in, naxes);
      if (!why.empty()) {
        std::printf("diverges at cycle %lld: input %lld was applied live but is refused now: %s\n",
                    static_cast<long long>(cycle), static_cast<long long>(in.index), why.c_str());
        return diverged();
      }
    }
    const cnc::interp::Setpoint& sp = core.step();
    while ((setpoints.empty() || setpoints.rbegin()->first < cycle + kReorder) && read_more()) {
    }
    while (!setpoints.empty() && setpoints.begin()->first < cycle) setpoints.erase(setpoints.begin());
    auto it = setpoints.find(cycle);
    if (it == setpoints.end()) continue;
    const std::string diff = compare(it->second, sp, cfg.ipo_period_s);
    if (!diff.empty()) {
      std::printf("diverges at cycle %lld (t = %.3f s, block %lld, line %d): %s\n", static_cast<long long>(cycle),
                  static_cast<double>(cycle) * cfg.ipo_period_s, static_cast<long long>(it->second.block_index),
                  it->second.source_line, diff.c_str());
      std::printf("%lld setpoints identical before it\n", static_cast<long long>(compared));
      return diverged();
    }
    setpoints.erase(it);
    ++compared;
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (other && substituted == 0)
    std::printf("note: no recorded program is named %s; nothing was substituted\n", other_name.c_str());
  const double run_s = static_cast<double>(last_cycle + 1) * cfg.ipo_period_s;
  const int64_t missing = last_cycle + 1 - compared;
  std::printf("identical: %lld setpoints compared bit for bit (cycles %lld..%lld%s), %zu inputs applied; "
              "%.1f s of run replayed in %.3f s (%.0fx real time)\n",
              static_cast<long long>(compared), static_cast<long long>(mine.first_cycle),
              static_cast<long long>(last_cycle),
              missing > 0 ? (", " + std::to_string(missing) + " cycles not in the log").c_str() : "",
              static_cast<size_t>(applied), run_s,
              wall, run_s / std::max(wall, 1e-9));
  if (foreign > 0) std::printf("(%lld messages of other interpolator runs in the log were not replayed)\n",
                               static_cast<long long>(foreign));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-replay", "deterministic re-run of the interpolator from a log, compared bit for bit",
                          
                          {{"log", "LOG", "the recorded run"},
                           {"program", "FILE", "replay with this version of a recorded program (same file name)"},
                           {"key", "KEYFILE", "verify every message's MAC first; a log that does not verify is refused"},
                           {"run", "N", "which interpolator run of the log (1: the first; a restart begins a new one)"}},
                          {},
                          false};
  return cnc::service::run(spec, argc, argv, replay);
}
