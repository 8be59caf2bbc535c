#include "tools/servo_sim/fault_injector.h"

#include <sstream>
#include <stdexcept>

namespace cnc::servo_sim {

std::string FaultInjector::apply(const std::string& line, double now_s) {
  std::istringstream in(line);
  std::string what;
  if (!(in >> what)) return "";
  auto number = [&](double fallback, bool required, double& v) {
    std::string tok;
    if (!(in >> tok)) {
      v = fallback;
      return !required;
    }
    try {
      size_t used = 0;
      v = std::stod(tok, &used);
      return used == tok.size();
    } catch (const std::exception&) {
      return false;
    }
  };
  double a = 0, b = 0;
  if (what == "drop") {
    if (!number(0, true, a) || a < 0) return "drop needs seconds";
    drop_until_s_ = now_s + a;
  } else if (what == "delay") {
    if (!number(0, true, a) || !number(1e9, false, b) || a < 0) return "delay needs milliseconds [seconds]";
    delay_s_ = a * 1e-3;
    delay_until_s_ = now_s + b;
  } else if (what == "exception") {
    if (!number(0, true, a) || !number(1, false, b) || a < 1 || a > 255) return "exception needs a code 1..255 [count]";
    exception_code_ = static_cast<int>(a);
    exceptions_left_ = static_cast<int>(b);
  } else if (what == "crc") {
    if (!number(1, false, a)) return "crc takes a count";
    crc_left_ = static_cast<int>(a);
  } else if (what == "fault") {
    std::string axis, code;
    in >> axis >> code;
    if (axis.empty()) return "fault needs an axis name";
    uint16_t c = 0x7500;
    try {
      if (!code.empty()) c = static_cast<uint16_t>(std::stoul(code, nullptr, 0));
    } catch (const std::exception&) {
      return "fault code '" + code + "' is not a number";
    }
    if (!on_fault_(axis, c)) return "no axis '" + axis + "'";
  } else if (what == "jam") {
    std::string axis;
    in >> axis;
    if (axis.empty()) return "jam needs an axis name";
    if (!on_jam_(axis, true)) return "no axis '" + axis + "'";
  } else if (what == "clear") {
    on_jam_("", false);
    drop_until_s_ = -1;
    delay_until_s_ = -1;
    exceptions_left_ = 0;
    crc_left_ = 0;
  } else {
    return "unknown command '" + what + "' (drop, delay, exception, crc, fault, jam, clear)";
  }
  return "";
}

void FaultInjector::schedule(const std::string& spec, double start_s) {
  std::istringstream in(spec);
  std::string item;
  while (std::getline(in, item, ';')) {
    const auto colon = item.find(':');
    if (item.find_first_not_of(" \t") == std::string::npos) continue;
    if (colon == std::string::npos) throw std::invalid_argument("--inject entry '" + item + "': expected T:COMMAND");
    double t = 0;
    try {
      t = std::stod(item.substr(0, colon));
    } catch (const std::exception&) {
      throw std::invalid_argument("--inject entry '" + item + "': bad time");
    }
    const std::string command = item.substr(colon + 1);
    // Check it now, on a scratch injector, so a typo fails at start-up.
    FaultInjector probe([](const std::string&, uint16_t) { return true; });
    const std::string why = probe.apply(command, 0.0);
    if (!why.empty()) throw std::invalid_argument("--inject entry '" + item + "': " + why);
    scheduled_.push_back({start_s + t, command});
  }
}

void FaultInjector::poll(double now_s) {
  for (auto it = scheduled_.begin(); it != scheduled_.end();) {
    if (it->at_s > now_s) {
      ++it;
      continue;
    }
    apply(it->command, now_s);
    it = scheduled_.erase(it);
  }
}

int FaultInjector::take_exception() {
  if (exceptions_left_ <= 0) return 0;
  --exceptions_left_;
  return exception_code_;
}

bool FaultInjector::take_crc() {
  if (crc_left_ <= 0) return false;
  --crc_left_;
  return true;
}

}  // namespace cnc::servo_sim
