#pragma once
// RS274 part-program parser. Every refusal names file:line:column and what was
// expected; a program is parsed and validated whole before any block is used.
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

class GcodeParser {
 public:
  explicit GcodeParser(ParserSettings settings);
  // Throws ProgramError on the first fault.
  Program parse(std::istream& in, const std::string& file_label) const;
  Program parse_file(const std::string& path) const;

 private:
  ParserSettings settings_;
};

}  // namespace cnc::program
