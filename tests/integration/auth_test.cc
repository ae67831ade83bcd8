// Authentication of the streaming service (common/auth.h): the daemons over
// loopback TCP with CURVE keys and allow-lists. A peer without a listed key
// gets nothing; each key can only send what its role may; the authenticated
// stack runs a job to the same mesh as `lfrecon run`.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <memory>
#include <thread>

#include "common/auth.h"
#include "common/job_store.h"
#include "common/messaging.h"
#include "common/stream_client.h"
#include "common/test_util.h"
#include "daemon_process.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/ply.h"
#include "reference_dataset.h"
#include "service_stack.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using lfrecon::testing::DaemonProcess;
using lfrecon::testing::kBin;
using lfrecon::testing::MakeReference;
using lfrecon::testing::ReferenceDataset;
using lfrecon::testing::RemoveReference;
using lfrecon::testing::RunShell;
using lfrecon::testing::ScoreAgainstReference;
using lfrecon::testing::ServiceStackTest;
using std::chrono::milliseconds;

constexpr double kVoxelMm = lfrecon::testing::kReferenceVoxelMm;

pb::Envelope Ping() {
  pb::Envelope p = NewEnvelope();
  p.mutable_ping();
  return p;
}
pb::Envelope TaskRequest() {
  pb::Envelope r = NewEnvelope();
  r.mutable_task_request()->set_stage(pb::STAGE_DEPTH);
  r.mutable_task_request()->set_worker("forged");
  return r;
}

// The store holds nothing but the ingest daemon's lock: no job was created.
bool NoJobs(const fs::path& store) {
  for (const auto& e : fs::directory_iterator(store))
    if (e.path().filename() != kIngestLockName) return false;
  return true;
}

// Keys of one stack: the two daemons' and one per role, allow-lists for each daemon.
struct Keys {
  fs::path dir;
  fs::path Key(const std::string& n) const { return dir / (n + ".key"); }
  fs::path Pub(const std::string& n) const { return dir / (n + ".pub"); }
  fs::path agg_allow, ing_allow;
};

Keys MakeKeys(const fs::path& dir) {
  Keys k;
  k.dir = dir;
  const std::pair<const char*, Role> keys[] = {{"aggregate", Role::kServer}, {"ingest", Role::kIngest},
                                                {"client", Role::kClient},   {"worker", Role::kWorker},
                                                {"outsider", Role::kWorker}};
  for (const auto& [name, role] : keys) WriteKeyFiles(dir, name, role, GenerateKeyPair(), false);
  // The aggregator: ingest, clients, workers. The ingest daemon: clients (and a
  // worker key, to show that a listed key still cannot submit). "outsider" is in neither.
  k.agg_allow = dir / "aggregate.allow";
  k.ing_allow = dir / "ingest.allow";
  std::ofstream(k.agg_allow) << ReadFileBytes(k.Pub("ingest")) << ReadFileBytes(k.Pub("client"))
                             << ReadFileBytes(k.Pub("worker"));
  std::ofstream(k.ing_allow) << ReadFileBytes(k.Pub("client")) << ReadFileBytes(k.Pub("worker"));
  return k;
}

// A synthetic dataset and `lfrecon run`'s fused mesh on it, shared by the tests.
ReferenceDataset* g_ref = nullptr;

MeshMetrics Score(const TriangleMesh& mesh) { return ScoreAgainstReference(mesh, *g_ref); }

class AuthTest : public ServiceStackTest {
 protected:
  static void SetUpTestSuite() {
    g_ref = new ReferenceDataset;
    MakeReference("auth_ref", /*with_run=*/true, g_ref);
  }
  static void TearDownTestSuite() {
    RemoveReference(*g_ref);
    delete g_ref;
  }

  void SetUp() override {
    ServiceStackTest::SetUp();
    fs::create_directories(store_);
    keys_ = MakeKeys(tmp_.path() / "keys");
    log_tail_chars_ = std::string::npos;  // whole logs
  }
  // CURVE over loopback TCP: what is tested here (ipc:// in a private folder needs no keys).
  std::string Endpoint(const std::string&) override { return lfrecon::testing::TcpEndpoint(); }

  // The base's daemons with this stack's keys and allow-lists.
  DaemonProcess* StartAggregator() {
    return ServiceStackTest::StartAggregator({"--lease-ms", "3000", "--key", keys_.Key("aggregate").string(),
                                              "--allow", keys_.agg_allow.string()});
  }
  DaemonProcess* StartIngest() {
    return ServiceStackTest::StartIngest({"--key", keys_.Key("ingest").string(), "--allow",
                                          keys_.ing_allow.string(), "--aggregate-key",
                                          keys_.Pub("aggregate").string()});
  }
  // A worker with key `key`, or none ("": --insecure).
  DaemonProcess* StartWorker(const std::string& exe, const std::string& key) {
    if (key.empty()) return ServiceStackTest::StartWorker(exe, {"--insecure"});
    return ServiceStackTest::StartWorker(
        exe, {"--key", keys_.Key(key).string(), "--aggregate-key", keys_.Pub("aggregate").string()});
  }
  // A REQ client of `endpoint` with the key `name` (none: plain, --insecure).
  std::unique_ptr<RequestClient> Client(const std::string& endpoint, const std::string& name,
                                        const std::string& server = "aggregate") {
    ClientSecurity s;
    s.insecure = name.empty();
    if (!name.empty()) {
      s.key = ReadSecretKeyFile(keys_.Key(name));
      s.server_key = ReadPublicKeyFile(keys_.Pub(server));
    }
    return std::make_unique<RequestClient>(context_, endpoint, kDefaultMaxMessageBytes, s);
  }
  // The CLI's key flags for the client key (submit also takes the ingest's).
  std::string ClientFlags(bool ingest = false) const {
    return " --key " + keys_.Key("client").string() +
           (ingest ? " --ingest-key " + keys_.Pub("ingest").string() : std::string()) + " --aggregate-key " +
           keys_.Pub("aggregate").string();
  }
  bool Up(const std::string& endpoint, const std::string& server) {
    auto c = Client(endpoint, "client", server);
    for (int i = 0; i < 50; ++i) {
      auto r = c->Request(Ping(), milliseconds(200));
      if (r && r->has_pong()) return true;
    }
    return false;
  }
  pb::JobStatus Status(const std::string& job) override {  // with the client key, a missing reply fails
    auto c = Client(agg_, "client");
    pb::Envelope req = NewEnvelope(job);
    req.mutable_status();
    auto r = c->Request(req, milliseconds(5000));
    EXPECT_TRUE(r && r->has_job_status()) << (r && r->has_error() ? r->error().message() : "no reply");
    return r ? r->job_status() : pb::JobStatus();
  }
  std::string Submit() {
    auto r = RunShell(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ + ClientFlags(true) +
                      " --dataset " + g_ref->dataset.string() + " --voxel-mm " + std::to_string(kVoxelMm));
    EXPECT_EQ(r.code, 0) << r.output;
    std::string out = r.output;
    out.erase(out.find_last_not_of("\n") + 1);
    EXPECT_TRUE(JobStore::ValidJobId(out)) << out;
    return out;
  }

  Keys keys_;
};

// Forged workers (no key; a key not in the allow-list) get no task while a job
// waits; then the authenticated workers run it to lfrecon run's mesh, and the
// client commands work with keys.
TEST_F(AuthTest, ForgedWorkersGetNothingAuthenticatedStackRunsTheJob) {
  StartAggregator();
  StartIngest();
  ASSERT_TRUE(Up(agg_, "aggregate"));
  ASSERT_TRUE(Up(ing_, "ingest"));
  DaemonProcess* plain = StartWorker("lfrecon-depth", "");
  DaemonProcess* outsider = StartWorker("lfrecon-depth", "outsider");
  const std::string job = Submit();
  // A raw forged worker too: its task requests are never answered.
  auto forged = Client(agg_, "");
  EXPECT_FALSE(forged->Request(TaskRequest(), milliseconds(1500)).has_value());
  auto unlisted = Client(agg_, "outsider");
  EXPECT_FALSE(unlisted->Request(TaskRequest(), milliseconds(1000)).has_value());
  std::this_thread::sleep_for(milliseconds(1500));
  pb::JobStatus s = Status(job);
  EXPECT_EQ(s.sparse_done(), 0u);
  EXPECT_EQ(s.leases_expired(), 0u);  // no lease was ever handed out (lease 3 s, asked for > 3 s)
  EXPECT_GT(s.frames_spooled(), 0u);  // the job is there, with work to do
  EXPECT_TRUE(plain->Running());
  EXPECT_TRUE(outsider->Running());
  plain->Kill(SIGKILL);
  outsider->Kill(SIGKILL);
  StartWorker("lfrecon-depth", "worker");
  StartWorker("lfrecon-propagate", "worker");
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(240)) {
    s = Status(job);
    if (s.state() == pb::STATE_DONE || s.state() == pb::STATE_FAILED) break;
    std::this_thread::sleep_for(milliseconds(100));
  }
  ASSERT_EQ(s.state(), pb::STATE_DONE) << s.message();
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(g_ref->views));
  EXPECT_EQ(s.leases_expired(), 0u);
  const fs::path mesh = tmp_.path() / "mesh.ply";
  auto r = RunShell(kBin + "lfrecon -q export " + job + " --aggregate " + agg_ + ClientFlags() + " -o " + mesh.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const MeshMetrics m = Score(ReadPly(mesh));
  std::printf("authenticated stack: F@%.0fmm %.4f, F@%.0fmm %.4f (lfrecon run %.4f, %.4f)\n", 2 * kVoxelMm,
              m.scores[0].fscore, 4 * kVoxelMm, m.scores[1].fscore, g_ref->f2, g_ref->f4);
  EXPECT_GT(g_ref->f4, 0.5);
  EXPECT_NEAR(m.scores[0].fscore, g_ref->f2, 1e-3);
  EXPECT_NEAR(m.scores[1].fscore, g_ref->f4, 1e-3);
  r = RunShell(kBin + "lfrecon status " + job + " --json --aggregate " + agg_ + ClientFlags());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("\"DONE\""), std::string::npos) << r.output;
  // The aggregator's ZAP handler refused the forged connections; no log holds a secret key.
  const std::string agg_log = procs_[0]->Log();
  EXPECT_NE(agg_log.find("auth: refused a connection"), std::string::npos) << agg_log;
  for (const char* name : {"aggregate", "ingest", "client", "worker", "outsider"}) {
    const std::string secret = ReadSecretKeyFile(keys_.Key(name)).secret_key;
    for (const auto& p : procs_) EXPECT_EQ(p->Log().find(secret), std::string::npos) << p->log();
  }
  for (auto& p : procs_)
    if (p->Running()) {
      EXPECT_EQ(p->Stop(), 0) << p->log();
    }
}

// Without a key a client cannot reach a CURVE daemon over TCP: the CLI refuses
// a network endpoint without keys (exit 2); with --insecure nothing answers.
TEST_F(AuthTest, ClientWithoutKeyCannotConnect) {
  StartAggregator();
  StartIngest();
  ASSERT_TRUE(Up(agg_, "aggregate"));
  auto r = RunShell(kBin + "lfrecon status j-x --aggregate " + agg_);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--insecure"), std::string::npos) << r.output;
  r = RunShell(kBin + "lfrecon status j-x --timeout-ms 1000 --insecure --aggregate " + agg_);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("no reply"), std::string::npos) << r.output;
  r = RunShell(kBin + "lfrecon submit --timeout-ms 1000 --insecure --ingest " + ing_ + " --dataset " +
               g_ref->dataset.string());
  EXPECT_EQ(r.code, 1) << r.output;
  auto plain = Client(ing_, "");
  EXPECT_FALSE(plain->Request(Ping(), milliseconds(1000)).has_value());
  // A client key with the wrong server key (the ingest's for the aggregator): the handshake fails.
  auto wrong = Client(agg_, "client", "ingest");
  EXPECT_FALSE(wrong->Request(Ping(), milliseconds(1000)).has_value());
  // A request sent once the refused handshake has torn the connection down: the REQ socket
  // then has no peer to send to, and the send is bounded by the timeout too (it used to block
  // forever; integration_auth_test once hung on it).
  auto refused = Client(agg_, "outsider");
  std::this_thread::sleep_for(milliseconds(1500));
  auto done = std::make_shared<std::promise<bool>>();
  auto answered = done->get_future();
  std::thread([done, c = std::shared_ptr<RequestClient>(std::move(refused))] {
    done->set_value(c->Request(Ping(), milliseconds(500)).has_value());
  }).detach();
  ASSERT_EQ(answered.wait_for(std::chrono::seconds(20)), std::future_status::ready) << "the request blocked";
  EXPECT_FALSE(answered.get());
  // The same for a stream (a DEALER socket): opening it fails with an error naming the endpoint.
  ClientSecurity outsider;
  outsider.key = ReadSecretKeyFile(keys_.Key("outsider"));
  outsider.server_key = ReadPublicKeyFile(keys_.Pub("ingest"));
  auto stream = std::make_shared<StreamClient>(context_, ing_, kDefaultMaxMessageBytes, outsider);
  std::this_thread::sleep_for(milliseconds(1500));
  auto opened = std::make_shared<std::promise<std::string>>();
  auto open_error = opened->get_future();
  std::thread([opened, stream] {
    try {
      stream->Open(pb::StreamOpen(), milliseconds(500));
      opened->set_value("");
    } catch (const ServiceError& e) {
      opened->set_value(e.what());
    }
  }).detach();
  ASSERT_EQ(open_error.wait_for(std::chrono::seconds(20)), std::future_status::ready) << "the stream's open blocked";
  EXPECT_NE(open_error.get().find(ing_), std::string::npos);
  EXPECT_TRUE(NoJobs(store_));  // nothing was submitted
  for (auto& p : procs_) EXPECT_TRUE(p->Running()) << p->log();
}

// Roles: a worker key cannot submit or cancel (or ask status); a client key
// (or the ingest's) cannot take or return leases; what a role may send works.
TEST_F(AuthTest, EachKeyOnlySendsWhatItsRoleMay) {
  StartAggregator();
  StartIngest();
  ASSERT_TRUE(Up(agg_, "aggregate"));
  ASSERT_TRUE(Up(ing_, "ingest"));
  auto expect_forbidden = [](RequestClient& c, const pb::Envelope& req, const std::string& what) {
    auto r = c.Request(req, milliseconds(5000));
    ASSERT_TRUE(r.has_value()) << what << ": no reply";
    ASSERT_TRUE(r->has_error()) << what << ": got " << BodyName(*r);
    EXPECT_EQ(r->error().code(), pb::ERROR_FORBIDDEN) << what << ": " << r->error().message();
  };
  pb::Envelope submit = NewEnvelope();
  submit.mutable_submit()->mutable_spec()->set_dataset_dir(g_ref->dataset.string());
  auto worker_ing = Client(ing_, "worker", "ingest");
  expect_forbidden(*worker_ing, submit, "worker submit");
  pb::Envelope stream_open = NewEnvelope();  // client-pushed streams: a client's, never a worker's
  stream_open.mutable_stream_open()->set_credits(2);
  expect_forbidden(*worker_ing, stream_open, "worker stream open");
  pb::Envelope stream_frame = NewEnvelope("j1");
  stream_frame.mutable_stream_frame()->mutable_frame()->set_index(0);
  expect_forbidden(*worker_ing, stream_frame, "worker stream frame");
  EXPECT_TRUE(worker_ing->Request(Ping(), milliseconds(5000))->has_pong());
  EXPECT_TRUE(NoJobs(store_));
  // A real job, submitted by the client.
  auto client_ing = Client(ing_, "client", "ingest");
  auto sub = client_ing->Request(submit, milliseconds(10000));
  ASSERT_TRUE(sub && sub->has_submit_reply()) << (sub && sub->has_error() ? sub->error().message() : "no reply");
  const std::string job = sub->submit_reply().job_id();
  auto worker = Client(agg_, "worker");
  pb::Envelope cancel = NewEnvelope(job);
  cancel.mutable_cancel();
  expect_forbidden(*worker, cancel, "worker cancel");
  pb::Envelope status = NewEnvelope(job);
  status.mutable_status();
  expect_forbidden(*worker, status, "worker status");
  pb::Envelope ex = NewEnvelope(job);
  ex.mutable_export_request();
  expect_forbidden(*worker, ex, "worker export");
  pb::Envelope done = NewEnvelope(job);
  done.mutable_ingest_failed()->set_message("forged");
  expect_forbidden(*worker, done, "worker ingest notice");
  auto client = Client(agg_, "client");
  expect_forbidden(*client, TaskRequest(), "client task request");
  pb::Envelope result = NewEnvelope(job);
  result.mutable_task_result()->set_view(0);
  result.mutable_task_result()->set_stage(pb::STAGE_DEPTH);
  expect_forbidden(*client, result, "client task result");
  expect_forbidden(*client, done, "client ingest notice");
  auto ingest = Client(agg_, "ingest");
  expect_forbidden(*ingest, TaskRequest(), "ingest task request");
  // The job was not touched by any of it; the worker key gets its tasks.
  EXPECT_NE(Status(job).state(), pb::STATE_CANCELLED);
  EXPECT_NE(Status(job).state(), pb::STATE_FAILED);
  bool got_task = false;
  for (int i = 0; i < 200 && !got_task; ++i) {
    auto r = worker->Request(TaskRequest(), milliseconds(5000));
    ASSERT_TRUE(r.has_value());
    ASSERT_FALSE(r->has_error()) << r->error().message();
    got_task = r->has_task();
    if (!got_task) std::this_thread::sleep_for(milliseconds(50));
  }
  EXPECT_TRUE(got_task);
  auto c = client->Request(cancel, milliseconds(5000));
  ASSERT_TRUE(c && c->has_job_status());
  EXPECT_EQ(c->job_status().state(), pb::STATE_CANCELLED);
  for (auto& p : procs_) EXPECT_TRUE(p->Running()) << p->log();
}

// Startup checks: plain TCP only with --insecure; ipc:// only in a private
// folder; a secret key file others may read is refused; keygen writes 0600.
TEST_F(AuthTest, DaemonsRefuseUnsafeEndpointsAndKeyFiles) {
  auto exits = [&](std::vector<std::string> args, const std::string& needle) {
    DaemonProcess* p = Start("lfrecon-aggregate", args);
    EXPECT_EQ(p->WaitExit(milliseconds(10000)), 2) << p->Log();
    EXPECT_NE(p->Log().find(needle), std::string::npos) << p->Log();
  };
  exits({"--bind", agg_, "--store", store_.string()}, "--insecure");
  const fs::path open_dir = tmp_.path() / "open";
  fs::create_directories(open_dir);
  fs::permissions(open_dir, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                                fs::perms::others_read | fs::perms::others_exec);
  exits({"--bind", "ipc://" + (open_dir / "a.sock").string(), "--store", store_.string()}, "0700");
  const fs::path lax = tmp_.path() / "lax.key";
  fs::copy_file(keys_.Key("aggregate"), lax);
  fs::permissions(lax, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read | fs::perms::others_read);
  {
    DaemonProcess* p = Start("lfrecon-aggregate", {"--bind", agg_, "--store", store_.string(), "--key", lax.string(),
                                                   "--allow", keys_.agg_allow.string()});
    EXPECT_EQ(p->WaitExit(milliseconds(10000)), 1) << p->Log();
    EXPECT_NE(p->Log().find("chmod 600"), std::string::npos) << p->Log();
  }
  exits({"--bind", agg_, "--store", store_.string(), "--key", keys_.Key("aggregate").string()}, "--allow");
  {  // --insecure: plain TCP, with a warning
    DaemonProcess* p = Start("lfrecon-aggregate", {"--bind", agg_, "--store", store_.string(), "--insecure"});
    auto c = Client(agg_, "");
    auto r = c->Request(Ping(), milliseconds(5000));
    EXPECT_TRUE(r && r->has_pong());
    EXPECT_EQ(p->Stop(), 0);
    EXPECT_NE(p->Log().find("plain TCP"), std::string::npos) << p->Log();
  }
  {  // ipc:// in a 0700 folder, no keys
    const fs::path priv = tmp_.path() / "private";
    fs::create_directories(priv);
    fs::permissions(priv, fs::perms::owner_all);
    const std::string ep = "ipc://" + (priv / "a.sock").string();
    DaemonProcess* p = Start("lfrecon-aggregate", {"--bind", ep, "--store", store_.string()});
    RequestClient c(context_, ep);
    auto r = c.Request(Ping(), milliseconds(5000));
    EXPECT_TRUE(r && r->has_pong()) << p->Log();
    EXPECT_EQ(p->Stop(), 0);
  }
  // lfrecon keygen: 0600 secret, a .pub that is an allow-list line; no overwrite without --force.
  const fs::path kd = tmp_.path() / "gen";
  auto r = RunShell(kBin + "lfrecon keygen w1 --role worker -o " + kd.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(fs::status(kd / "w1.key").permissions() & fs::perms::all, fs::perms::owner_read | fs::perms::owner_write);
  const CurveKeyPair k = ReadSecretKeyFile(kd / "w1.key");
  EXPECT_EQ(ReadPublicKeyFile(kd / "w1.pub"), k.public_key);
  EXPECT_EQ(r.output.find(k.secret_key), std::string::npos);
  const AllowList list = AllowList::Load(kd);
  ASSERT_EQ(list.size(), 1u);
  ASSERT_NE(list.Find(k.public_key), nullptr);
  EXPECT_EQ(list.Find(k.public_key)->role, Role::kWorker);
  EXPECT_EQ(list.Find(k.public_key)->name, "w1");
  EXPECT_NE(RunShell(kBin + "lfrecon keygen w1 -o " + kd.string()).code, 0);
  EXPECT_EQ(ReadSecretKeyFile(kd / "w1.key").secret_key, k.secret_key);
  EXPECT_EQ(RunShell(kBin + "lfrecon keygen w1 --force -o " + kd.string()).code, 0);
  EXPECT_NE(ReadSecretKeyFile(kd / "w1.key").secret_key, k.secret_key);
}

// Allow-list and key file errors name the file and line.
TEST(AllowListTest, BadLinesAreInputErrorsNamingTheFile) {
  lfrecon::testing::TempDir tmp;
  const CurveKeyPair k = GenerateKeyPair();
  const fs::path f = tmp.path() / "allow";
  std::ofstream(f) << "# comment\n\nworker " << k.public_key << " w\nadmin " << k.public_key << "\n";
  lfrecon::testing::ExpectInputError([&] { AllowList::Load(f); }, {f.string(), "line 4", "admin"});
  std::ofstream(f) << "client notakey\n";
  lfrecon::testing::ExpectInputError([&] { AllowList::Load(f); }, {f.string(), "line 1"});
  std::ofstream(f) << "client " << k.public_key << "\nworker " << k.public_key << "\n";
  lfrecon::testing::ExpectInputError([&] { AllowList::Load(f); }, {f.string(), "line 2", "client", "worker"});
  std::ofstream(f) << "  # indented comment\nclient " << k.public_key << " c\n";
  const AllowList ok = AllowList::Load(f);
  ASSERT_NE(ok.Find(k.public_key), nullptr);
  EXPECT_EQ(ok.Find(k.public_key)->role, Role::kClient);
  EXPECT_EQ(ok.Find(GenerateKeyPair().public_key), nullptr);
  // A key file whose public key is not its secret key's.
  const fs::path kf = tmp.path() / "bad.key";
  std::ofstream(kf) << "public-key = " << GenerateKeyPair().public_key << "\nsecret-key = " << k.secret_key << "\n";
  fs::permissions(kf, fs::perms::owner_read | fs::perms::owner_write);
  lfrecon::testing::ExpectInputError([&] { ReadSecretKeyFile(kf); }, {kf.string(), "public-key"});
}

}  // namespace
}  // namespace lfrecon::svc
