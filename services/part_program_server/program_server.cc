#include "services/part_program_server/program_server.h"

#include <algorithm>

namespace cnc::pps {

namespace {

// The load pass: counts blocks, drops them, and keeps a checkpoint every chunk.
class Indexer : public program::BlockSink {
 public:
  Indexer(const ServerLimits& limits, std::vector<program::ParserState>* checkpoints)
      : limits_(limits), checkpoints_(checkpoints) {}
  bool block(program::Block&&) override { return true; }
  bool resume_point(const program::ParserState& s) override {
    const program::ParserState* last = checkpoints_->empty() ? nullptr : &checkpoints_->back();
    if (!last || s.next_index - last->next_index >= limits_.blocks_per_chunk ||
        (s.offset - last->offset >= limits_.bytes_per_chunk && s.next_index > last->next_index))
      checkpoints_->push_back(s);
    return true;
  }
  void finished(const program::ParserState& s) override { end = s; }

  program::ParserState end;

 private:
  const ServerLimits& limits_;
  std::vector<program::ParserState>* checkpoints_;
};

// The serve pass: the blocks of one chunk, up to the next checkpoint's offset.
class ChunkReader : public program::BlockSink {
 public:
  ChunkReader(int64_t stop_offset, std::vector<program::Block>* out) : stop_offset_(stop_offset), out_(out) {}
  bool block(program::Block&& b) override {
    out_->push_back(std::move(b));
    return true;
  }
  bool resume_point(const program::ParserState& s) override {
    if (stop_offset_ < 0 || s.offset < stop_offset_) return true;
    reached = s;
    return false;
  }
  void finished(const program::ParserState& s) override { reached = s; }

  program::ParserState reached;

 private:
  int64_t stop_offset_;
  std::vector<program::Block>* out_;
};

bool same_place(const program::ParserState& a, const program::ParserState& b) {
  return a.offset == b.offset && a.next_index == b.next_index && a.content_hash == b.content_hash;
}

}  // namespace

program::ParserSettings parser_settings(const config::MachineConfig& cfg) {
  program::ParserSettings s;
  for (const auto& a : cfg.axes) {
    s.axis_names.push_back(a.name);
    s.start_position_mm.push_back(a.home_mm);
  }
  s.default_feed_mm_per_min = 0;  // a G1 needs an F: a silent default feed surprises machinists
  s.spindle_rpm = cfg.process.spindle_rpm;
  s.process = program::ProcessParams{cfg.process.ball_radius_mm, cfg.process.flutes, cfg.process.pick_feed_mm,
                                     cfg.process.target_rmax_um};
  return s;
}

ProgramServer::ProgramServer(const config::MachineConfig& cfg, ServerLimits limits)
    : ProgramServer(parser_settings(cfg), limits) {}

ProgramServer::ProgramServer(program::ParserSettings settings, ServerLimits limits)
    : parser_(std::move(settings)), limits_(limits) {
  limits_.blocks_per_chunk = std::max(1, limits_.blocks_per_chunk);
  limits_.bytes_per_chunk = std::max<int64_t>(1, limits_.bytes_per_chunk);
  limits_.cached_chunks = std::max(1, limits_.cached_chunks);
}

const std::string& ProgramServer::path() const {
  static const std::string kNone;
  return program_ ? program_->path : kNone;
}

LoadResult ProgramServer::load(const std::string& path, int64_t token, const std::vector<double>& start_position_mm) {
  LoadResult r;
  program::ParserState start = parser_.initial_state();
  // The program starts where the machine is (RS274): its first move, a G91 move
  // or a NURBS's first control point are taken from there.
  if (start_position_mm.size() == start.position_mm.size()) start.position_mm = start_position_mm;
  auto next = std::make_unique<Loaded>();
  next->path = path;
  next->token = token;
  next->in = std::make_unique<std::ifstream>(path, std::ios::binary);
  try {
    if (!*next->in) throw program::ProgramError(program::SourceLocation{path, 0, 0}, "cannot open the program file");
    Indexer indexer(limits_, &next->checkpoints);
    parser_.stream(*next->in, path, start, indexer);
    next->end = indexer.end;
    next->num_blocks = indexer.end.next_index;
  } catch (const program::ProgramError& e) {
    r.error = e.what();
    r.line = e.where().line;
    r.column = e.where().column;
    return r;
  }
  program_ = std::move(next);
  cache_.clear();
  serving_error_.clear();
  r.ok = true;
  return r;
}

const program::Block* ProgramServer::block(int64_t index) {
  if (!program_ || index < 0 || index >= program_->num_blocks) return nullptr;
  const Chunk* c = chunk_for(index);
  if (c == nullptr) return nullptr;
  const int64_t k = index - c->first;
  if (k < 0 || k >= static_cast<int64_t>(c->blocks.size())) return nullptr;
  return &c->blocks[static_cast<size_t>(k)];
}

const ProgramServer::Chunk* ProgramServer::chunk_for(int64_t index) {
  const auto& cps = program_->checkpoints;
  // The last checkpoint at or before `index`.
  const auto it = std::upper_bound(cps.begin(), cps.end(), index,
                                   [](int64_t i, const program::ParserState& s) { return i < s.next_index; });
  const size_t c = static_cast<size_t>(it - cps.begin()) - 1;
  const int64_t first = cps[c].next_index;
  for (Chunk& ch : cache_) {
    if (ch.first == first) {
      ch.last_use = ++use_clock_;
      return &ch;
    }
  }
  Chunk fresh;
  if (!read_chunk(c, &fresh)) {
    program_.reset();  // nothing more of this file is served
    cache_.clear();
    return nullptr;
  }
  fresh.last_use = ++use_clock_;
  if (static_cast<int>(cache_.size()) < limits_.cached_chunks) {
    cache_.push_back(std::move(fresh));
    return &cache_.back();
  }
  Chunk& victim = *std::min_element(cache_.begin(), cache_.end(),
                                    [](const Chunk& a, const Chunk& b) { return a.last_use < b.last_use; });
  victim = std::move(fresh);
  return &victim;
}

bool ProgramServer::read_chunk(size_t c, Chunk* out) {
  Loaded& p = *program_;
  const program::ParserState& from = p.checkpoints[c];
  const bool last = c + 1 == p.checkpoints.size();
  const program::ParserState& to = last ? p.end : p.checkpoints[c + 1];
  ++chunk_reads_;
  out->first = from.next_index;
  out->blocks.clear();
  out->blocks.reserve(static_cast<size_t>(std::min<int64_t>(to.next_index - from.next_index, 1 << 16)));
  const std::string changed = p.path + ": the program file changed since it was loaded";
  try {
    p.in->clear();
    p.in->seekg(from.offset);
    if (!*p.in) {
      serving_error_ = p.path + ": cannot seek in the program file";
      return false;
    }
    ChunkReader reader(last ? -1 : to.offset, &out->blocks);
    parser_.stream(*p.in, p.path, from, reader);
    if (!same_place(reader.reached, to) || out->first + static_cast<int64_t>(out->blocks.size()) != to.next_index) {
      serving_error_ = changed;
      return false;
    }
  } catch (const program::ProgramError& e) {
    serving_error_ = changed + " (" + e.what() + ")";
    return false;
  }
  return true;
}

}  // namespace cnc::pps
