// The malformed-program corpus (tests/golden/programs/malformed): each file's first
// line is `( expect: LINE:COLUMN fragment )`, and the parser must refuse the file at
// exactly that place with a message containing the fragment — both through
// GcodeParser::parse and through the part-program server, which must then serve
// nothing of it. The valid programs (tests/golden/programs/valid) parse, the server
// streams the same blocks as the whole-file parse, and random edits of them are
// either refused with a place or give only blocks that pass from_msg.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "common/program/block_msg.h"
#include "common/program/gcode_parser.h"
#include "services/part_program_server/program_server.h"

namespace cnc::program {
namespace {

namespace fs = std::filesystem;

const fs::path kCorpus = fs::path(CNC_SOURCE_DIR) / "tests" / "golden" / "programs";

ParserSettings settings() {
  ParserSettings s;
  s.axis_names = {"X", "Y", "Z"};
  s.start_position_mm = {0, 0, 0};
  return s;
}

std::vector<std::string> programs(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(kCorpus / dir))
    if (e.path().extension() == ".ngc") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

struct Expectation {
  int line = 0;
  int column = 0;
  std::string fragment;
};

Expectation expectation(const fs::path& file) {
  std::ifstream in(file);
  std::string first;
  std::getline(in, first);
  static const std::regex re(R"(^\( expect: (\d+):(\d+) (.*) \)$)");
  std::smatch m;
  if (!std::regex_match(first, m, re)) return {};
  return {std::stoi(m[1]), std::stoi(m[2]), m[3]};
}

class Malformed : public ::testing::TestWithParam<std::string> {};

TEST_P(Malformed, RefusedAtTheRecordedPlace) {
  const fs::path file = kCorpus / "malformed" / (GetParam() + ".ngc");
  const Expectation want = expectation(file);
  ASSERT_GT(want.line, 1) << file << ": first line must be '( expect: LINE:COLUMN fragment )'";
  try {
    GcodeParser(settings()).parse_file(file.string());
    FAIL() << file << " was accepted";
  } catch (const ProgramError& e) {
    EXPECT_EQ(e.where().file, file.string());
    EXPECT_EQ(e.where().line, want.line) << e.what();
    EXPECT_EQ(e.where().column, want.column) << e.what();
    EXPECT_NE(e.detail().find(want.fragment), std::string::npos) << "'" << want.fragment << "' not in: " << e.what();
    const std::string prefix = file.string() + ":" + std::to_string(want.line) + ":" + std::to_string(want.column) + ": ";
    EXPECT_EQ(std::string(e.what()).rfind(prefix, 0), 0u) << e.what();
  }
  // The server refuses it the same way and serves no block of it.
  pps::ProgramServer server(settings(), pps::ServerLimits{});
  const pps::LoadResult r = server.load(file.string(), 7);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.line, want.line);
  EXPECT_EQ(r.column, want.column);
  EXPECT_FALSE(server.loaded());
  EXPECT_EQ(server.block(0), nullptr);
}

INSTANTIATE_TEST_SUITE_P(Corpus, Malformed, ::testing::ValuesIn(programs("malformed")),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

TEST(MalformedCorpus, HasAtLeastThirtyPrograms) { EXPECT_GE(programs("malformed").size(), 30u); }

class Valid : public ::testing::TestWithParam<std::string> {};

TEST_P(Valid, ParsesAndStreamsTheSameBlocks) {
  const fs::path file = kCorpus / "valid" / (GetParam() + ".ngc");
  const Program whole = GcodeParser(settings()).parse_file(file.string());
  ASSERT_GE(whole.blocks.size(), 2u);
  EXPECT_EQ(whole.blocks.back().kind, BlockKind::kEnd);
  // Tiny chunks and a one-chunk cache: every block comes from a re-parse.
  pps::ProgramServer server(settings(), pps::ServerLimits{2, 1 << 20, 1});
  const pps::LoadResult r = server.load(file.string(), 7);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(server.num_blocks(), static_cast<int64_t>(whole.blocks.size()));
  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << server.serving_error();
    const Block& w = whole.blocks[static_cast<size_t>(i)];
    EXPECT_EQ(b->index, i);
    EXPECT_EQ(b->kind, w.kind);
    EXPECT_EQ(b->source_line, w.source_line);
    EXPECT_EQ(b->start, w.start);
    EXPECT_EQ(b->end, w.end);
    EXPECT_EQ(b->arc.center, w.arc.center);
    EXPECT_EQ(b->nurbs.knots, w.nurbs.knots);
    EXPECT_EQ(b->nurbs.control_points, w.nurbs.control_points);
    EXPECT_EQ(b->nurbs.weights, w.nurbs.weights);
  }
}

// Random edits of the valid programs (fixed seed): each result is either refused
// with a place in the file, or every block it gives passes from_msg's checks — the
// parser never hands the interpolator a block the network side would refuse.
TEST(MutatedCorpus, RefusedWithAPlaceOrEveryBlockIsValid) {
  std::vector<std::string> seeds;
  for (const auto& name : programs("valid")) {
    std::ifstream in(kCorpus / "valid" / (name + ".ngc"));
    seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_FALSE(seeds.empty());
  const std::string alphabet = "0123456789GXYZIJKRPLFSMN .-\n()";
  std::mt19937 rng(5);
  const GcodeParser parser(settings());
  int accepted = 0;
  for (int it = 0; it < 4000; ++it) {
    std::string text = seeds[rng() % seeds.size()];
    for (int m = 0, n = 1 + static_cast<int>(rng() % 3); m < n && !text.empty(); ++m) {
      const size_t at = rng() % text.size();
      const char c = alphabet[rng() % alphabet.size()];
      switch (rng() % 3) {
        case 0: text[at] = c; break;
        case 1: text.insert(at, 1, c); break;
        default: text.erase(at, 1); break;
      }
    }
    std::istringstream in(text);
    try {
      const Program p = parser.parse(in, "m.ngc");
      ++accepted;
      for (const Block& b : p.blocks) {
        Block back;
        ASSERT_EQ(from_msg(to_msg(b, 1), 3, &back), "") << "block " << b.index << " of:\n" << text;
      }
    } catch (const ProgramError& e) {
      ASSERT_EQ(e.where().file, "m.ngc");
      ASSERT_GT(e.where().line, 0) << e.what();
      ASSERT_GT(e.where().column, 0) << e.what();
    }
  }
  EXPECT_GT(accepted, 400);  // the edits must leave enough programs valid to mean something
}

INSTANTIATE_TEST_SUITE_P(Corpus, Valid, ::testing::ValuesIn(programs("valid")),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

}  // namespace
}  // namespace cnc::program
