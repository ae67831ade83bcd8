#pragma once
// The fixture the service's integration tests share: a temporary folder with
// the job store, the aggregator's and ingest's endpoints, and the daemons a
// test starts, killed after it (their logs printed when it failed).
#include <gtest/gtest.h>

#include <chrono>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/messaging.h"
#include "common/test_util.h"
#include "daemon_process.h"
#include "reference_dataset.h"

namespace lfrecon::testing {

// Runs a shell command; its output (stdout and stderr); a non-zero exit fails the test.
inline std::string Sh(const std::string& cmd) {
  const CommandResult r = RunShell(cmd);
  EXPECT_EQ(r.code, 0) << cmd << "\n" << r.output;
  return r.output;
}

// An endpoint on a loopback TCP port that was free a moment ago.
inline std::string TcpEndpoint() { return "tcp://127.0.0.1:" + std::to_string(FreePort()); }

class ServiceStackTest : public ::testing::Test {
 protected:
  void SetUp() override {
    store_ = tmp_.path() / "store";
    agg_ = Endpoint("agg");
    ing_ = Endpoint("ing");
  }
  void TearDown() override {
    if (HasFailure())
      for (const auto& p : procs_)
        std::printf("---- %s ----\n%s\n", p->log().c_str(), p->LogTail(log_tail_chars_).c_str());
    procs_.clear();
  }

  // The endpoint daemon `name` binds: an ipc:// socket in the temporary folder
  // (private, so no keys are needed); a test of TCP overrides it.
  virtual std::string Endpoint(const std::string& name) {
    return "ipc://" + (tmp_.path() / (name + ".sock")).string();
  }

  // Daemon `exe` (a file in kBin) with `args`, logging to tmp_/<exe>_<n>.log;
  // `max_file_bytes`: see DaemonProcess.
  DaemonProcess* Start(const std::string& exe, std::vector<std::string> args, long max_file_bytes = 0) {
    args.insert(args.begin(), kBin + exe);
    const std::filesystem::path log = tmp_.path() / (exe + "_" + std::to_string(procs_.size()) + ".log");
    procs_.push_back(std::make_unique<DaemonProcess>(args, log, max_file_bytes));
    return procs_.back().get();
  }
  // The daemons on agg_, ing_ and store_, with `extra` arguments after those.
  DaemonProcess* StartAggregator(std::vector<std::string> extra = {}, long max_file_bytes = 0) {
    return Start("lfrecon-aggregate", Args({"--bind", agg_, "--store", store_.string()}, extra), max_file_bytes);
  }
  DaemonProcess* StartIngest(std::vector<std::string> extra = {}) {
    return Start("lfrecon-ingest", Args({"--bind", ing_, "--aggregate", agg_, "--store", store_.string()}, extra));
  }
  DaemonProcess* StartWorker(const std::string& exe, std::vector<std::string> extra = {}) {
    return Start(exe, Args({"--aggregate", agg_, "--store", store_.string()}, extra));
  }
  // The aggregator, ingest (with `ingest_extra`) and `workers` depth and propagate workers each.
  void StartStack(int workers, std::vector<std::string> ingest_extra = {}) {
    StartAggregator();
    StartIngest(std::move(ingest_extra));
    for (int i = 0; i < workers; ++i) {
      StartWorker("lfrecon-depth");
      StartWorker("lfrecon-propagate");
    }
  }

  // The job's status from the aggregator (empty when it does not answer in 5 s);
  // virtual for tests whose clients need keys or check the reply.
  virtual svc::pb::JobStatus Status(const std::string& job) {
    svc::RequestClient c(context_, agg_);
    svc::pb::Envelope req = svc::NewEnvelope(job);
    req.mutable_status();
    auto r = c.Request(req, std::chrono::milliseconds(5000));
    if (!r || !r->has_job_status()) return svc::pb::JobStatus();
    return r->job_status();
  }

  TempDir tmp_;  // first member: removed last, after the daemons that write into it
  std::filesystem::path store_;
  std::string agg_, ing_;
  zmq::context_t context_{1};
  std::vector<std::unique_ptr<DaemonProcess>> procs_;
  std::size_t log_tail_chars_ = 3000;  // of each daemon's log, printed on failure

 private:
  static std::vector<std::string> Args(std::vector<std::string> a, const std::vector<std::string>& extra) {
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  }
};

}  // namespace lfrecon::testing
