#include "services/part_program_server/program_server.h"

namespace cnc::pps {

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

ProgramServer::ProgramServer(const config::MachineConfig& cfg) : parser_(parser_settings(cfg)) {}

LoadResult ProgramServer::load(const std::string& path, int64_t token) {
  LoadResult r;
  try {
    program::Program p = parser_.parse_file(path);
    program_ = std::move(p);
    token_ = token;
    path_ = path;
    r.ok = true;
  } catch (const program::ProgramError& e) {
    r.error = e.what();
    r.line = e.where().line;
    r.column = e.where().column;
  }
  return r;
}

const program::Block* ProgramServer::block(int64_t index) const {
  if (!program_ || index < 0 || index >= num_blocks()) return nullptr;
  return &program_->blocks[static_cast<size_t>(index)];
}

}  // namespace cnc::pps
