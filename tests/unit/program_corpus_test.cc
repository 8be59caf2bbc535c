// The malformed-program corpus (tests/golden/programs/malformed): each file's first
// line is `( expect: LINE:COLUMN fragment )`, and the RS274NGC interpreter (with the
// block builder's checks) must refuse the file at exactly that place with a message
// containing the fragment — both when run directly and through the part-program
// server, which must then serve nothing of it. Column 0 is the interpreter's "the
// line as a whole" (a curve closed or ended without the word at fault).
// The valid programs (tests/golden/programs/valid) run, the server serves the same
// blocks as the whole run, and random edits of them are either refused with a place
// or give only blocks that pass from_msg.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "common/program/block_msg.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/program_test_util.h"

namespace cnc::program {
namespace {

namespace fs = std::filesystem;

const fs::path kCorpus = fs::path(CNC_SOURCE_DIR) / "tests" / "golden" / "programs";

std::vector<std::string> programs(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(kCorpus / dir))
    if (e.path().extension() == ".ngc") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

struct Expectation {
  int line = 0;
  int column = -1;
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
    test::run_program(file.string());
    FAIL() << file << " was accepted";
  } catch (const rs274::Error& e) {
    EXPECT_EQ(e.file_name(), file.string());
    EXPECT_EQ(e.where().line, want.line) << e.what();
    EXPECT_EQ(e.where().column, want.column) << e.what();
    EXPECT_NE(e.detail().find(want.fragment), std::string::npos) << "'" << want.fragment << "' not in: " << e.what();
    // "file:line:column: " or, for a whole line, "file:line: ".
    const std::string prefix = file.string() + ":" + std::to_string(want.line) +
                               (want.column > 0 ? ":" + std::to_string(want.column) : std::string()) + ": ";
    EXPECT_EQ(std::string(e.what()).rfind(prefix, 0), 0u) << e.what();
  }
  // The server refuses it the same way and serves no block of it.
  pps::ProgramServer server(test::xyz_setup(), pps::ServerLimits{});
  const pps::LoadResult r = server.load(file.string(), 7);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.file, file.string());
  EXPECT_EQ(r.line, want.line);
  EXPECT_EQ(r.column, want.column);
  EXPECT_NE(r.error.find(want.fragment), std::string::npos) << r.error;
  EXPECT_FALSE(server.loaded());
  EXPECT_EQ(server.num_blocks(), 0);
  EXPECT_EQ(server.block(0), nullptr);
}

INSTANTIATE_TEST_SUITE_P(Corpus, Malformed, ::testing::ValuesIn(programs("malformed")),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

TEST(MalformedCorpus, HasAtLeastThirtyPrograms) { EXPECT_GE(programs("malformed").size(), 30u); }

class Valid : public ::testing::TestWithParam<std::string> {};

TEST_P(Valid, RunsAndServesTheSameBlocks) {
  const fs::path file = kCorpus / "valid" / (GetParam() + ".ngc");
  const std::vector<Block> whole = test::run_program(file.string());
  ASSERT_GE(whole.size(), 2u);
  EXPECT_EQ(whole.back().kind, BlockKind::kEnd);
  // Tiny chunks and a one-chunk cache: every chunk comes from the serving run.
  pps::ProgramServer server(test::xyz_setup(), pps::ServerLimits{2, 1});
  const pps::LoadResult r = server.load(file.string(), 7);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(server.num_blocks(), static_cast<int64_t>(whole.size()));
  EXPECT_EQ(server.num_checkpoints(), (whole.size() + 1) / 2);
  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << server.serving_error();
    const Block& w = whole[static_cast<size_t>(i)];
    EXPECT_EQ(b->index, i);
    EXPECT_EQ(b->kind, w.kind);
    EXPECT_EQ(b->source_line, w.source_line);
    EXPECT_EQ(b->source_column, w.source_column);
    EXPECT_EQ(b->source_file, file.string());
    EXPECT_EQ(b->start, w.start);
    EXPECT_EQ(b->end, w.end);
    EXPECT_EQ(b->feed_mm_per_min, w.feed_mm_per_min);
    EXPECT_EQ(b->arc.center, w.arc.center);
    EXPECT_EQ(b->nurbs.knots, w.nurbs.knots);
    EXPECT_EQ(b->nurbs.control_points, w.nurbs.control_points);
    EXPECT_EQ(b->nurbs.weights, w.nurbs.weights);
    EXPECT_EQ(b->event.kind, w.event.kind);
    Block back;
    EXPECT_EQ(from_msg(to_msg(*b, 7), 3, &back), "") << "block " << i;
  }
}

INSTANTIATE_TEST_SUITE_P(Corpus, Valid, ::testing::ValuesIn(programs("valid")),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

// Random edits of the valid programs (fixed seed): each result is either refused
// with a place in the file (a line, and a column or 0 for the whole line), or every
// block it gives passes from_msg's checks — the interpreter and the block builder
// never hand the interpolator a block the network side would refuse.
TEST(MutatedCorpus, RefusedWithAPlaceOrEveryBlockIsValid) {
  std::vector<std::string> seeds;
  for (const auto& name : programs("valid")) {
    std::ifstream in(kCorpus / "valid" / (name + ".ngc"));
    seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_FALSE(seeds.empty());
  const std::string alphabet = "0123456789GXYZIJKRPLFSMN .-\n()";
  std::mt19937 rng(5);
  test::TempDir dir;
  const std::string path = (dir / "m.ngc").string();
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
    test::write_file(path, text);
    try {
      const std::vector<Block> blocks = test::run_program(path, test::xyz_setup(), 100'000);
      ++accepted;
      for (const Block& b : blocks) {
        Block back;
        ASSERT_EQ(from_msg(to_msg(b, 1), 3, &back), "") << "block " << b.index << " of:\n" << text;
      }
    } catch (const rs274::Error& e) {
      ASSERT_EQ(e.file_name(), path) << e.what();
      ASSERT_GT(e.where().line, 0) << e.what() << "\nof:\n" << text;
      ASSERT_GE(e.where().column, 0) << e.what();
    }
  }
  EXPECT_GT(accepted, 400);  // the edits must leave enough programs valid to mean something
}

}  // namespace
}  // namespace cnc::program
