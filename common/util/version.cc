// Only this file includes the generated version header: a new commit recompiles it alone.
#include "cnc_version.h"
#include "common/util/install.h"

namespace cnc::util {
const char* version() { return CNC_VERSION; }
}  // namespace cnc::util
