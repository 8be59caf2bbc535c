#include "common/drive/link_factory.h"

#include <stdexcept>

#include "common/drive/loopback_link.h"
#include "common/drive/modbus_link.h"

namespace cnc::drive {

Transport transport_of(const config::DriveConfig& d) {
  if (const auto t = transport_named(d.transport)) return *t;
  throw std::invalid_argument("unknown drive transport '" + d.transport + "'");
}

std::unique_ptr<Link> make_link(const config::DriveConfig& d) {
  switch (transport_of(d)) {
    case Transport::kModbusTcp: return ModbusLink::tcp(d.host, d.port, d.response_timeout_s);
    case Transport::kModbusRtu: {
      const char parity = d.parity == "even" ? 'E' : d.parity == "odd" ? 'O' : 'N';
      return ModbusLink::rtu(d.device, d.baud, parity, d.stop_bits, d.response_timeout_s);
    }
    case Transport::kLoopback: return std::make_unique<LoopbackLink>();
  }
  throw std::invalid_argument("unknown drive transport '" + d.transport + "'");
}

}  // namespace cnc::drive
