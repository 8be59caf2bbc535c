#pragma once
// The one place a drive config becomes a link: the drive bridge and the benches make
// their links here, by the transport the config names (transport.h).
#include <memory>

#include "common/config/machine_config.h"
#include "common/drive/link.h"
#include "common/drive/transport.h"

namespace cnc::drive {

// The transport of a config the reader accepted (std::invalid_argument otherwise).
Transport transport_of(const config::DriveConfig& d);

// A closed link for the drive's transport: Modbus TCP to host:port, Modbus RTU on
// device with the line settings, or an empty LoopbackLink (its drives are added by
// the caller, which knows their profiles and start positions).
std::unique_ptr<Link> make_link(const config::DriveConfig& d);

}  // namespace cnc::drive
