// Runs the lfrecon binary as a user would and checks exit codes and messages.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;

struct Result {
  int code = -1;
  std::string output;  // stdout and stderr together
};

Result RunCli(const std::string& args) {
  const std::string cmd = std::string(LFRECON_CLI) + " " + args + " 2>&1";
  Result r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

fs::path TempDir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("lfrecon_cli_test_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

TEST(LfreconCli, VersionAndHelp) {
  Result r = RunCli("--version");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.output.find("lfrecon"), std::string::npos);
  r = RunCli("--help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.output.find("info"), std::string::npos);
  EXPECT_NE(r.output.find("synth"), std::string::npos);
  for (const char* sub : {"info", "synth"}) {
    r = RunCli(std::string(sub) + " --help");
    EXPECT_EQ(r.code, 0) << sub;
  }
}

TEST(LfreconCli, UsageErrorsExitTwo) {
  EXPECT_EQ(RunCli("").code, 2);
  EXPECT_EQ(RunCli("no-such-command").code, 2);
  EXPECT_EQ(RunCli("info --no-such-flag").code, 2);
  EXPECT_EQ(RunCli("info --bbox 1 2 3").code, 2);
  EXPECT_EQ(RunCli("info --dataset /tmp --bbox 0 0 0 -1 1 1").code, 2);
}

TEST(LfreconCli, MissingDatasetExitsOneNamingIt) {
  const Result r = RunCli("info --dataset /nonexistent/lfrecon_dataset_xyz");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("/nonexistent/lfrecon_dataset_xyz"), std::string::npos) << r.output;
}

TEST(LfreconCli, NanQuaternionExitsOneNamingTheFile) {
  const fs::path dir = TempDir("nan");
  fs::create_directories(dir / "sparse");
  fs::create_directories(dir / "images");
  std::ofstream(dir / "sparse" / "cameras.txt") << "1 PINHOLE 64 48 50 50 32 24\n";
  std::ofstream(dir / "sparse" / "images.txt") << "1 nan 0 0 0 0 0 0 1 a.png\n\n";
  std::ofstream(dir / "sparse" / "points3D.txt") << "";
  const Result r = RunCli("info --dataset " + dir.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("images.txt"), std::string::npos) << r.output;
  fs::remove_all(dir);
}

TEST(LfreconCli, SynthThenInfo) {
  const fs::path dir = TempDir("synth");
  Result r = RunCli("-q synth --out " + (dir / "ds").string() + " --frames 24 --width 160 --height 90");
  ASSERT_EQ(r.code, 0) << r.output;
  r = RunCli("info --json --dataset " + (dir / "ds").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("\"views\": 24"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("scene.json"), std::string::npos) << r.output;
  fs::remove_all(dir);
}

TEST(LfreconCli, SynthUnknownSceneIsUsageError) {
  const fs::path dir = TempDir("badscene");
  const Result r = RunCli("synth --out " + dir.string() + " --scene no_such_scene");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no_such_scene"), std::string::npos) << r.output;
  fs::remove_all(dir);
}

// σ_s so large that a free-space vote never carves (FusionOptions::Check):
// `lfrecon run` refuses it, and `lfrecon submit` must too, before anything is
// sent (it used to print a job id; the job then answered ERROR_INTERNAL for ever).
TEST(LfreconCli, SubmitRefusesInvalidJobOptionsAsRunDoes) {
  const fs::path dir = TempDir("submit_opts");
  Result r = RunCli("-q synth --out " + (dir / "ds").string() + " --frames 12 --width 64 --height 36");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string data = " --dataset " + (dir / "ds").string();
  r = RunCli("run" + data + " --sigma-s 2 --out " + (dir / "run").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("sigma_s"), std::string::npos) << r.output;
  // No daemon listens there: a refusal must come from the option check, at once.
  const std::string nowhere = " --timeout-ms 300 --ingest ipc://" + (dir / "no_ingest.sock").string();
  for (const char* flags : {" --sigma-s 2", " --sigma-s 2 --no-densify", " --color-views -1"}) {
    r = RunCli("submit" + data + flags + nowhere);
    EXPECT_EQ(r.code, 2) << flags << ": " << r.output;
    EXPECT_NE(r.output.find(std::string(flags).find("color") != std::string::npos ? "color_views" : "sigma_s"),
              std::string::npos)
        << r.output;
  }
  // Valid options get as far as the (absent) daemon: exit 1, not 2.
  r = RunCli("submit" + data + " --sigma-s 0.3" + nowhere);
  EXPECT_EQ(r.code, 1) << r.output;
  fs::remove_all(dir);
}

}  // namespace
