#pragma once
// The format of the cell's log files. Every file the logger writes begins with one
// event on kLogFormatChannel whose data is the text "cnc-log-format N VERSION" (N
// the format, VERSION the logger's). A log without it was recorded in format 1.
// Readers take every format from kOldestReadableLogFormat on and refuse the others
// with the format, the version that recorded it and what to do.
//
// Formats (one golden log each in tests/golden/logs, replayed by the suite):
//   1  no format event; SETPOINTS without stream and engagement (lcmt_setpoint_v1)
//   2  the format event; SETPOINTS carry the stream and the bridge's engagement
//   3  blocks (PROGRAM_BLOCKS, INTERP_INPUT) carry the path tolerance (lcmt_program_block_v2
//      and lcmt_interp_input_v2 read formats 1 and 2)
//   4  SPINDLE_STATUS carries the encoder's position and the orientation's state
//      (lcmt_spindle_status_v1 reads formats 1 to 3: common/service/spindle_status_msg.h),
//      SPINDLE_CMD the orientation (no reader of logs takes SPINDLE_CMD; its leading
//      fields, which the integration tests read, are unchanged)
#include <cstddef>
#include <string>

namespace cnc::bus {

inline constexpr int kLogFormat = 4;

// The interpolator's behaviour: the same inputs give the same setpoints within one
// revision; a revision changes them by design (the format event carries it from
// format 3 on, "cnc-log-format N VERSION motion R"; older logs are revision 1).
// cnc-replay replays a log of another revision and, where it diverges, says so.
//   1  up to format 3
//   2  a stop point reached with motion rests two cycles (the bridge's moving averages
//      then never mix the two directions)
//   3  the look-ahead brakes for a block's entry with the limits of the blocks before
//      it, not with the entered block's lower ones
inline constexpr int kMotionRevision = 3;
inline constexpr int kOldestReadableLogFormat = 1;
inline constexpr char kLogFormatChannel[] = "CNC_LOG_FORMAT";

// The data of the format event that begins each file, this build's.
std::string log_format_record();

struct LogFormat {
  int format = 1;       // 1 when the log has no format event
  std::string version;  // the logger's version; empty for format 1
  int motion = 1;       // the motion revision (kMotionRevision) of the cell that recorded it
};
// Parses a format event's data; false when it is not one.
bool parse_log_format(const void* data, size_t size, LogFormat* out);
// "" when this build reads `f`; otherwise why not and what to do.
std::string unreadable_log_format(const LogFormat& f);

}  // namespace cnc::bus
