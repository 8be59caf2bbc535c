// cnc-hmi's program directory: what a browser may load, and every way out refused.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "services/hmi/programs.h"

namespace fs = std::filesystem;

class ProgramDir : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/cnc-hmi-programs-XXXXXX";
    root_ = mkdtemp(tmpl);
    dir_ = root_ / "programs";
    fs::create_directories(dir_ / "sub");
    std::ofstream(dir_ / "a.ngc") << "M2\n";
    std::ofstream(dir_ / "sub" / "b.nc") << "M2\n";
    std::ofstream(dir_ / "notes.txt") << "no\n";
    std::ofstream(root_ / "secret.ngc") << "M2\n";
    fs::create_symlink(root_ / "secret.ngc", dir_ / "link.ngc");
    fs::create_directory_symlink(root_, dir_ / "up");
  }
  void TearDown() override { fs::remove_all(root_); }
  std::string resolve(const std::string& name, std::string* why) {
    return cnc::hmi::resolve_program(dir_.string(), name, why);
  }
  fs::path root_, dir_;
};

TEST_F(ProgramDir, ListsProgramsOnly) {
  const auto l = cnc::hmi::list_programs(dir_.string());
  // Not offered: link.ngc (a link leading out), up/ (a folder link), notes.txt.
  EXPECT_EQ(l, (std::vector<std::string>{"a.ngc", "sub/b.nc"}));
}

TEST_F(ProgramDir, ResolvesInside) {
  std::string why;
  EXPECT_EQ(resolve("a.ngc", &why), fs::canonical(dir_ / "a.ngc").string()) << why;
  EXPECT_EQ(resolve("sub/b.nc", &why), fs::canonical(dir_ / "sub" / "b.nc").string()) << why;
  EXPECT_EQ(resolve("./sub/../a.ngc", &why), "") << "'..' anywhere is refused";
}

TEST_F(ProgramDir, RefusesEveryWayOut) {
  std::string why;
  EXPECT_EQ(resolve("../secret.ngc", &why), "");
  EXPECT_NE(why.find("climbs out of the program directory"), std::string::npos) << why;
  EXPECT_EQ(resolve((root_ / "secret.ngc").string(), &why), "");
  EXPECT_NE(why.find("is an absolute path"), std::string::npos) << why;
  EXPECT_EQ(resolve("link.ngc", &why), "");
  EXPECT_NE(why.find("leads outside the program directory"), std::string::npos) << why;
  EXPECT_EQ(resolve("up/secret.ngc", &why), "");
  EXPECT_NE(why.find("leads outside the program directory"), std::string::npos) << why;
  EXPECT_EQ(resolve("notes.txt", &why), "");
  EXPECT_NE(why.find("is not a program file"), std::string::npos) << why;
  EXPECT_EQ(resolve("missing.ngc", &why), "");
  EXPECT_NE(why.find("is not in the program directory"), std::string::npos) << why;
  EXPECT_EQ(resolve("", &why), "");
}
