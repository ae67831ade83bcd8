// The streaming service across hosts on one machine (issue 14 §3): three
// network namespaces this test creates itself stand for three hosts.
//   svc: lfrecon-aggregate (tcp://0.0.0.0:5551) and lfrecon-ingest (tcp://10.231.2.1:5550)
//   wrk: lfrecon-depth and lfrecon-propagate, asking the aggregator at 10.231.1.1
//   cli: `lfrecon stream --wait` and `lfrecon export`, at 10.231.2.1
// linked by two veth pairs (svc 10.231.1.1 <-> wrk 10.231.1.2, svc 10.231.2.1
// <-> cli 10.231.2.2). No namespace has a default route or a link to the host,
// so the service's traffic stays between them. Every TCP socket is CURVE with
// keys from `lfrecon keygen` and allow-lists, as deploy/README.md says.
//
// The job store: namespaces share the file system, so the store is one local
// folder here. On real hosts it must be shared: ingest writes the frames and
// the aggregator the maps, and the workers READ their inputs (frames, sparse
// maps) from the store directly (services/common/worker_loop.cc, StoreCache);
// only their results travel over the wire. So across hosts the store is a
// shared file system (NFS, CephFS, a ReadWriteMany volume), read-write for
// ingest and the aggregator, read-only for the workers; the client needs none
// (it pushes its frames over the wire).
//
// Needs root (CAP_NET_ADMIN and CAP_SYS_ADMIN: `ip netns add`, `ip netns exec`)
// and iproute2; skipped with the reason otherwise (e.g. a CI container without
// those capabilities). Namespaces are deleted on every exit path (RAII), and
// ones left by a test process that was killed are deleted at the next start.
#include <signal.h>
#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <memory>
#include <sstream>
#include <thread>

#include "common/job_store.h"
#include "common/test_util.h"
#include "daemon_process.h"
#include "eval/mesh_metrics.h"
#include "io/ply.h"
#include "reference_dataset.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using lfrecon::testing::CommandResult;
using lfrecon::testing::DaemonProcess;
using lfrecon::testing::kBin;
using lfrecon::testing::ReferenceDataset;
using lfrecon::testing::RunShell;

constexpr double kVoxelMm = lfrecon::testing::kReferenceVoxelMm;
const std::string kPrefix = "lfrecon-t";  // namespace names: lfrecon-t<pid>-<role>

std::string Trim(std::string s) {
  s.erase(s.find_last_not_of(" \n") + 1);
  return s;
}

// Namespaces named by a test process that no longer runs.
void RemoveStaleNamespaces(const std::string& ip) {
  std::istringstream list(RunShell(ip + " netns list").output);
  std::string line;
  while (std::getline(list, line)) {
    const std::string name = line.substr(0, line.find(' '));
    if (name.rfind(kPrefix, 0) != 0) continue;
    const long pid = std::atol(name.c_str() + kPrefix.size());
    if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) RunShell(ip + " netns del " + name);
  }
}

// Three namespaces and two veth pairs; deleted on destruction (their veths with them).
class Hosts {
 public:
  explicit Hosts(std::string ip) : ip_(std::move(ip)) {}
  ~Hosts() {
    for (const std::string& n : made_) RunShell(ip_ + " netns del " + n);
  }
  Hosts(const Hosts&) = delete;
  Hosts& operator=(const Hosts&) = delete;

  // "" on success, else the failing command and its output.
  std::string Add(const std::string& role) {
    const std::string n = Name(role);
    RunShell(ip_ + " netns del " + n);  // a namespace of a reused pid
    const CommandResult r = RunShell(ip_ + " netns add " + n);
    if (r.code != 0) return "ip netns add " + n + ": " + r.output;
    made_.push_back(n);
    return Sh("-n " + n + " link set lo up");
  }
  // A veth pair `a_if` in `a` (address a_addr/24) <-> `b_if` in `b` (b_addr/24).
  std::string Link(const std::string& a, const std::string& a_if, const std::string& a_addr, const std::string& b,
                   const std::string& b_if, const std::string& b_addr) {
    for (const std::string& c :
         {"-n " + Name(a) + " link add " + a_if + " type veth peer name " + b_if + " netns " + Name(b),
          "-n " + Name(a) + " addr add " + a_addr + "/24 dev " + a_if, "-n " + Name(b) + " addr add " + b_addr +
          "/24 dev " + b_if, "-n " + Name(a) + " link set " + a_if + " up", "-n " + Name(b) + " link set " + b_if +
          " up"}) {
      const std::string e = Sh(c);
      if (!e.empty()) return e;
    }
    return "";
  }
  std::string Name(const std::string& role) const { return kPrefix + std::to_string(::getpid()) + "-" + role; }
  // The argv prefix that runs a program in `role`'s namespace.
  std::vector<std::string> Exec(const std::string& role) const { return {ip_, "netns", "exec", Name(role)}; }
  std::string ExecShell(const std::string& role) const { return ip_ + " netns exec " + Name(role) + " "; }
  // Bytes received and sent by interface `dev` of `role`'s namespace (-1: unknown).
  std::pair<std::int64_t, std::int64_t> Bytes(const std::string& role, const std::string& dev) const {
    const CommandResult r = RunShell(ip_ + " -j -s -n " + Name(role) + " link show dev " + dev);
    try {
      const auto j = nlohmann::json::parse(r.output);
      const auto& s = j.at(0).at("stats64");
      return {s.at("rx").at("bytes").get<std::int64_t>(), s.at("tx").at("bytes").get<std::int64_t>()};
    } catch (const std::exception&) {
      return {-1, -1};
    }
  }

 private:
  std::string Sh(const std::string& args) {
    const CommandResult r = RunShell(ip_ + " " + args);
    return r.code == 0 ? "" : "ip " + args + ": " + r.output;
  }
  std::string ip_;
  std::vector<std::string> made_;
};

TEST(NetnsTest, StackAcrossThreeHostsStreamsAJobToLfreconRunsMesh) {
  const std::string ip = Trim(RunShell("command -v ip").output);
  if (ip.empty()) GTEST_SKIP() << "iproute2 (ip) is not installed";
  RemoveStaleNamespaces(ip);
  // Declared before the processes: they are killed first, then the namespaces go.
  Hosts hosts(ip);
  std::string err = hosts.Add("svc");
  if (!err.empty()) GTEST_SKIP() << "cannot create network namespaces (needs root / CAP_NET_ADMIN): " << err;
  for (const char* role : {"wrk", "cli"}) {
    err = hosts.Add(role);
    ASSERT_TRUE(err.empty()) << err;
  }
  err = hosts.Link("svc", "wrk0", "10.231.1.1", "wrk", "wrk1", "10.231.1.2");
  ASSERT_TRUE(err.empty()) << err;
  err = hosts.Link("svc", "cli0", "10.231.2.1", "cli", "cli1", "10.231.2.2");
  ASSERT_TRUE(err.empty()) << err;
  // `ip netns exec` must work too (it needs CAP_SYS_ADMIN for its mount namespace).
  const CommandResult probe = RunShell(hosts.ExecShell("cli") + "true");
  if (probe.code != 0) GTEST_SKIP() << "ip netns exec fails: " << probe.output;
  // Isolation: the client's host reaches the service's host only; the worker host is not on its link.
  EXPECT_NE(RunShell(hosts.ExecShell("cli") + ip + " route get 10.231.1.2").code, 0)
      << "the client namespace has a route to the worker namespace";

  // The dataset and lfrecon run's mesh on it (host namespace: no network).
  ReferenceDataset ref;
  lfrecon::testing::MakeReference("netns_ref", /*with_run=*/true, &ref);
  ASSERT_FALSE(::testing::Test::HasFatalFailure());
  struct RefCleanup {
    ReferenceDataset* r;
    ~RefCleanup() { lfrecon::testing::RemoveReference(*r); }
  } ref_cleanup{&ref};

  lfrecon::testing::TempDir tmp;
  const fs::path store = tmp.path() / "store", keys = tmp.path() / "keys";
  fs::create_directories(store);
  fs::create_directories(keys);
  // Keys as an operator makes them: one per daemon, one per worker stage, one client.
  for (const auto& [name, role] : std::vector<std::pair<std::string, std::string>>{
           {"aggregate", "server"}, {"ingest", "ingest"}, {"depth", "worker"}, {"propagate", "worker"},
           {"client", "client"}}) {
    const CommandResult r = RunShell(kBin + "lfrecon -q keygen " + name + " --role " + role + " -o " + keys.string());
    ASSERT_EQ(r.code, 0) << r.output;
  }
  auto pub = [&](const std::string& n) { return (keys / (n + ".pub")).string(); };
  auto key = [&](const std::string& n) { return (keys / (n + ".key")).string(); };
  const fs::path agg_allow = keys / "aggregate.allow", ing_allow = keys / "ingest.allow";
  ASSERT_EQ(RunShell("cat " + pub("ingest") + " " + pub("depth") + " " + pub("propagate") + " " + pub("client") +
                     " > " + agg_allow.string() + " && cat " + pub("client") + " > " + ing_allow.string())
                .code,
            0);

  std::vector<std::unique_ptr<DaemonProcess>> procs;
  auto start = [&](const std::string& role, const std::string& exe, const std::vector<std::string>& args) {
    std::vector<std::string> argv = hosts.Exec(role);
    argv.push_back(kBin + exe);
    argv.insert(argv.end(), args.begin(), args.end());
    const fs::path log = tmp.path() / (exe + "_" + std::to_string(procs.size()) + ".log");
    procs.push_back(std::make_unique<DaemonProcess>(argv, log));
    return procs.back().get();
  };
  struct DumpLogs {
    std::vector<std::unique_ptr<DaemonProcess>>* p;
    ~DumpLogs() {
      if (::testing::Test::HasFailure())
        for (const auto& d : *p) std::printf("---- %s ----\n%s\n", d->log().c_str(), d->LogTail().c_str());
    }
  } dump{&procs};

  // The service host: the aggregator on every address of its namespace (loopback
  // for ingest, wrk0 for workers, cli0 for clients), ingest on the client link only.
  start("svc", "lfrecon-aggregate",
        {"--bind", "tcp://0.0.0.0:5551", "--store", store.string(), "--key", key("aggregate"), "--allow",
         agg_allow.string()});
  start("svc", "lfrecon-ingest",
        {"--bind", "tcp://10.231.2.1:5550", "--aggregate", "tcp://127.0.0.1:5551", "--store", store.string(), "--key",
         key("ingest"), "--allow", ing_allow.string(), "--aggregate-key", pub("aggregate")});
  // The worker host: one worker per stage, each with its own key.
  for (const std::string stage : {"depth", "propagate"})
    start("wrk", "lfrecon-" + stage,
          {"--aggregate", "tcp://10.231.1.1:5551", "--store", store.string(), "--key", key(stage), "--aggregate-key",
           pub("aggregate")});

  const std::string client = hosts.ExecShell("cli") + kBin + "lfrecon ";
  const std::string agg_flags = " --aggregate tcp://10.231.2.1:5551 --key " + key("client") + " --aggregate-key " +
                                pub("aggregate");
  // Up: the aggregator answers the client host (an unknown job is an answer).
  bool up = false;
  for (int i = 0; i < 50 && !up; ++i) {
    const CommandResult r = RunShell(client + "status j-none --timeout-ms 300" + agg_flags);
    up = r.output.find("no reply") == std::string::npos;
    if (!up) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(up) << "the aggregator does not answer from the client namespace";

  const auto [cli_rx0, cli_tx0] = hosts.Bytes("svc", "cli0");
  const auto [wrk_rx0, wrk_tx0] = hosts.Bytes("svc", "wrk0");
  const fs::path stats = tmp.path() / "stats.json";
  const auto t0 = std::chrono::steady_clock::now();
  const CommandResult s = RunShell(client + "-q stream --ingest tcp://10.231.2.1:5550 --ingest-key " + pub("ingest") +
                                   agg_flags + " --dataset " + ref.dataset.string() + " --voxel-mm " +
                                   std::to_string(kVoxelMm) + " --stats " + stats.string() + " --wait --wait-s 300");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(s.code, 0) << s.output;
  const std::string job = s.output.substr(0, s.output.find('\n'));
  ASSERT_TRUE(JobStore::ValidJobId(job)) << s.output;
  EXPECT_NE(s.output.find("DONE"), std::string::npos) << s.output;

  const CommandResult st = RunShell(client + "status " + job + " --json" + agg_flags);
  ASSERT_EQ(st.code, 0) << st.output;
  const auto status = nlohmann::json::parse(st.output.substr(st.output.find('{')));
  EXPECT_EQ(status.value("state", std::string()), "DONE") << st.output;
  EXPECT_EQ(status.value("views_fused", 0), ref.views) << st.output;

  const fs::path mesh = tmp.path() / "mesh.ply";
  const CommandResult ex = RunShell(client + "-q export " + job + " -o " + mesh.string() + agg_flags);
  ASSERT_EQ(ex.code, 0) << ex.output;
  const MeshMetrics m = lfrecon::testing::ScoreAgainstReference(ReadPly(mesh), ref);

  // What crossed the links, seen from the service host.
  const auto [cli_rx, cli_tx] = hosts.Bytes("svc", "cli0");
  const auto [wrk_rx, wrk_tx] = hosts.Bytes("svc", "wrk0");
  const auto js = nlohmann::json::parse(ReadFileBytes(stats));
  const std::int64_t sent = js.at("bytes_sent").get<std::int64_t>();
  std::printf(
      "netns stack: job %s DONE in %.1f s; F@%.0fmm %.4f, F@%.0fmm %.4f (lfrecon run %.4f, %.4f); client link "
      "%.2f MB in (frames pushed %.2f MB), %.2f MB out; worker link %.2f MB in (results), %.2f MB out\n",
      job.c_str(), seconds, 2 * kVoxelMm, m.scores[0].fscore, 4 * kVoxelMm, m.scores[1].fscore, ref.f2, ref.f4,
      (cli_rx - cli_rx0) / 1e6, sent / 1e6, (cli_tx - cli_tx0) / 1e6, (wrk_rx - wrk_rx0) / 1e6,
      (wrk_tx - wrk_tx0) / 1e6);
  // As good as lfrecon run on the same frames (the same plan; the auth and stream tests bound it the same way).
  EXPECT_GT(ref.f4, 0.5);
  EXPECT_NEAR(m.scores[0].fscore, ref.f2, 1e-3);
  EXPECT_NEAR(m.scores[1].fscore, ref.f4, 1e-3);
  // The frames came over the client's link (CURVE adds a little), the maps over the workers'.
  ASSERT_GE(cli_rx0, 0);
  ASSERT_GE(wrk_rx0, 0);
  EXPECT_GT(sent, 0);
  EXPECT_GE(cli_rx - cli_rx0, sent);
  // Each view's maps came back from the worker host: at least one map of 9 bytes a pixel
  // (float depth, float confidence, a label byte) per view (measured: 8.6 MB for 90
  // views of 96x54, a sparse and a dense map each).
  const std::int64_t pixels = static_cast<std::int64_t>(ref.views) * 96 * 54;
  EXPECT_GE(wrk_rx - wrk_rx0, 9 * pixels);
  // Daemons stop cleanly on SIGTERM.
  for (auto& p : procs) EXPECT_EQ(p->Stop(), 0) << p->log();
}

}  // namespace
}  // namespace lfrecon::svc
