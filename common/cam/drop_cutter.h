#pragma once
// Hwang, drop-cutter by inverse offset: for a point (x, y), the height z of the
// cutter's tip at which the cutter, lowered along z, first touches the mesh.
//
// For one triangle T that height is max over p in T with rho(p) <= R of
// p.z − h(rho(p)), rho the xy distance from the axis and h the cutter's lower surface
// (Cutter::height_at). The function maximised is concave on T (affine minus a convex
// function of the xy position), so its maximum is at one of:
//   facet  — the critical point inside T: where the corner torus (ring of radius a at
//            height r, swept by a ball of radius r) touches T's plane; the offset plane
//            of the paper, closed form;
//   vertex — a corner of T: sphere (ball), torus (bull), disc (flat), closed form;
//   edge   — the critical point inside an edge: cylinder (ball, closed form), circle
//            crossing (flat, closed form), and for a bull cutter the offset of the
//            torus over a line, solved on the edge's parameter by Newton's method
//            inside a bracket that halves when Newton leaves it (the derivative is
//            monotone, the root unique), to 1e-14 of R in the parameter.
// The highest contact over all triangles wins. The cutter's shank and flute length do
// not take part: only points within R of the axis can be touched first from above.
//
// DropCutter adds a spatial index: a uniform 2-D grid whose cells list every triangle
// whose xy bounds, grown by R, overlap the cell, sorted by the highest contact the
// triangle can give anywhere in the cell (its top lowered by the cutter's height at its
// nearest approach), so a query reads one cell and stops at the first triangle that
// cannot beat the best contact so far.
// The algorithms know nothing of threads or files; drop_batch only splits points.
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "common/cam/cutter.h"
#include "common/cam/mesh.h"

namespace cnc::cam {

enum class Contact : std::uint8_t { kNone, kFacet, kVertex, kEdge };
const char* contact_name(Contact c);

struct ClPoint {
  double z = -std::numeric_limits<double>::infinity();  // -inf: the cutter touches nothing
  Contact contact = Contact::kNone;
  bool touched() const { return contact != Contact::kNone; }
};

struct XY {
  double x = 0, y = 0;
};

// A triangle with what every query needs precomputed.
struct PreparedTriangle {
  std::array<Vec3, 3> v;
  double nx = 0, ny = 0, nz = 0;  // unit normal with nz >= 0; nz == 0: vertical, no facet contact
  double nxy = 0;                 // |(nx, ny)|
  double xmin = 0, xmax = 0, ymin = 0, ymax = 0, zmax = 0;
  std::uint8_t edge_mask = 7;  // bit k: this triangle answers for edge v[k]–v[k+1]
};
PreparedTriangle prepare(const Triangle& t);

// Clears edge_mask bits so that an edge two triangles share (same vertices, bit for
// bit) is answered by the first only. Exact for any query that skips a triangle only
// for reasons that hold for its edges too (its bounds, its highest point): the edge is
// a subset of either triangle.
void share_edges(std::vector<PreparedTriangle>& tris);

// The contact queries of one cutter; -inf where the contact does not exist (facet:
// the contact point is outside T or T is vertical; edge: the critical point is not
// strictly inside the edge, where a vertex query gives the maximum; all: farther
// than R).
class CutterContacts {
 public:
  explicit CutterContacts(const Cutter& cutter);
  const Cutter& cutter() const { return cutter_; }
  double facet(double x, double y, const PreparedTriangle& t) const;
  double vertex(double x, double y, const Vec3& p) const;
  // `floor`: a height the caller already has; where the edge provably cannot rise above
  // it (a cheap bound), the bull cutter's root is not sought and -inf is returned.
  double edge(double x, double y, const Vec3& p, const Vec3& q, double floor = -std::numeric_limits<double>::infinity()) const;
  // The highest of the seven contacts of T, and which kind it is; with `floor`, only
  // contacts above it count (kNone if there is none), and edges that cannot beat the
  // best so far are skipped.
  ClPoint triangle(double x, double y, const PreparedTriangle& t,
                   double floor = -std::numeric_limits<double>::infinity()) const;
  // The two halves of triangle(): the closed-form vertex and facet contacts, and the edges.
  void vertices_and_facet(double x, double y, const PreparedTriangle& t, ClPoint& best) const;
  void edges(double x, double y, const PreparedTriangle& t, ClPoint& best) const;

 private:
  Cutter cutter_;
  double R_, R2_, a_, r_;
};

// Every triangle, no index: the reference the index is checked and timed against.
class BruteForceDropCutter {
 public:
  BruteForceDropCutter(const Mesh& mesh, const Cutter& cutter);
  ClPoint drop(double x, double y) const;

 private:
  CutterContacts contacts_;
  std::vector<PreparedTriangle> tris_;
};

class DropCutter {
 public:
  struct Options {
    double cell_mm = 0;  // grid cell size; 0: R/2, grown until the index holds <= 32 entries per triangle
  };
  DropCutter(const Mesh& mesh, const Cutter& cutter);
  DropCutter(const Mesh& mesh, const Cutter& cutter, Options options);

  ClPoint drop(double x, double y) const;
  // out[i] = drop(in[i]) on `threads` threads (>= 1), in chunks taken in turn; `done`,
  // if given, counts finished points (for progress reports from another thread).
  void drop_batch(std::span<const XY> in, std::span<ClPoint> out, int threads,
                  std::atomic<std::size_t>* done = nullptr) const;

  double cell_mm() const { return cell_; }
  std::size_t index_entries() const { return entries_.size(); }
  std::size_t triangle_count() const { return tris_.size(); }

 private:
  struct Entry {  // one triangle in one cell, as floats rounded outward: its xy bounds grown by R, and
                 // its top lowered by the cutter's height at the triangle's nearest approach to the cell
    float xmin, xmax, ymin, ymax, top;
    std::uint32_t tri;
  };
  CutterContacts contacts_;
  std::vector<PreparedTriangle> tris_;
  double R2_, a2_;
  double cell_ = 1, x0_ = 0, y0_ = 0;
  std::int64_t nx_ = 0, ny_ = 0;
  std::vector<std::uint32_t> cell_start_;  // nx·ny + 1 offsets into entries_
  std::vector<Entry> entries_;
};

}  // namespace cnc::cam
