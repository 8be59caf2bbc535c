#pragma once
// The part-program server core: validates a whole program by interpreting it once to
// its end, then serves its blocks by index without holding the program in memory. A
// refused program leaves the previously accepted one as it was. No LCM here;
// program_server_node.h is the network side.
//
// Memory: validation keeps one 64-bit hash per chunk of `blocks_per_chunk` blocks.
// Serving runs a second interpreter forward through the program (loops and
// subroutines run again, as they do on LinuxCNC), a chunk at a time, into a small
// cache of chunks; each chunk must hash as it did at validation, so a file changed
// after it was validated is refused, never served. A block before the serving
// interpreter's position (rare: the interpolator asks for blocks in order) restarts
// it from the program's start. Memory is O(blocks / chunk) + a few chunks, whatever
// the program's length or the number of times its loops run.
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/program/block.h"
#include "common/rs274/block_builder.h"
#include "common/rs274/interpreter.h"

namespace cnc::pps {

struct LoadResult {
  bool ok = false;
  std::string error;  // "file:line:column: what was expected" (+ the chain of subroutine calls)
  std::string file;   // the file of the fault (a subroutine file possibly)
  int line = 0;
  int column = 0;
  // Accepted, but worth a look: "file:line:column: what" (a dwell over 10 minutes;
  // at most 20, then a count).
  std::vector<std::string> warnings;
};

// The machine's answer to a probing move (G38.x): where the probe input changed and
// where the machine came to rest, machine coordinates (mm), one value per axis.
struct ProbeResult {
  bool tripped = false;
  std::vector<double> trip_mm, rest_mm;
};

// The machine's answer to a block whose result the rest of the program reads
// (program::Block::awaits_result): a probing move's or an input wait's (M66).
struct MachineResult {
  bool is_probe = false;
  ProbeResult probe;
  double input_value = 0;  // M66: the value read, -1 when its wait timed out (#5399)
};

struct ServerLimits {
  int blocks_per_chunk = 256;
  int cached_chunks = 4;
};

// Everything the language needs from the machine: the interpreter's set-up and the
// block builder's (axes, start, spindle, process).
struct ProgramSetup {
  rs274::MachineSetup machine;
  rs274::BuilderSetup builder;
  int64_t max_validation_lines = 200'000'000;
  // Travel per axis (machine coordinates, mm), in the builder's axis order: the
  // validation run refuses a program whose path leaves it. Empty: not checked.
  std::vector<std::pair<double, double>> travel_mm;
  // Run from line N: the approach's safe height (machine Z, mm; NaN: Z's travel maximum).
  double safe_z_mm = std::numeric_limits<double>::quiet_NaN();
};

ProgramSetup program_setup(const config::MachineConfig& cfg);

// The dry run's setup (cnc-plan, which the HMI's preview runs): the cell's, from the
// same machine file, with the language's files the command line names in place of the
// config's, and the var file and the tool table read but never written (they are the
// machine's, kept by the runs that move it). dry_run_agreement_test holds the two
// alike on every shipped machine file.
struct DryRunFiles {
  std::vector<std::string> subroutine_path;  // empty: program.subroutine_path
  std::string tool_table;                    // empty: program.tool_table
};
ProgramSetup dry_run_setup(const config::MachineConfig& cfg, const DryRunFiles& files = {});

// Every field of a setup, one "key = value" line each (numbers to 17 digits): what
// dry_run_agreement_test compares, and what `cnc-plan --show-setup` prints.
std::string describe(const ProgramSetup& s);

class ProgramServer {
 public:
  // Probing and input waits: the validation takes each G38.x move as tripped at its
  // end and each M66 as LinuxCNC's rs274 reads it (#5399 as it was, a digital input 0
  // or 1); the blocks after one depend on the machine's result. live_probing (a cell):
  // no block after such a block is served before probe_result() or input_result() has
  // given its result and the rest of the program has been validated again with it.
  // Otherwise (the dry run) the blocks are served as validated.
  explicit ProgramServer(const config::MachineConfig& cfg, ServerLimits limits = {});
  ProgramServer(ProgramSetup setup, ServerLimits limits);
  ~ProgramServer();

  // token: the caller's unique id of this load. start_position_mm: where the
  // machine stands (one entry per axis); empty: the config's home position.
  LoadResult load(const std::string& path, int64_t token, const std::vector<double>& start_position_mm = {});
  // Run from line N (README "Run from line N"): the whole program is interpreted (and
  // validated) as by load(), without motion up to the main file's line N; what is
  // served is an approach from where the machine stands (Z up to the safe height,
  // across to the start point of line N, the tool change, spindle and coolant the
  // program had set there as events, down to the start point, a dwell of 0 s: at rest
  // there) and then the program's blocks from line N on, numbered from the approach's
  // end. from_line <= 0: load().
  LoadResult load_from(const std::string& path, int64_t token, const std::vector<double>& start_position_mm,
                       int from_line);
  int from_line() const { return program_ ? program_->from_line : 0; }
  // The approach (what an operator confirms), "" for a program run from its start.
  const std::string& approach_text() const;
  int64_t approach_blocks() const { return program_ ? static_cast<int64_t>(program_->approach.size()) : 0; }
  // The interpreter's state before line N, as the validation run and the serving run
  // reached it (the serving one once it has served that far; false before).
  const rs274::ModalState& state_at_from() const { return program_->state_at_from; }
  bool serving_state_at_from(rs274::ModalState* out) const {
    if (!serving_reached_) return false;
    *out = serving_state_;
    return true;
  }
  // MDI: the next load is one line (then M2) that starts in `modes` (nullptr: as a
  // program starts); once it is loaded, modes_after() is the state after the line.
  void next_load_is_line(const rs274::ModalState* modes) {
    next_is_line_ = true;
    next_modes_.reset();
    if (modes != nullptr) next_modes_ = *modes;
  }
  const std::optional<rs274::ModalState>& modes_after() const {
    static const std::optional<rs274::ModalState> kNone;
    return program_ ? program_->modes_after : kNone;
  }
  bool loaded() const { return program_ != nullptr; }
  int64_t token() const { return program_ ? program_->token : 0; }
  const std::string& path() const;
  int64_t num_blocks() const { return program_ ? program_->num_blocks : 0; }
  int64_t lines_interpreted() const { return program_ ? program_->lines : 0; }

  // Block `index` of the loaded program; nullptr outside it, or when the program no
  // longer interprets as it did when it was validated (serving_error() then says
  // why, and the program stays unserved until the next load). The pointer stays
  // valid until the next call.
  const program::Block* block(int64_t index);
  const std::string& serving_error() const { return serving_error_; }

  void set_live_probing(bool on) { live_probing_ = on; }
  // Block `index` comes after a probing move or an input wait whose result is not
  // known yet (block() gives nullptr without an error: not yet).
  bool awaiting_result(int64_t index) const;
  // The block (of the whole program) whose result is awaited; -1: none awaited.
  int64_t awaited_result_block() const;
  // ...and whether it is a probing move (else an input wait).
  bool awaited_result_is_probe() const;
  // The result of the probing move at block `index` (the awaited one): the program is
  // validated again from its start with every result so far; on a refusal (an error
  // the result leads to, a path out of travel) the program is unloaded and the
  // result says why, at its file and line. num_blocks() may change.
  LoadResult probe_result(int64_t index, const ProbeResult& result);
  // The same for the input wait (M66) at block `index`: the value it read (#5399).
  LoadResult input_result(int64_t index, double value);
  int64_t probes_known() const { return program_ ? program_->probes_known : 0; }
  int64_t inputs_known() const { return program_ ? static_cast<int64_t>(program_->results.size()) - program_->probes_known : 0; }

  // Called as a validation begins and every 4,096 blocks of it with the blocks so far:
  // a program of millions of lines validates for seconds (a minute on a busy machine),
  // and the node keeps its heartbeat going.
  void on_validation_progress(std::function<void(int64_t)> f) { progress_ = std::move(f); }

  const ProgramSetup& setup() const { return setup_; }
  // The block delete switch ('/' lines skipped when on) for the programs loaded from now
  // on; a loaded program keeps the value it was loaded with.
  void set_block_delete(bool on) { setup_.machine.block_delete = on; }
  bool block_delete() const { return setup_.machine.block_delete; }
  // For tests and the benchmark.
  size_t num_checkpoints() const { return program_ ? program_->chunk_hashes.size() : 0; }
  int64_t chunk_reads() const { return chunk_reads_; }
  int64_t restarts() const { return restarts_; }

 private:
  class Run;
  std::function<void(int64_t)> progress_;
  struct Loaded {
    std::string path;
    int64_t token = 0;
    std::vector<double> start;
    bool block_delete = true;  // as loaded: the serving run reads the program the same way
    std::vector<uint64_t> chunk_hashes;
    int64_t num_blocks = 0;   // served (the approach's and the program's from line N)
    int64_t full_blocks = 0;  // of the whole program
    int from_line = 0;
    int64_t from_block = 0;   // the program's first block from line N
    std::vector<program::Block> approach;
    std::string approach_text;
    rs274::ModalState state_at_from;
    int64_t lines = 0;
    bool line = false;  // MDI
    std::optional<rs274::ModalState> modes_in, modes_after;
    std::vector<MachineResult> results;   // the machine's results so far, in order
    int64_t probes_known = 0;             // ...of which probing moves'
    std::vector<int64_t> result_blocks;   // each block awaiting a result (of the whole program)
    std::vector<bool> result_is_probe;    // ...a probing move (else an input wait)
    std::vector<uint64_t> result_hashes;  // its chunk's hash up to and including it
  };
  struct Chunk {
    int64_t first = -1;
    std::vector<program::Block> blocks;
    uint64_t last_use = 0;
  };

  std::unique_ptr<Run> start_run(const Loaded& p, bool validating) const;
  LoadResult add_result(int64_t index, const MachineResult& result);
  // Interprets p's program to its end (with p.results), fills p's counts and hashes;
  // r gets the refusal.
  bool validate(Loaded& p, LoadResult& r) const;
  void install(std::unique_ptr<Loaded> p);
  const Chunk* chunk_for(int64_t index);
  const program::Block* full_block(int64_t index);
  // The approach of a run from line N into p.approach (and its text): "" or why not.
  std::string make_approach(Loaded& p, const std::vector<double>& target, const program::Block* tool,
                            const program::Block* spindle, const program::Block* coolant) const;

  ProgramSetup setup_;
  ServerLimits limits_;
  std::unique_ptr<Loaded> program_;
  std::unique_ptr<Run> serving_;
  int64_t serving_next_ = 0;     // the index of the block the serving run makes next
  uint64_t chunk_hash_ = 0;
  std::vector<Chunk> cache_;
  uint64_t use_clock_ = 0;
  int64_t chunk_reads_ = 0;
  int64_t restarts_ = 0;
  std::string serving_error_;
  bool serving_reached_ = false;
  rs274::ModalState serving_state_;
  program::Block renumbered_;
  bool next_is_line_ = false;
  bool live_probing_ = false;
  std::optional<rs274::ModalState> next_modes_;
};

// A hash of everything in a block that the interpolator uses (FNV-1a over the bits).
uint64_t block_hash(const program::Block& b, uint64_t h);

}  // namespace cnc::pps
