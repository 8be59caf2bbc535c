// STL reader: ASCII and binary, the errors for broken files, zero-area triangles.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "common/cam/points_csv.h"
#include "common/cam/stl.h"
#include "temp_dir.h"

namespace cnc::cam {
namespace {

Mesh two_triangles() {
  Mesh m;
  m.triangles.push_back({{Vec3{0, 0, 0}, Vec3{1, 0, 0.5}, Vec3{0, 1, 0.25}}});
  m.triangles.push_back({{Vec3{1, 0, 0.5}, Vec3{1, 1, 1}, Vec3{0, 1, 0.25}}});
  return m;
}

std::string binary_bytes(const Mesh& m) {
  test::TempDir dir;
  const std::string p = (dir / "m.stl").string();
  write_stl_binary(p, m);
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

std::string error_of(const std::string& data, const std::string& name = "part.stl") {
  try {
    parse_stl(data, name);
  } catch (const StlError& e) {
    return e.what();
  }
  return "no error";
}

TEST(CamStl, BinaryAndAsciiReadBackTheSameTriangles) {
  test::TempDir dir;
  const Mesh m = two_triangles();
  write_stl_binary((dir / "b.stl").string(), m);
  write_stl_ascii((dir / "a.stl").string(), m);
  StlInfo bi, ai;
  const Mesh b = read_stl((dir / "b.stl").string(), &bi);
  const Mesh a = read_stl((dir / "a.stl").string(), &ai);
  EXPECT_TRUE(bi.binary);
  EXPECT_FALSE(ai.binary);
  EXPECT_EQ(bi.bytes, 84u + 2 * 50u);
  ASSERT_EQ(b.triangles.size(), 2u);
  ASSERT_EQ(a.triangles.size(), 2u);
  for (std::size_t t = 0; t < 2; ++t)
    for (std::size_t k = 0; k < 3; ++k) {
      EXPECT_EQ(a.triangles[t].v[k].x, m.triangles[t].v[k].x);  // all exact in float too
      EXPECT_EQ(b.triangles[t].v[k].y, m.triangles[t].v[k].y);
      EXPECT_EQ(b.triangles[t].v[k].z, a.triangles[t].v[k].z);
    }
}

TEST(CamStl, BinaryWhoseHeaderSaysSolidIsStillBinary) {
  std::string bytes = binary_bytes(two_triangles());
  std::memcpy(bytes.data(), "solid evil", 10);
  StlInfo info;
  EXPECT_EQ(parse_stl(bytes, "x.stl", &info).triangles.size(), 2u);
  EXPECT_TRUE(info.binary);
}

TEST(CamStl, TruncatedBinaryNamesTheFileAndTheCutTriangle) {
  const std::string bytes = binary_bytes(two_triangles());
  const std::string e = error_of(bytes.substr(0, bytes.size() - 7));
  EXPECT_NE(e.find("part.stl: truncated"), std::string::npos) << e;
  EXPECT_NE(e.find("announces 2 triangles (184 bytes)"), std::string::npos) << e;
  EXPECT_NE(e.find("triangle 2 is cut off"), std::string::npos) << e;
}

TEST(CamStl, CountThatDisagreesWithTheSizeIsAnError) {
  std::string bytes = binary_bytes(two_triangles()) + std::string(50, '\0');  // a third triangle not counted
  const std::string e = error_of(bytes);
  EXPECT_NE(e.find("disagrees with its size"), std::string::npos) << e;
  EXPECT_NE(e.find("room for 3 triangles"), std::string::npos) << e;
  EXPECT_NE(error_of("tiny").find("too short"), std::string::npos);
}

TEST(CamStl, NonFiniteBinaryCoordinateNamesTheTriangle) {
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::string bytes = binary_bytes(two_triangles());
    // Triangle 2, vertex 3, y: header 84 + 50 + normal 12 + 2 vertices 24 + x 4.
    std::memcpy(bytes.data() + 84 + 50 + 12 + 24 + 4, &bad, 4);
    const std::string e = error_of(bytes);
    EXPECT_NE(e.find("part.stl: triangle 2 of 2"), std::string::npos) << e;
    EXPECT_NE(e.find("vertex 3"), std::string::npos) << e;
    EXPECT_NE(e.find("not finite"), std::string::npos) << e;
  }
}

const char* kAscii =
    "solid cube part\n"
    "  facet normal 0 0 1\n"
    "    outer loop\n"
    "      vertex 0 0 0\n"
    "      vertex 1 0 0\n"
    "      vertex +1 1 1e-1\n"
    "    endloop\n"
    "  endfacet\n"
    "  facet normal nan nan nan\n"  // normals are not read: some exporters write these
    "    outer loop\n"
    "      vertex 0 0 0\n"
    "      vertex 1 1 0\n"
    "      vertex 2 2 0\n"  // collinear: zero area
    "    endloop\n"
    "  endfacet\n"
    "endsolid cube part\n";

TEST(CamStl, AsciiSkipsAndCountsZeroAreaTriangles) {
  StlInfo info;
  const Mesh m = parse_stl(kAscii, "a.stl", &info);
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(info.triangles_in_file, 2u);
  EXPECT_EQ(info.zero_area_skipped, 1u);
  EXPECT_DOUBLE_EQ(m.triangles[0].v[2].z, 0.1);
}

TEST(CamStl, ZeroAreaBinaryTrianglesAreSkippedAndCounted) {
  Mesh m = two_triangles();
  m.triangles.push_back({{Vec3{0, 0, 0}, Vec3{0, 0, 0}, Vec3{1, 1, 1}}});  // repeated vertex
  StlInfo info;
  EXPECT_EQ(parse_stl(binary_bytes(m), "b.stl", &info).triangles.size(), 2u);
  EXPECT_EQ(info.zero_area_skipped, 1u);
  EXPECT_EQ(info.triangles_in_file, 3u);
}

TEST(CamStl, TruncatedAsciiNamesTheLineAndFacet) {
  const std::string text(kAscii);
  const std::string cut = text.substr(0, text.find("      vertex 2 2 0"));
  const std::string e = error_of(cut, "a.stl");
  EXPECT_NE(e.find("a.stl:13 (facet 2): end of file, expected 'vertex'"), std::string::npos) << e;
}

TEST(CamStl, AsciiErrorsNameTheLine) {
  std::string text(kAscii);
  std::string bad = text;
  bad.replace(bad.find("vertex 1 0 0"), 12, "vertex 1 nan 0");
  std::string e = error_of(bad, "a.stl");
  EXPECT_NE(e.find("a.stl:5 (facet 1): vertex coordinate 'nan' is not finite"), std::string::npos) << e;
  bad = text;
  bad.replace(bad.find("vertex 1 0 0"), 12, "vertex 1 -inf 0");
  EXPECT_NE(error_of(bad, "a.stl").find("'-inf' is not finite"), std::string::npos);
  bad = text;
  bad.replace(bad.find("vertex 1 0 0"), 12, "vertex 1 0x 0");
  e = error_of(bad, "a.stl");
  EXPECT_NE(e.find("a.stl:5 (facet 1): expected a number, found '0x'"), std::string::npos) << e;
  bad = text;
  bad.replace(bad.find("endloop"), 7, "endlop");
  e = error_of(bad, "a.stl");
  EXPECT_NE(e.find("a.stl:7 (facet 1): expected 'endloop', found 'endlop'"), std::string::npos) << e;
  e = error_of(text.substr(0, text.find("endsolid")), "a.stl");
  EXPECT_NE(e.find("end of file before 'endsolid'"), std::string::npos) << e;
}

TEST(CamStl, MissingFileIsAnErrorNamingIt) {
  try {
    read_stl("/nonexistent/x.stl");
    FAIL();
  } catch (const StlError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/x.stl: cannot open"), std::string::npos);
  }
}

// The drop command's files: x and y echoed exactly as written, z the shortest text
// that reads back as the same double, empty where nothing is touched.
TEST(CamPointsCsv, EchoesXYAsWrittenAndLeavesUntouchedZEmpty) {
  const PointsCsv in = parse_points_csv("x,y\r\n 1.50, -2e-1\n\n+3,4.000\n", "p.csv");
  ASSERT_EQ(in.points.size(), 2u);
  EXPECT_EQ(in.points[0].x, 1.5);
  EXPECT_EQ(in.points[0].y, -0.2);
  EXPECT_EQ(in.points[1].x, 3);
  test::TempDir dir;
  const std::string out = (dir / "o.csv").string();
  write_xyz_csv(out, in, {ClPoint{0.1 + 0.2, Contact::kFacet}, ClPoint{}});
  std::ifstream f(out);
  const std::string text(std::istreambuf_iterator<char>(f), {});
  EXPECT_EQ(text, "x,y,z\n1.50,-2e-1,0.30000000000000004\n+3,4.000,\n");
}

TEST(CamPointsCsv, ErrorsNameTheLine) {
  auto error_of_csv = [](const std::string& text) {
    try {
      parse_points_csv(text, "p.csv");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of_csv("a,b\n1,2\n").find("p.csv:1: expected the header 'x,y'"), std::string::npos);
  EXPECT_NE(error_of_csv("x,y\n1,2\n3\n").find("p.csv:3: expected two fields"), std::string::npos);
  EXPECT_NE(error_of_csv("x,y\n1,2,3\n").find("p.csv:2: expected two fields"), std::string::npos);
  EXPECT_NE(error_of_csv("x,y\n1,nan\n").find("p.csv:2: 'nan' is not a finite number"), std::string::npos);
  EXPECT_NE(error_of_csv("x,y\n1,2x\n").find("p.csv:2: '2x' is not a finite number"), std::string::npos);
  EXPECT_NE(error_of_csv("").find("p.csv: empty"), std::string::npos);
}

}  // namespace
}  // namespace cnc::cam
