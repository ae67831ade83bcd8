// `lfrecon eval` run as a user would: on a synthetic dataset written by
// `lfrecon synth`, its own ground truth scores 1, a shifted copy fails at the
// small thresholds, and bad input gives the documented exit codes.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "io/ply.h"

namespace {

namespace fs = std::filesystem;

struct Result {
  int code = -1;
  std::string out;
};

Result RunCli(const std::string& args) {
  Result r;
  FILE* pipe = popen((std::string(LFRECON_CLI) + " " + args + " 2>/dev/null").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

class EvalCommand : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("lfrecon_eval_cli_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    ASSERT_EQ(RunCli("synth --scene sphere --frames 4 --width 64 --height 36 --supersampling 1 --depth-every 0 --out " +
                  dir_.string())
                  .code,
              0);
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
};
fs::path EvalCommand::dir_;

TEST_F(EvalCommand, GroundTruthScoresOneAndShiftedCopyDoesNot) {
  const Result r = RunCli("eval --dataset " + dir_.string() + " --mesh " + (dir_ / "gt_mesh.ply").string() +
                       " --json --spacing-mm 4");
  ASSERT_EQ(r.code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["scores"].size(), 3u);
  for (const auto& s : j["scores"]) {
    EXPECT_DOUBLE_EQ(s["fscore"].get<double>(), 1.0);
  }
  EXPECT_EQ(j["scores"][0]["threshold_mm"].get<double>(), 2.0);

  lfrecon::TriangleMesh shifted = lfrecon::ReadPly(dir_ / "gt_mesh.ply");
  for (auto& v : shifted.vertices) v.z() += 0.003f;  // 3 mm up
  lfrecon::WritePly(shifted, dir_ / "shifted.ply");
  const Result s = RunCli("eval --dataset " + dir_.string() + " --mesh " + (dir_ / "shifted.ply").string() +
                       " --json --spacing-mm 4 --thresholds-mm 1,5");
  ASSERT_EQ(s.code, 0);
  const nlohmann::json k = nlohmann::json::parse(s.out);
  EXPECT_LT(k["scores"][0]["fscore"].get<double>(), 0.5);   // at 1 mm
  EXPECT_DOUBLE_EQ(k["scores"][1]["fscore"].get<double>(), 1.0);  // at 5 mm
  // The text report names the columns.
  const Result t = RunCli("eval --dataset " + dir_.string() + " --mesh " + (dir_ / "gt_mesh.ply").string() +
                       " --spacing-mm 4");
  EXPECT_EQ(t.code, 0);
  EXPECT_NE(t.out.find("precision"), std::string::npos);
}

TEST_F(EvalCommand, ExitCodes) {
  EXPECT_EQ(RunCli("eval --dataset " + dir_.string()).code, 2);  // --mesh missing
  EXPECT_EQ(RunCli("eval --dataset " + dir_.string() + " --mesh " + (dir_ / "gt_mesh.ply").string() +
                " --thresholds-mm 0")
                .code,
            2);
  EXPECT_EQ(RunCli("eval --dataset " + dir_.string() + " --mesh " + (dir_ / "nope.ply").string()).code, 1);
}

}  // namespace
