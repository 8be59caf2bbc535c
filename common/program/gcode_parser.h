#pragma once
// RS274 part-program parser: G0 G1 G2 G3 G4 G17-G19 G20 G21 G90 G91, F S P N,
// M2 M3 M5 M30, ( ) and ; comments, `(PROCESS, KEY=VALUE, ...)` directives, and
// NURBS in two dialects: Fanuc G06.2 and LinuxCNC G5.2/G5.3. Every refusal names
// file:line:column and what was expected.
//
// One code path reads a program line by line and hands each block to a sink as it
// is completed. parse() collects them all (small programs, tests); the part-program
// server instead validates a whole file once and later resumes parsing from saved
// ParserStates to re-create any block, so it never holds a whole program.
#include <cstdint>
#include <istream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/program/block.h"

namespace cnc::program {

struct SourceLocation {
  std::string file;
  int line = 0;
  int column = 0;
  std::string str() const { return file + ":" + std::to_string(line) + ":" + std::to_string(column); }
};

class ProgramError : public std::runtime_error {
 public:
  ProgramError(SourceLocation where, const std::string& what);
  const SourceLocation& where() const { return where_; }
  const std::string& detail() const { return detail_; }

 private:
  SourceLocation where_;
  std::string detail_;
};

struct ParserSettings {
  std::vector<std::string> axis_names;  // machine axes in order, e.g. X Y Z
  std::vector<double> start_position_mm;
  double default_feed_mm_per_min = 0;   // 0: a feed move before any F is an error
  double spindle_rpm = 0;
  ProcessParams process;
};

struct Program {
  std::string file;
  std::vector<Block> blocks;  // the last block has kind kEnd
};

// Everything the parser carries from one line to the next. Taken at a line
// boundary outside any NURBS curve, it lets parsing resume at `offset` exactly as
// if the file had been read from its start.
struct ParserState {
  int64_t offset = 0;        // bytes of the file consumed
  int32_t line = 0;          // lines consumed
  int64_t next_index = 0;    // blocks emitted so far
  uint64_t content_hash = 14695981039346656037ull;  // FNV-1a of the bytes consumed: a file changed under us
  std::vector<double> position_mm;
  int motion = -1;           // active motion code in tenths (0, 10, 20, 30); -1: none
  int plane = 17;            // 17, 18, 19
  double unit_mm = 1.0;      // 25.4 under G20
  bool absolute = true;      // G90 / G91
  double feed_mm_per_min = 0;
  double spindle_speed_rpm = 0;
  bool spindle_on = false;
  ProcessParams process;
};

// Receives blocks in order. Either call may return false to stop reading early.
class BlockSink {
 public:
  virtual ~BlockSink() = default;
  virtual bool block(Block&& b) = 0;
  // Called before every line read outside a NURBS curve: parsing may later resume
  // from a copy of `state`.
  virtual bool resume_point(const ParserState& state) {
    (void)state;
    return true;
  }
  // Called once after the end block, with the state after the last line read.
  virtual void finished(const ParserState& state) { (void)state; }
};

class GcodeParser {
 public:
  explicit GcodeParser(ParserSettings settings);

  // The state at the start of a program: settings' position, feed, spindle, process.
  ParserState initial_state() const;

  // Parses `in` from its current position, which must be from.offset, and hands
  // each block to `sink`. Throws ProgramError on the first fault. The last block of
  // a program read to its end is kEnd (after M2/M30 or at the end of the input).
  void stream(std::istream& in, const std::string& file_label, const ParserState& from, BlockSink& sink) const;

  // The whole program in memory. Throws ProgramError on the first fault.
  Program parse(std::istream& in, const std::string& file_label) const;
  Program parse_file(const std::string& path) const;

  const ParserSettings& settings() const { return settings_; }

 private:
  ParserSettings settings_;
};

}  // namespace cnc::program
