#pragma once
// The cell's own comment directive for Choi et al. 2005's roughness law:
//   (PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)
// any subset of the keys, any case; BALL_RADIUS and PICK_FEED in mm and RMAX_UM in µm
// whatever G20/G21 say; RMAX_UM=0 switches the law off. LinuxCNC reads it as a plain
// comment. The one owner of the directive's rules.
#include <string_view>

#include "common/rs274/canon.h"

namespace cnc::rs274 {

// `body` is the comment's text between its parentheses, `body_column` the column of
// its first character. Returns false when the comment is not a directive ("(PROCESS
// the part)" is a remark). Throws Error(column, detail) for a malformed directive.
bool parse_process_directive(std::string_view body, int body_column, ProcessSettings* out);

}  // namespace cnc::rs274
