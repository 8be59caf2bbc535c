#pragma once
// The part-program server core: validates a whole program file, then serves its
// blocks by index without holding the program in memory. A refused program leaves
// the previously accepted one as it was. No LCM here; program_server_node.h is the
// network side.
//
// Memory: load() parses the file once, to its end, keeping only a ParserState every
// `blocks_per_chunk` blocks (a checkpoint: file offset, line, modal state, block
// index, hash of the bytes so far). Serving block i re-parses the chunk that holds
// it from its checkpoint into a small cache of chunks. Memory is O(blocks / chunk)
// for the checkpoints plus a few chunks, whatever the program's length. Each chunk
// re-read must reproduce the hash and block count seen at load time, so a file
// changed after it was validated is refused, never served.
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/program/gcode_parser.h"

namespace cnc::pps {

struct LoadResult {
  bool ok = false;
  std::string error;  // "file:line:column: what was expected"
  int line = 0;
  int column = 0;
};

struct ServerLimits {
  int blocks_per_chunk = 256;
  int64_t bytes_per_chunk = int64_t{1} << 20;  // also cut a chunk after this many bytes of source
  int cached_chunks = 4;
};

class ProgramServer {
 public:
  explicit ProgramServer(const config::MachineConfig& cfg, ServerLimits limits = {});
  ProgramServer(program::ParserSettings settings, ServerLimits limits);

  // token: the caller's unique id of this load. start_position_mm: where the
  // machine stands (one entry per axis); empty: the config's home position.
  LoadResult load(const std::string& path, int64_t token, const std::vector<double>& start_position_mm = {});
  bool loaded() const { return program_ != nullptr; }
  int64_t token() const { return program_ ? program_->token : 0; }
  const std::string& path() const;
  int64_t num_blocks() const { return program_ ? program_->num_blocks : 0; }

  // Block `index` of the loaded program; nullptr outside it, or when the file no
  // longer reads as it did when it was validated (serving_error() then says why,
  // and the program stays unserved until the next load). The pointer stays valid
  // until the next call.
  const program::Block* block(int64_t index);
  const std::string& serving_error() const { return serving_error_; }

  // For tests and the benchmark.
  size_t num_checkpoints() const { return program_ ? program_->checkpoints.size() : 0; }
  int64_t chunk_reads() const { return chunk_reads_; }

 private:
  struct Loaded {
    std::string path;
    int64_t token = 0;
    std::unique_ptr<std::ifstream> in;  // kept open: a file replaced by rename still reads as validated
    std::vector<program::ParserState> checkpoints;  // checkpoints[0] is the program's start
    program::ParserState end;                       // after the last line read
    int64_t num_blocks = 0;
  };
  struct Chunk {
    int64_t first = -1;  // block index of blocks[0]
    std::vector<program::Block> blocks;
    uint64_t last_use = 0;
  };

  const Chunk* chunk_for(int64_t index);
  bool read_chunk(size_t c, Chunk* out);

  program::GcodeParser parser_;
  ServerLimits limits_;
  std::unique_ptr<Loaded> program_;
  std::vector<Chunk> cache_;
  uint64_t use_clock_ = 0;
  int64_t chunk_reads_ = 0;
  std::string serving_error_;
};

program::ParserSettings parser_settings(const config::MachineConfig& cfg);

}  // namespace cnc::pps
