#pragma once
// The drive transports a machine config may name (axes[].drive.transport): the
// config reader accepts these names, make_link (link_factory.h) makes the link of
// each, and the servo simulator serves the Modbus ones. A new transport is a name
// and an enumerator here, a case in make_link and a Link implementation.
#include <array>
#include <optional>
#include <string_view>
#include <utility>

namespace cnc::drive {

enum class Transport { kModbusTcp, kModbusRtu, kLoopback };

inline constexpr std::array<std::pair<Transport, std::string_view>, 3> kTransports{{
    {Transport::kModbusTcp, "modbus_tcp"},
    {Transport::kModbusRtu, "modbus_rtu"},  // a serial line (RS-485), the drives as unit ids on it
    {Transport::kLoopback, "loopback"},     // drives emulated in process (LoopbackLink)
}};

constexpr std::optional<Transport> transport_named(std::string_view name) {
  for (const auto& [t, n] : kTransports)
    if (n == name) return t;
  return std::nullopt;
}

constexpr std::string_view transport_name(Transport t) {
  for (const auto& [u, n] : kTransports)
    if (u == t) return n;
  return "?";
}

}  // namespace cnc::drive
