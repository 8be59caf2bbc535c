// cnc-path-deviation: a program's geometry and how far commanded paths leave it, for
// the machining-time bench (tools/bench/machining_time.py, issue 31).
//
//   cnc-path-deviation --program P.ngc [--machine M.yaml] [--path CSV]... [--dump FILE]
//
// The program runs through the project's interpreter (the dry run's set-up from the
// machine file: tool table, subroutine path) into a recorder of its canonical moves in
// machine coordinates (mm): G0 and G1 lines, G2/G3 arcs (with helix and spiral, the
// radius going linearly from the start's to the end's), dwells. Prints one line
//   geometry moves=N rapids=N feeds=N arcs=N rapid_mm=L feed_mm=L dwell_s=S
//            dwell_stops=N bound_s=B segments=N
// where bound_s is the length/F bound: each move's length over its feed, the feed
// capped along the move by the axes' velocity limits (rapids at that cap), plus the
// dwells; dwell_stops counts the dwells with motion before and after them (runs of
// dwells with no motion between count once): the stops a path must make for them.
// Then, for each --path (a CSV with columns x_mm, y_mm, z_mm, the points of a path in
// order, joined by straight lines), one line
//   path file=F points=N max_mm=U lo_mm=L row=K x=.. y=.. z=.. line=N
// with the largest distance of the path from the geometry: the truth lies in
// [lo_mm - s, max_mm + s], s = the arcs' sagitta (1e-5 mm); row is the CSV row (from 0)
// where the chord farthest out starts, x y z the farthest point found on it and line
// the program line of the geometry nearest to it (tests/unit/path_distance.h has the
// algorithm). --dump writes every move (kind, line, start, end, centre, turns, feed).
// Exit status 0, 1 when the program is refused, 2 on bad flags or files.
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/path_segment.h"
#include "common/program/block.h"
#include "common/rs274/canon.h"
#include "common/rs274/interpreter.h"
#include "common/util/cli.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/path_distance.h"

namespace {

using cnc::pathdist::V3;
using cnc::rs274::Pose;
using cnc::rs274::SourceRef;

constexpr double kMmPerInch = 25.4;
constexpr double kSagittaMm = 1e-5;  // an arc's inscribed polyline from the arc
constexpr double kEpsMm = 1e-5;      // U - L of every chord's largest distance

struct Move {
  enum Kind { kRapid, kFeed, kArc } kind = kFeed;
  int line = 0;
  V3 start{}, end{}, center{};
  int plane = 17;    // arcs: 17 XY, 18 XZ (first axis Z), 19 YZ
  int rotation = 0;  // arcs: LinuxCNC's turn count (> 0 counterclockwise)
  double feed_mm_min = 0;
};

// The canonical calls of a 3-axis program as moves in machine coordinates (mm), in
// LinuxCNC's order of offsets (G92, G5x, tool length), as the block builder does.
class Recorder : public cnc::rs274::Canon {
 public:
  std::vector<Move> moves;
  std::vector<std::pair<size_t, double>> dwells;  // (moves before it, seconds)

  void use_length_units(const SourceRef&, cnc::rs274::Units u) override {
    const double s = u == cnc::rs274::Units::kInch ? kMmPerInch : 1.0;
    feed_ *= scale_ / s;
    scale_ = s;
  }
  void select_plane(const SourceRef&, cnc::rs274::Plane p) override { plane_ = p; }
  void set_g5x_offset(const SourceRef&, int, const Pose& p) override { scaled(p, &g5x_); }
  void set_g92_offset(const SourceRef&, const Pose& p) override { scaled(p, &g92_); }
  void set_xy_rotation(const SourceRef&, double deg) override {
    if (deg != 0) throw std::runtime_error("a rotated coordinate system (G10 L2 R) is not supported here");
  }
  void set_feed_rate(const SourceRef&, double rate) override { feed_ = rate; }
  void set_feed_mode(const SourceRef&, cnc::rs274::FeedMode m) override {
    if (m == cnc::rs274::FeedMode::kUnitsPerRev) throw std::runtime_error("feed per revolution (G95) is not supported here");
  }
  void use_tool_length_offset(const SourceRef&, const Pose& p) override { scaled(p, &tool_); }
  void straight_traverse(const SourceRef& ref, const Pose& end) override { line(ref, end, Move::kRapid); }
  void straight_feed(const SourceRef& ref, const Pose& end) override { line(ref, end, Move::kFeed); }
  void arc_feed(const SourceRef& ref, double, double, double first_axis, double second_axis, int rotation, double,
                const Pose& end) override {
    int a1 = 0, a2 = 1, pl = 17;
    if (plane_ == cnc::rs274::Plane::kXZ) a1 = 2, a2 = 0, pl = 18;
    if (plane_ == cnc::rs274::Plane::kYZ) a1 = 1, a2 = 2, pl = 19;
    Pose c = end;
    c[static_cast<size_t>(a1)] = first_axis;
    c[static_cast<size_t>(a2)] = second_axis;
    Move m;
    m.kind = Move::kArc;
    m.line = ref.line;
    m.start = pos_;
    m.end = machine(end);
    m.center = machine(c);
    m.plane = pl;
    m.rotation = rotation;
    m.feed_mm_min = feed_ * scale_;
    moves.push_back(m);
    pos_ = m.end;
  }
  void nurbs_feed(const SourceRef&, int, const std::vector<cnc::rs274::NurbsPoint>&, const std::vector<double>&,
                  const Pose&) override {
    throw std::runtime_error("NURBS (G5.2, G6.2) are not supported here");
  }
  void dwell(const SourceRef&, double seconds) override { dwells.emplace_back(moves.size(), seconds); }

 private:
  void scaled(const Pose& p, V3* out) const {
    for (size_t i = 0; i < 3; ++i) (*out)[i] = p[i] * scale_;
  }
  V3 machine(const Pose& p) const {
    V3 m{};
    for (size_t i = 0; i < 3; ++i) m[i] = p[i] * scale_ + g92_[i] + g5x_[i] + tool_[i];
    return m;
  }
  void line(const SourceRef& ref, const Pose& end, Move::Kind kind) {
    Move m;
    m.kind = kind;
    m.line = ref.line;
    m.start = pos_;
    m.end = machine(end);
    m.feed_mm_min = feed_ * scale_;
    moves.push_back(m);
    pos_ = m.end;
  }

  double scale_ = 1.0, feed_ = 0;
  cnc::rs274::Plane plane_ = cnc::rs274::Plane::kXY;
  V3 g5x_{}, g92_{}, tool_{}, pos_{};
};

// An arc as the motion core runs it (motion::PathSegment: radius and the normal axis
// linear in the angle, LinuxCNC's spiral), from the recorder's move.
cnc::motion::PathSegment arc_segment(const Move& m) {
  cnc::program::Block b;
  b.kind = m.rotation > 0 ? cnc::program::BlockKind::kArcCcw : cnc::program::BlockKind::kArcCw;
  b.start.assign(m.start.begin(), m.start.end());
  b.end.assign(m.end.begin(), m.end.end());
  b.arc.center.assign(m.center.begin(), m.center.end());
  b.arc.plane = m.plane;
  b.arc.turns = std::abs(m.rotation) - 1;
  b.feed_mm_per_min = m.feed_mm_min;
  return cnc::motion::PathSegment(b, 3);
}

// The larger of the arc's start and end radius in its plane.
double arc_radius(const Move& m) {
  size_t a1 = 0, a2 = 1;
  if (m.plane == 18) a1 = 2, a2 = 0;
  if (m.plane == 19) a1 = 1, a2 = 2;
  return std::max(std::hypot(m.start[a1] - m.center[a1], m.start[a2] - m.center[a2]),
                  std::hypot(m.end[a1] - m.center[a1], m.end[a2] - m.center[a2]));
}

// The highest speed along unit direction d that every axis's velocity limit allows.
double cap_along(const V3& d, const std::vector<double>& vmax) {
  double cap = 1e300;
  for (size_t i = 0; i < 3; ++i)
    if (std::fabs(d[i]) > 1e-12) cap = std::min(cap, vmax[i] / std::fabs(d[i]));
  return cap;
}

// Seconds to go from p to q at feed f (mm/s; 0: a rapid) under the axes' caps.
double piece_time(const V3& p, const V3& q, double f_mm_s, const std::vector<double>& vmax) {
  const V3 d = cnc::pathdist::sub(q, p);
  const double len = cnc::pathdist::norm(d);
  if (len <= 0) return 0;
  const V3 u{d[0] / len, d[1] / len, d[2] / len};
  const double cap = cap_along(u, vmax);
  return len / (f_mm_s > 0 ? std::min(f_mm_s, cap) : cap);
}

bool read_path(const std::string& file, std::vector<V3>* out, std::string* error) {
  std::ifstream in(file);
  if (!in) {
    *error = "cannot read " + file;
    return false;
  }
  std::string header;
  std::getline(in, header);
  std::vector<std::string> names;
  {
    std::stringstream ss(header);
    std::string n;
    while (std::getline(ss, n, ',')) names.push_back(n);
  }
  int col[3] = {-1, -1, -1};
  const char* want[3] = {"x_mm", "y_mm", "z_mm"};
  for (int k = 0; k < 3; ++k)
    for (size_t i = 0; i < names.size(); ++i)
      if (names[i] == want[k]) col[k] = static_cast<int>(i);
  if (col[0] < 0 || col[1] < 0 || col[2] < 0) {
    *error = file + ": no x_mm, y_mm, z_mm columns in its header";
    return false;
  }
  std::string row;
  std::vector<double> f;
  while (std::getline(in, row)) {
    f.clear();
    const char* s = row.c_str();
    while (*s) {
      char* e = nullptr;
      f.push_back(std::strtod(s, &e));
      s = e;
      while (*s && *s != ',') ++s;
      if (*s == ',') ++s;
    }
    const int need = std::max(col[0], std::max(col[1], col[2]));
    if (static_cast<int>(f.size()) <= need) continue;
    out->push_back({f[static_cast<size_t>(col[0])], f[static_cast<size_t>(col[1])], f[static_cast<size_t>(col[2])]});
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string program, machine = "config/machines/sim3.yaml", dump;
  std::vector<std::string> paths;
  CLI::App app{"a program's geometry, its length/F bound and how far commanded paths leave it", "cnc-path-deviation"};
  cnc::util::cli::setup(app);
  app.add_option("--program", program, "the part program")->required()->type_name("FILE");
  app.add_option("--machine", machine, "the machine file (axes' velocity limits, tool table)")->type_name("FILE");
  app.add_option("--path", paths, "a path to measure: CSV with x_mm, y_mm, z_mm (repeatable)")->type_name("CSV");
  app.add_option("--dump", dump, "write the moves here")->type_name("FILE");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;

  cnc::config::MachineConfig cfg;
  try {
    cfg = cnc::config::load_machine_config(machine);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-path-deviation: %s\n", e.what());
    return 2;
  }
  if (cfg.axes.size() < 3) {
    std::fprintf(stderr, "cnc-path-deviation: %s: the machine needs axes X, Y, Z\n", machine.c_str());
    return 2;
  }
  std::vector<double> vmax;
  for (size_t i = 0; i < 3; ++i) vmax.push_back(cfg.axes[i].max_velocity_mm_s);

  // The program as the dry run reads it, without writing the machine's files.
  cnc::rs274::MachineSetup setup = cnc::pps::program_setup(cfg).machine;
  setup.write_var_file = false;
  setup.write_tool_table = false;
  setup.optional_stop = false;
  Recorder rec;
  try {
    cnc::rs274::Interpreter interp(setup, rec);
    interp.open(program);
    while (interp.execute_next()) {
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-path-deviation: %s: %s\n", program.c_str(), e.what());
    return 1;
  }

  // The geometry, the bound, the dwells' stops.
  cnc::pathdist::SegmentSet geometry(0.25);
  std::vector<int> seg_line;
  int64_t rapids = 0, feeds = 0, arcs = 0;
  double rapid_mm = 0, feed_mm = 0, bound_s = 0;
  for (const Move& m : rec.moves) {
    const double f = m.kind == Move::kRapid ? 0.0 : m.feed_mm_min / 60.0;
    if (m.kind == Move::kArc) {
      ++arcs;
      const cnc::motion::PathSegment arc = arc_segment(m);
      const int n = cnc::pathdist::arc_pieces(arc.arc_sweep_rad(), arc_radius(m), kSagittaMm);
      V3 prev = m.start;
      for (int k = 1; k <= n; ++k) {
        const cnc::motion::AxisVec p = arc.point(arc.u_begin() + (arc.u_end() - arc.u_begin()) * k / n);
        const V3 x = k == n ? m.end : V3{p[0], p[1], p[2]};
        feed_mm += cnc::pathdist::norm(cnc::pathdist::sub(x, prev));
        bound_s += piece_time(prev, x, f, vmax);
        if (x != prev) {
          geometry.add(prev, x);
          seg_line.push_back(m.line);
        }
        prev = x;
      }
      continue;
    }
    const double len = cnc::pathdist::norm(cnc::pathdist::sub(m.end, m.start));
    (m.kind == Move::kRapid ? rapid_mm : feed_mm) += len;
    ++(m.kind == Move::kRapid ? rapids : feeds);
    bound_s += piece_time(m.start, m.end, f, vmax);
    if (m.end != m.start) {
      geometry.add(m.start, m.end);
      seg_line.push_back(m.line);
    }
  }
  // Dwells: their time, and the stops they need (motion before and after them).
  double dwell_s = 0;
  int64_t dwell_stops = 0;
  size_t last_counted = SIZE_MAX;
  auto moving_between = [&](size_t a, size_t b) {  // a move of non-zero length in [a, b)
    for (size_t i = a; i < b && i < rec.moves.size(); ++i)
      if (rec.moves[i].end != rec.moves[i].start || rec.moves[i].kind == Move::kArc) return true;
    return false;
  };
  for (const auto& [before, seconds] : rec.dwells) {
    dwell_s += seconds;
    bound_s += seconds;
    if (!moving_between(0, before) || !moving_between(before, rec.moves.size())) continue;
    if (last_counted != SIZE_MAX && !moving_between(last_counted, before)) continue;
    ++dwell_stops;
    last_counted = before;
  }
  std::printf("geometry moves=%zu rapids=%" PRId64 " feeds=%" PRId64 " arcs=%" PRId64
              " rapid_mm=%.6f feed_mm=%.6f dwell_s=%.6f dwell_stops=%" PRId64 " bound_s=%.6f segments=%zu\n",
              rec.moves.size(), rapids, feeds, arcs, rapid_mm, feed_mm, dwell_s, dwell_stops, bound_s, geometry.size());
  std::fflush(stdout);

  if (!dump.empty()) {
    std::FILE* f = std::fopen(dump.c_str(), "w");
    if (f == nullptr) {
      std::fprintf(stderr, "cnc-path-deviation: cannot write %s\n", dump.c_str());
      return 2;
    }
    std::fprintf(f, "kind,line,x0,y0,z0,x1,y1,z1,cx,cy,cz,plane,rotation,feed_mm_min\n");
    for (const Move& m : rec.moves)
      std::fprintf(f, "%s,%d,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%d,%d,%.6f\n",
                   m.kind == Move::kRapid ? "rapid" : m.kind == Move::kFeed ? "feed" : "arc", m.line, m.start[0],
                   m.start[1], m.start[2], m.end[0], m.end[1], m.end[2], m.center[0], m.center[1], m.center[2],
                   m.plane, m.rotation, m.feed_mm_min);
    std::fclose(f);
  }

  for (const std::string& file : paths) {
    std::vector<V3> path;
    std::string error;
    if (!read_path(file, &path, &error)) {
      std::fprintf(stderr, "cnc-path-deviation: %s\n", error.c_str());
      return 2;
    }
    if (geometry.size() == 0 || path.empty()) {
      std::printf("path file=%s points=%zu max_mm=nan lo_mm=nan row=-1 x=nan y=nan z=nan line=0\n", file.c_str(),
                  path.size());
      continue;
    }
    cnc::pathdist::FarthestPoint far(geometry, kEpsMm, {0.25, 1.0, 4.0, 16.0});
    double hi = -1, lo = 0;
    size_t worst = 0;
    for (size_t i = 0; i < path.size(); ++i) {
      const V3& p = i == 0 ? path[0] : path[i - 1];
      const cnc::pathdist::Range r = far.of(p, path[i]);
      lo = std::max(lo, r.lo);
      if (r.hi > hi) hi = r.hi, worst = i == 0 ? 0 : i - 1;
    }
    // Where on the worst chord, and the program line of the geometry nearest there.
    const V3 a = path[worst], b = path[std::min(worst + 1, path.size() - 1)];
    V3 at = a;
    double at_d = -1;
    int at_line = 0;
    std::vector<int> all;
    geometry.all(&all);
    for (int k = 0; k <= 64; ++k) {
      const V3 x = cnc::pathdist::lerp(a, b, k / 64.0);
      double d = 1e300;
      int line = 0;
      for (int i : all) {
        const double di = geometry.dist(i, x);
        if (di < d) d = di, line = seg_line[static_cast<size_t>(i)];
      }
      if (d > at_d) at_d = d, at = x, at_line = line;
    }
    std::printf("path file=%s points=%zu max_mm=%.7f lo_mm=%.7f row=%zu x=%.6f y=%.6f z=%.6f line=%d\n", file.c_str(),
                path.size(), hi, lo, worst, at[0], at[1], at[2], at_line);
    std::fflush(stdout);
  }
  return 0;
}
